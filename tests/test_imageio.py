"""Tests of core.files.imageio: round trips, orientation, linear values, metadata, atomic writes."""

import os
import struct
import subprocess
import sys
import types

import numpy as np
import pytest

OpenImageIO = pytest.importorskip("OpenImageIO")

from core.files import imageio  # noqa: E402
from core._version import OUTPUT_VERSION, __version__  # noqa: E402
from core.base.errors import ImageWriteError, McAoError, SettingsError  # noqa: E402

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))

# (extension, bits) for every supported combination, and the default bits of each extension.
CASES = [
    (".exr", "half"), (".exr", "float"),
    (".png", 8), (".png", 16),
    (".tif", 8), (".tif", 16), (".tif", "float"),
    (".tiff", 16),
]
DEFAULT_BITS = {".exr": "half", ".png": 8, ".tif": 8, ".tiff": 8}
METADATA = {
    "samples": 256,
    "seed": 2**40 + 3,  # beyond int32 and float32
    "sample_source": "sobol-owen",
    "max_distance": 0.1,  # not a float32 value
    "version": "9.9.9",
    "output_version": 7,
}


def error_bound(bits, x):
    """Largest |read - written| a correct writer can produce for values x in [0, 1]."""
    f32 = 4 * np.finfo(np.float32).eps  # the reader's float32 of code / (2^bits - 1)
    if bits == 8:
        return 0.5 / 255 + f32
    if bits == 16:
        return 0.5 / 65535 + f32
    if bits == "half":
        # 10 stored mantissa bits: round to nearest is within 2^-11 relative; below the smallest
        # normal (2^-14) the spacing is 2^-24, so the absolute error is at most 2^-25.
        return np.maximum(np.abs(x) * 2.0**-11, 2.0**-25)
    return 0.0  # float: exact


def ramp(h=5, w=7, c=None, seed=0):
    rng = np.random.default_rng(seed)
    shape = (h, w) if c is None else (h, w, c)
    x = rng.random(shape, dtype=np.float32)
    x.flat[0], x.flat[1], x.flat[2] = 0.0, 1.0, 0.5
    return x


def files_in(directory):
    return sorted(os.listdir(directory))


# --- round trips ----------------------------------------------------------------------------------

@pytest.mark.parametrize("ext,bits", CASES)
@pytest.mark.parametrize("channels", [None, 1, 2, 3, 4])
def test_round_trip_within_quantisation(tmp_path, ext, bits, channels):
    x = ramp(c=channels)
    path = imageio.write_image(tmp_path / f"ao{ext}", x, bits=bits)
    assert path == tmp_path / f"ao{ext}"
    y, _ = imageio.read_image(path)
    expected_shape = x.shape if channels != 1 else x.shape[:2]  # one channel reads back as (H, W)
    assert y.shape == expected_shape and y.dtype == np.float32
    assert np.all(np.abs(y.reshape(x.shape) - x) <= error_bound(bits, x))
    assert files_in(tmp_path) == [f"ao{ext}"]


@pytest.mark.parametrize("ext", sorted(DEFAULT_BITS))
def test_default_bits(tmp_path, ext):
    path = imageio.write_image(tmp_path / f"ao{ext}", ramp())
    inp = OpenImageIO.ImageInput.open(str(path))
    try:
        fmt = str(inp.spec().format)
    finally:
        inp.close()
    assert fmt == {"half": "half", 8: "uint8"}[DEFAULT_BITS[ext]]


@pytest.mark.parametrize("ext,bits", CASES)
def test_file_has_the_requested_sample_type(tmp_path, ext, bits):
    path = imageio.write_image(tmp_path / f"ao{ext}", ramp(), bits=bits)
    inp = OpenImageIO.ImageInput.open(str(path))
    try:
        fmt = str(inp.spec().format)
    finally:
        inp.close()
    assert fmt == {8: "uint8", 16: "uint16", "half": "half", "float": "float"}[bits]


@pytest.mark.parametrize("ext,bits", CASES)
def test_alpha_is_data_not_premultiplied(tmp_path, ext, bits):
    """OIIO would divide colour by alpha when writing PNG (and multiply when reading) unless told
    the alpha is unassociated; zero and small alphas must not touch the other channels."""
    x = np.array([[[0.2, 1.0, 0.5, 0.0], [0.9, 0.1, 0.3, 0.25], [0.6, 0.7, 0.8, 1.0]]], np.float32)
    y, _ = imageio.read_image(imageio.write_image(tmp_path / f"a{ext}", x, bits=bits))
    assert np.all(np.abs(y - x) <= error_bound(bits, x))
    ya, _ = imageio.read_image(imageio.write_image(tmp_path / f"ya{ext}", x[..., 2:], bits=bits))
    assert np.all(np.abs(ya - x[..., 2:]) <= error_bound(bits, x[..., 2:]))


@pytest.mark.parametrize("ext,bits", [(".png", 8), (".png", 16), (".tif", 8), (".tif", 16)])
def test_integer_formats_clip_and_round_to_nearest(tmp_path, ext, bits):
    top = 2**bits - 1
    # Codes k +- 0.49 must land on k; out-of-range values clip to 0 and 1.
    k = np.array([0, 1, 2, top // 3, top - 1, top], dtype=np.float64)
    x = np.concatenate([(k + 0.49) / top, (k - 0.49) / top, [-0.3, 1.7, -np.inf, np.inf]])
    expected = np.concatenate([k, k, [0, top, 0, top]])
    expected = np.clip(expected, 0, top)  # (0 - 0.49) and (top + 0.49) clip
    path = imageio.write_image(tmp_path / f"q{ext}", x.reshape(1, -1), bits=bits)
    inp = OpenImageIO.ImageInput.open(str(path))
    try:
        codes = inp.read_image("uint8" if bits == 8 else "uint16")
    finally:
        inp.close()
    assert codes.reshape(-1).tolist() == expected.astype(int).tolist()


def test_float_formats_keep_out_of_range_and_nan(tmp_path):
    x = np.array([[-0.25, 2.5, np.inf, np.nan]], dtype=np.float32)
    for ext, bits in [(".exr", "float"), (".exr", "half"), (".tif", "float")]:
        y, _ = imageio.read_image(imageio.write_image(tmp_path / f"f{bits}{ext}", x, bits=bits))
        np.testing.assert_array_equal(y, x)


def test_nan_refused_by_integer_formats(tmp_path):
    x = np.array([[0.5, np.nan]], dtype=np.float32)
    with pytest.raises(SettingsError, match="NaN"):
        imageio.write_image(tmp_path / "n.png", x)
    assert files_in(tmp_path) == []


# --- orientation and colour -----------------------------------------------------------------------

@pytest.mark.parametrize("ext,bits", CASES)
def test_row_zero_is_the_bottom_row(tmp_path, ext, bits):
    x = np.full((4, 3), 0.25, dtype=np.float32)
    x[0] = 1.0  # bottom row (v = 0)
    x[-1] = 0.0  # top row
    path = imageio.write_image(tmp_path / f"o{ext}", x, bits=bits)
    y, _ = imageio.read_image(path)
    np.testing.assert_array_equal(y[0], 1.0)
    np.testing.assert_array_equal(y[-1], 0.0)
    # The file itself is top-down: its first scanline is our last row.
    inp = OpenImageIO.ImageInput.open(str(path))
    try:
        first = inp.read_scanline(0, 0, "float")
        last = inp.read_scanline(3, 0, "float")
    finally:
        inp.close()
    np.testing.assert_array_equal(first, 0.0)
    np.testing.assert_array_equal(last, 1.0)


def test_png_values_are_linear_not_srgb_encoded(tmp_path):
    path = imageio.write_image(tmp_path / "half.png", np.full((2, 2), 0.5, np.float32), bits=8)
    inp = OpenImageIO.ImageInput.open(str(path))
    try:
        codes = inp.read_image("uint8")
        colour_space = inp.spec().get_string_attribute("oiio:ColorSpace")
    finally:
        inp.close()
    assert np.all(codes == 128)  # round(0.5 * 255); the sRGB encoding of 0.5 would be 188
    y, _ = imageio.read_image(path)
    np.testing.assert_allclose(y, 128 / 255, rtol=0, atol=1e-7)
    # OIIO 3.0 reads the tag back as written; 3.2 (the numpy 2 line, Blender 5.1+) calls the same
    # space "lin_rec709_scene".
    assert colour_space in (imageio.COLOR_SPACE, imageio.COLOR_SPACE + "_scene")
    # OIIO maps the linear tag onto a gAMA chunk of 1.0 (stored as 100000 / 100000).
    data = path.read_bytes()
    i = data.index(b"gAMA")
    assert struct.unpack(">I", data[i + 4:i + 8])[0] == 100000
    assert b"sRGB" not in data[:i]


def test_color_space_name_is_linear_in_oiio():
    config = OpenImageIO.ColorConfig()
    assert config.equivalent(imageio.COLOR_SPACE, "linear")
    assert not config.equivalent(imageio.COLOR_SPACE, "sRGB")


# --- metadata -------------------------------------------------------------------------------------

@pytest.mark.parametrize("ext,bits", CASES)
def test_metadata_round_trip_with_types(tmp_path, ext, bits):
    path = imageio.write_image(tmp_path / f"m{ext}", ramp(), bits=bits, metadata=METADATA)
    _, meta = imageio.read_image(path)
    assert meta == METADATA
    for key, value in METADATA.items():
        assert type(meta[key]) is type(value)


def test_metadata_special_values(tmp_path):
    md = {"max_distance": float("inf"), "adaptive": True, "note": "h\u00e9llo", "n": np.int64(7),
          "x": np.float32(0.5)}
    for ext in (".exr", ".png", ".tif"):
        _, meta = imageio.read_image(imageio.write_image(tmp_path / f"s{ext}", ramp(), metadata=md))
        assert meta == {"max_distance": float("inf"), "adaptive": True, "note": "h\u00e9llo", "n": 7,
                        "x": 0.5, "version": __version__, "output_version": OUTPUT_VERSION}
        assert type(meta["n"]) is int and type(meta["adaptive"]) is bool


@pytest.mark.parametrize("ext", [".exr", ".png", ".tif"])
def test_software_and_version_are_written(tmp_path, ext):
    path = imageio.write_image(tmp_path / f"v{ext}", ramp())
    _, meta = imageio.read_image(path)
    assert meta == {"version": __version__, "output_version": OUTPUT_VERSION}
    assert type(meta["output_version"]) is int
    inp = OpenImageIO.ImageInput.open(str(path))
    try:
        assert inp.spec().get_string_attribute("Software") == f"mc_ao {__version__}"
    finally:
        inp.close()


@pytest.mark.parametrize("ext", [".exr", ".png"])
def test_per_key_attributes_are_visible_to_other_readers(tmp_path, ext):
    """EXR and PNG keep the mc_ao:<key> text attributes (TIFF drops them; the JSON record stays)."""
    path = imageio.write_image(tmp_path / f"k{ext}", ramp(), metadata=METADATA)
    inp = OpenImageIO.ImageInput.open(str(path))
    try:
        spec = inp.spec()
        for key, value in METADATA.items():
            assert spec.get_string_attribute("mc_ao:" + key) == str(value)
    finally:
        inp.close()


@pytest.mark.parametrize("ext", [".exr", ".png"])
def test_metadata_falls_back_to_text_attributes(tmp_path, ext):
    """Without the JSON record (another tool rewrote the description), values come back as text."""
    x = ramp()
    path = tmp_path / f"t{ext}"
    spec = OpenImageIO.ImageSpec(x.shape[1], x.shape[0], 1, "float" if ext == ".exr" else "uint8")
    spec.attribute("mc_ao:samples", "64")
    spec.attribute("mc_ao:sample_source", "random")
    spec.attribute("ImageDescription", "written by someone else")
    out = OpenImageIO.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(x) and out.close()
    _, meta = imageio.read_image(path)
    assert meta == {"samples": "64", "sample_source": "random"}


def test_tiff_drops_per_key_attributes_but_keeps_the_record(tmp_path):
    """Documents the OIIO 3.0 TIFF limitation that the JSON record works around."""
    path = imageio.write_image(tmp_path / "d.tif", ramp(), metadata=METADATA)
    inp = OpenImageIO.ImageInput.open(str(path))
    try:
        spec = inp.spec()
        names = [p.name for p in spec.extra_attribs]
        description = spec.get_string_attribute("ImageDescription")
    finally:
        inp.close()
    assert not [n for n in names if n.startswith("mc_ao:")]
    assert '"samples": 256' in description


@pytest.mark.parametrize("bad", [{"": 1}, {"a b": 1}, {"mc_ao:x": 1}, {1: 2}, {"x": [1, 2]},
                                 {"x": None}, {"x": b"bytes"}, {"9lives": 1}])
def test_bad_metadata_is_a_settings_error(tmp_path, bad):
    with pytest.raises(SettingsError):
        imageio.write_image(tmp_path / "b.exr", ramp(), metadata=bad)
    assert files_in(tmp_path) == []


# --- validation -----------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["ao.jpg", "ao", "ao.exr.bak", "ao.hdr"])
def test_unsupported_extension(tmp_path, name):
    with pytest.raises(SettingsError) as info:
        imageio.write_image(tmp_path / name, ramp())
    message = str(info.value)
    for ext in (".exr", ".png", ".tif"):
        assert ext in message
    assert files_in(tmp_path) == []


def test_extension_is_case_insensitive(tmp_path):
    y, _ = imageio.read_image(imageio.write_image(tmp_path / "AO.PNG", ramp(), bits=16))
    assert y.shape == (5, 7)


@pytest.mark.parametrize("ext,bits", [(".exr", 8), (".exr", 16), (".exr", 32), (".png", "half"),
                                      (".png", "float"), (".png", 32), (".tif", "half"), (".tif", 12),
                                      (".png", True), (".png", 8.0), (".png", "8")])
def test_invalid_bits(tmp_path, ext, bits):
    with pytest.raises(SettingsError, match="bits"):
        imageio.write_image(tmp_path / f"a{ext}", ramp(), bits=bits)
    assert files_in(tmp_path) == []


@pytest.mark.parametrize("pixels", [np.zeros((2, 2), np.uint8), np.zeros((2, 2), bool),
                                    np.zeros((2, 2), np.complex64), np.zeros(4, np.float32),
                                    np.zeros((0, 3), np.float32), np.zeros((2, 2, 5), np.float32),
                                    np.zeros((2, 2, 1, 1), np.float32)])
def test_bad_pixels(tmp_path, pixels):
    with pytest.raises(SettingsError):
        imageio.write_image(tmp_path / "p.exr", pixels)
    assert files_in(tmp_path) == []


def test_float64_and_lists_are_accepted(tmp_path):
    y, _ = imageio.read_image(imageio.write_image(tmp_path / "l.exr", [[0.25, 0.5]], bits="float"))
    np.testing.assert_array_equal(y, [[0.25, 0.5]])


def test_errors_are_catchable_as_builtins():
    assert issubclass(ImageWriteError, OSError) and issubclass(ImageWriteError, McAoError)
    assert issubclass(imageio.ImageReadError, OSError)
    assert issubclass(imageio.ImageReadError, McAoError)


# --- directories and overwrite --------------------------------------------------------------------

def test_missing_directory(tmp_path):
    target = tmp_path / "nope" / "ao.png"
    with pytest.raises(ImageWriteError) as info:
        imageio.write_image(target, ramp())
    assert str(tmp_path / "nope") in str(info.value)
    assert "make_dirs" in str(info.value)
    assert info.value.errno == 2
    assert not (tmp_path / "nope").exists()


def test_make_dirs_creates_parents(tmp_path):
    target = tmp_path / "a" / "b" / "ao.exr"
    imageio.write_image(target, ramp(), make_dirs=True)
    assert files_in(target.parent) == ["ao.exr"]


def test_parent_is_a_file(tmp_path):
    """Fails for root too, unlike permission bits."""
    (tmp_path / "afile").write_bytes(b"x")
    for make_dirs in (False, True):
        with pytest.raises(ImageWriteError) as info:
            imageio.write_image(tmp_path / "afile" / "x.png", ramp(), make_dirs=make_dirs)
        assert str(tmp_path / "afile") in str(info.value)
    assert (tmp_path / "afile").read_bytes() == b"x"


def test_target_is_a_directory(tmp_path):
    (tmp_path / "d.png").mkdir()
    with pytest.raises(ImageWriteError, match="is a directory"):
        imageio.write_image(tmp_path / "d.png", ramp())
    assert files_in(tmp_path) == ["d.png"]


def test_read_only_directory(tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        # Root (with CAP_DAC_OVERRIDE) ignores permission bits; os.access would not tell, so try.
        try:
            (ro / "probe").touch()
        except PermissionError:
            pass
        else:
            (ro / "probe").unlink()
            pytest.skip("this user can write into a 0o555 directory (root); "
                        "test_unwritable_directory_reports_the_os_reason covers the path")
        with pytest.raises(ImageWriteError) as info:
            imageio.write_image(ro / "ao.png", ramp())
        assert str(ro) in str(info.value) and info.value.errno == 13
        assert files_in(ro) == []
    finally:
        ro.chmod(0o755)


def test_unwritable_directory_reports_the_os_reason(tmp_path, monkeypatch):
    """The same path as a read-only directory, made to fail even for root."""
    real_open = os.open

    def refuse(path, flags, *args, **kwargs):
        if flags & os.O_CREAT:
            raise PermissionError(13, "Permission denied", str(path))
        return real_open(path, flags, *args, **kwargs)

    monkeypatch.setattr(os, "open", refuse)
    with pytest.raises(ImageWriteError) as info:
        imageio.write_image(tmp_path / "ao.png", ramp())
    assert str(tmp_path) in str(info.value) and "Permission denied" in str(info.value)
    assert info.value.errno == 13
    monkeypatch.undo()
    assert files_in(tmp_path) == []


def test_overwrite_false(tmp_path):
    target = tmp_path / "ao.png"
    target.write_bytes(b"old")
    with pytest.raises(ImageWriteError) as info:
        imageio.write_image(target, ramp(), overwrite=False)
    assert info.value.errno == 17 and str(target) in str(info.value)
    assert target.read_bytes() == b"old"
    assert files_in(tmp_path) == ["ao.png"]
    imageio.write_image(tmp_path / "new.png", ramp(), overwrite=False)
    assert files_in(tmp_path) == ["ao.png", "new.png"]


def test_overwrite_false_loses_a_race_cleanly(tmp_path, monkeypatch):
    """A file that appears after the check but before the rename is still not clobbered."""
    target = tmp_path / "ao.png"
    real_write = imageio._write_temp

    def write_then_race(*args):
        real_write(*args)
        target.write_bytes(b"raced")

    monkeypatch.setattr(imageio, "_write_temp", write_then_race)
    with pytest.raises(ImageWriteError, match="already exists"):
        imageio.write_image(target, ramp(), overwrite=False)
    assert target.read_bytes() == b"raced"
    assert files_in(tmp_path) == ["ao.png"]


def test_overwrite_replaces_and_uses_umask_permissions(tmp_path):
    target = tmp_path / "ao.exr"
    target.write_bytes(b"old")
    imageio.write_image(target, ramp())
    assert target.read_bytes()[:4] == b"\x76\x2f\x31\x01"  # EXR magic
    if os.name == "posix":
        umask = os.umask(0)
        os.umask(umask)
        assert target.stat().st_mode & 0o777 == 0o666 & ~umask


# --- atomicity ------------------------------------------------------------------------------------

@pytest.fixture
def existing(tmp_path):
    target = tmp_path / "ao.png"
    imageio.write_image(target, np.zeros((3, 3), np.float32))
    return target, target.read_bytes()


def test_failed_replace_leaves_target_and_no_temp(existing, monkeypatch):
    target, before = existing

    def broken_replace(src, dst):
        raise OSError(5, "Input/output error")

    monkeypatch.setattr(os, "replace", broken_replace)
    with pytest.raises(ImageWriteError) as info:
        imageio.write_image(target, np.ones((3, 3), np.float32))
    monkeypatch.undo()
    assert str(target) in str(info.value) and "Input/output error" in str(info.value)
    assert target.read_bytes() == before
    assert files_in(target.parent) == ["ao.png"]


class _FailingOutput:
    """Wraps a real ImageOutput: writes part of the file, then fails like OIIO does (or raises)."""

    def __init__(self, real, mode):
        self.real, self.mode = real, mode

    def open(self, name, spec):
        return self.real.open(name, spec)

    def write_image(self, data):
        self.real.write_scanline(0, 0, data[0])  # some bytes reach the temp file
        if self.mode == "false":
            return False
        if self.mode == "interrupt":
            raise KeyboardInterrupt
        raise RuntimeError("disk on fire")

    def geterror(self):
        return "simulated OIIO failure"

    def close(self):
        return self.real.close()


def _fake_oiio(mode):
    class ImageOutput:
        @staticmethod
        def create(name):
            return _FailingOutput(OpenImageIO.ImageOutput.create(name), mode)

    return types.SimpleNamespace(ImageOutput=ImageOutput, ImageSpec=OpenImageIO.ImageSpec,
                                 geterror=OpenImageIO.geterror)


@pytest.mark.parametrize("mode,raised,text", [("false", ImageWriteError, "simulated OIIO failure"),
                                              ("raise", ImageWriteError, "disk on fire"),
                                              ("interrupt", KeyboardInterrupt, None)])
def test_failed_oiio_write_leaves_target_and_no_temp(existing, monkeypatch, mode, raised, text):
    target, before = existing
    monkeypatch.setattr(imageio, "import_oiio", lambda error_class: _fake_oiio(mode))
    with pytest.raises(raised) as info:
        imageio.write_image(target, np.ones((3, 3), np.float32))
    if text:
        assert text in str(info.value) and str(target) in str(info.value)
    assert target.read_bytes() == before
    assert files_in(target.parent) == ["ao.png"]


def test_oiio_error_on_open_is_reported(tmp_path, monkeypatch):
    """A real OIIO refusal (here: a writer that does not exist) surfaces OIIO's message."""
    def no_writer(error_class):
        class ImageOutput:
            @staticmethod
            def create(name):
                return None
        return types.SimpleNamespace(ImageOutput=ImageOutput, ImageSpec=OpenImageIO.ImageSpec,
                                     geterror=lambda: "could not find a format writer")
    monkeypatch.setattr(imageio, "import_oiio", no_writer)
    with pytest.raises(ImageWriteError, match="could not find a format writer"):
        imageio.write_image(tmp_path / "ao.exr", ramp())
    assert files_in(tmp_path) == []


def test_missing_openimageio_module(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "OpenImageIO", None)  # makes `import OpenImageIO` fail
    with pytest.raises(ImageWriteError, match="OpenImageIO"):
        imageio.write_image(tmp_path / "ao.png", ramp())
    with pytest.raises(imageio.ImageReadError, match="OpenImageIO"):
        imageio.read_image(tmp_path / "ao.png")
    assert files_in(tmp_path) == []


def test_importing_the_module_needs_neither_oiio_nor_bpy():
    code = (
        "import sys; sys.modules['OpenImageIO'] = None\n"
        "import core.files.imageio\n"
        "assert 'bpy' not in sys.modules\n"
    )
    subprocess.run([sys.executable, "-c", code], cwd=REPO, check=True)


# --- reading --------------------------------------------------------------------------------------

def test_read_missing_file(tmp_path):
    with pytest.raises(imageio.ImageReadError) as info:
        imageio.read_image(tmp_path / "none.exr")
    assert info.value.errno == 2 and str(tmp_path / "none.exr") in str(info.value)
    assert isinstance(info.value, OSError)


def test_read_garbage(tmp_path):
    (tmp_path / "g.png").write_bytes(b"not an image at all")
    with pytest.raises(imageio.ImageReadError, match="g.png"):
        imageio.read_image(tmp_path / "g.png")


# --- write_ao -------------------------------------------------------------------------------------

class Result:
    def __init__(self, h=4, w=6, metadata=None):
        rng = np.random.default_rng(1)
        self.ao = rng.random((h, w), dtype=np.float32)
        self.stderr = (rng.random((h, w), dtype=np.float32) * 0.01).astype(np.float32)
        if metadata is not None:
            self.metadata = metadata


def test_write_ao_alone(tmp_path):
    r = Result(metadata={"samples": 64, "seed": 3})
    out = imageio.write_ao(tmp_path / "ao.png", r, bits=16, metadata={"seed": 4})
    assert out == tmp_path / "ao.png"
    y, meta = imageio.read_image(out)
    assert np.all(np.abs(y - r.ao) <= error_bound(16, r.ao))
    assert meta == {"samples": 64, "seed": 4, "content": "ao", "version": __version__,
                    "output_version": OUTPUT_VERSION}
    assert files_in(tmp_path) == ["ao.png"]


def test_write_ao_without_metadata_attribute(tmp_path):
    r = types.SimpleNamespace(ao=np.zeros((2, 2), np.float32))
    _, meta = imageio.read_image(imageio.write_ao(tmp_path / "ao.exr", r))
    assert meta == {"content": "ao", "version": __version__, "output_version": OUTPUT_VERSION}


def test_write_ao_with_stderr(tmp_path):
    r = Result(metadata={"samples": 64})
    ao_path, se_path = imageio.write_ao(tmp_path / "ao.png", r, stderr_path=tmp_path / "se.exr",
                                        stderr_bits="float")
    ao, ao_meta = imageio.read_image(ao_path)
    se, se_meta = imageio.read_image(se_path)
    assert np.all(np.abs(ao - r.ao) <= error_bound(8, r.ao))
    np.testing.assert_array_equal(se, r.stderr)
    assert ao_meta["content"] == "ao" and se_meta["content"] == "stderr"
    assert ao_meta["samples"] == se_meta["samples"] == 64
    assert files_in(tmp_path) == ["ao.png", "se.exr"]


def test_write_ao_validates_both_before_writing(tmp_path):
    with pytest.raises(SettingsError):
        imageio.write_ao(tmp_path / "ao.png", Result(), stderr_path=tmp_path / "se.jpg")
    with pytest.raises(SettingsError):
        imageio.write_ao(tmp_path / "ao.png", Result(), stderr_path=tmp_path / "se.png",
                         stderr_bits="half")
    with pytest.raises(SettingsError, match="same path"):
        imageio.write_ao(tmp_path / "ao.exr", Result(), stderr_path=tmp_path / "ao.exr")
    assert files_in(tmp_path) == []


def test_write_ao_second_file_fails_before_commit(tmp_path):
    """The standard-error file cannot be written: the AO file is not touched either."""
    (tmp_path / "ao.exr").write_bytes(b"old ao")
    with pytest.raises(ImageWriteError):
        imageio.write_ao(tmp_path / "ao.exr", Result(), stderr_path=tmp_path / "missing" / "se.exr")
    assert (tmp_path / "ao.exr").read_bytes() == b"old ao"
    assert files_in(tmp_path) == ["ao.exr"]


@pytest.mark.parametrize("had_ao", [True, False])
def test_write_ao_second_rename_fails_rolls_back(tmp_path, monkeypatch, had_ao):
    if had_ao:
        (tmp_path / "ao.exr").write_bytes(b"old ao")
    (tmp_path / "se.exr").write_bytes(b"old se")
    real_replace = os.replace

    def fail_on_stderr(src, dst):
        if os.fspath(dst).endswith("se.exr"):
            raise OSError(28, "No space left on device")
        return real_replace(src, dst)

    monkeypatch.setattr(os, "replace", fail_on_stderr)
    with pytest.raises(ImageWriteError, match="No space left"):
        imageio.write_ao(tmp_path / "ao.exr", Result(), stderr_path=tmp_path / "se.exr")
    monkeypatch.undo()
    assert (tmp_path / "se.exr").read_bytes() == b"old se"
    if had_ao:
        assert (tmp_path / "ao.exr").read_bytes() == b"old ao"
        assert files_in(tmp_path) == ["ao.exr", "se.exr"]
    else:
        assert files_in(tmp_path) == ["se.exr"]


def test_write_ao_rollback_impossible_is_reported(tmp_path, monkeypatch):
    """Without hard links the old AO file cannot be kept for a rollback; the error says so."""
    (tmp_path / "ao.exr").write_bytes(b"old ao")
    real_replace = os.replace

    def no_link(src, dst):
        raise OSError(1, "Operation not permitted")

    def fail_on_stderr(src, dst):
        if os.fspath(dst).endswith("se.exr"):
            raise OSError(28, "No space left on device")
        return real_replace(src, dst)

    monkeypatch.setattr(os, "link", no_link)
    monkeypatch.setattr(os, "replace", fail_on_stderr)
    with pytest.raises(ImageWriteError, match="could not be restored"):
        imageio.write_ao(tmp_path / "ao.exr", Result(), stderr_path=tmp_path / "se.exr")
    monkeypatch.undo()
    assert files_in(tmp_path) == ["ao.exr"]  # the new AO file; no temp or backup files


def test_write_ao_overwrite_false(tmp_path):
    (tmp_path / "se.exr").write_bytes(b"old se")
    with pytest.raises(ImageWriteError, match="already exists"):
        imageio.write_ao(tmp_path / "ao.exr", Result(), stderr_path=tmp_path / "se.exr",
                         overwrite=False)
    assert files_in(tmp_path) == ["se.exr"]
