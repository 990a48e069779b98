"""Channel packing (core.files.imageio): a map written into one channel of an existing image leaves every other
channel's samples exactly as they were, in 8- and 16-bit PNG, half and float EXR and TIFF; the file keeps
its format, sample types and attributes; a failed write leaves the old file; bad input is refused by
name before anything is written; and Blender's in-memory pixels are packed the same way."""

import os
from dataclasses import replace

import numpy as np
import pytest

from core.files import imageio
from core.base.errors import ChannelError, ImageWriteError
from core.files.channels import check_channel, pack_channel, write_channel
from tests.fullfs import fill, listing, small_filesystem

oiio = pytest.importorskip("OpenImageIO")

W, H = 37, 23  # odd sizes: rows and columns cannot be swapped unnoticed


def user_image(path, fmt, channels=4, channelformats=None, rng=None):
    """An image as another tool writes it (OpenImageIO directly, not core.files.imageio): random samples of
    every code (integers) or value (floats), a custom attribute. Returns its samples as stored."""
    rng = rng or np.random.default_rng(7)
    names = {1: ("Y",), 2: ("Y", "A"), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}[channels]
    spec = oiio.ImageSpec(W, H, channels, fmt)
    spec.channelnames = names
    if channelformats:
        spec.channelformats = tuple(oiio.TypeDesc(t) for t in channelformats)
    if channels in (2, 4):
        spec.alpha_channel = channels - 1
        spec.attribute("oiio:UnassociatedAlpha", 1)
    spec.attribute("Artist", "someone else")
    if fmt in ("uint8", "uint16"):
        data = rng.integers(0, np.iinfo(fmt).max + 1, (H, W, channels)).astype(fmt)
        # Transparent pixels with colour: a writer that premultiplied would lose it.
        data[0, :, -1] = 0
    else:
        data = (rng.random((H, W, channels)) * 4 - 1).astype(np.float32)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec) and out.write_image(data), oiio.geterror()
    out.close()
    return stored(path)[0]


def stored(path):
    """(samples as stored: codes or float32 (exact for half), top scanline first; spec)."""
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(str(path), config)
    spec = inp.spec()
    fmt = str(spec.format)
    data = inp.read_image(fmt if fmt in ("uint8", "uint16") and not len(spec.channelformats) else "float")
    inp.close()
    return np.asarray(data).reshape(spec.height, spec.width, spec.nchannels), spec


def ao_map(rng=None):
    return (rng or np.random.default_rng(3)).random((H, W)).astype(np.float32)


CASES = [
    ("png", "uint8", 4, None), ("png", "uint8", 3, None), ("png", "uint16", 4, None), ("png", "uint16", 2, None),
    ("exr", "half", 4, None), ("exr", "float", 3, None), ("exr", "half", 3, ("half", "float", "half")),
    ("tif", "uint8", 4, None), ("tif", "uint16", 3, None), ("tif", "float", 4, None),
]


@pytest.mark.parametrize("ext, fmt, channels, channelformats", CASES)
def test_the_other_channels_are_byte_identical_after_writing_one(tmp_path, ext, fmt, channels, channelformats):
    path = tmp_path / f"orm.{ext}"
    before = user_image(path, fmt, channels, channelformats)
    _, spec_before = stored(path)
    names = list(spec_before.channelnames)
    for channel in [c for c in ("R", "G", "A") if c in names]:
        values = ao_map(np.random.default_rng(ord(channel)))
        assert write_channel(path, channel, values) == path
        after, spec = stored(path)
        i = names.index(channel)
        others = [k for k in range(channels) if k != i]
        assert after.dtype == before.dtype
        assert after[:, :, others].tobytes() == before[:, :, others].tobytes(), channel
        # The channel holds the map (bottom row first in memory, top scanline first in the file),
        # quantised as the file stores it.
        kind = ([str(t) for t in spec.channelformats] or [str(spec.format)] * channels)[i]
        want = values[::-1].astype(np.float64)
        if kind in ("uint8", "uint16"):
            top = np.iinfo(kind).max
            code = np.rint(want * top)
            got = after[:, :, i].astype(np.float64) * (1 if after.dtype.kind == "u" else top)
            assert np.array_equal(np.rint(got), code)
        elif kind == "half":
            assert np.array_equal(after[:, :, i], want.astype(np.float32).astype(np.float16).astype(np.float32))
        else:
            assert np.array_equal(after[:, :, i], want.astype(np.float32))
        before = after
    # The file is what it was: format, sample types, channel names, its attributes.
    assert (str(spec.format), [str(t) for t in spec.channelformats]) == (
        str(spec_before.format), [str(t) for t in spec_before.channelformats])
    assert list(spec.channelnames) == names and spec.get_string_attribute("Artist") == "someone else"
    assert [n for n in os.listdir(tmp_path)] == [path.name]  # no temporary file left


def test_an_image_written_here_keeps_its_metadata_and_other_channels(tmp_path):
    path = tmp_path / "packed.png"
    rgba = np.random.default_rng(1).random((H, W, 4)).astype(np.float32)
    imageio.write_image(path, rgba, bits=16, metadata={"content": "orm"})
    before, _ = stored(path)
    write_channel(path, "r", ao_map())
    after, _ = stored(path)
    assert after[:, :, 1:].tobytes() == before[:, :, 1:].tobytes()
    pixels, meta = imageio.read_image(path)
    assert meta["content"] == "orm"
    assert np.allclose(pixels[:, :, 0], ao_map(), atol=0.5 / 65535)


def test_source_gives_a_copy_with_one_channel_replaced_and_leaves_the_source(tmp_path):
    source = tmp_path / "template.tif"
    user_image(source, "uint8", 4)
    old = source.read_bytes()
    target = tmp_path / "out" / "packed.tif"
    target.parent.mkdir()
    write_channel(target, 2, ao_map(), source=source)
    assert source.read_bytes() == old
    a, _ = stored(source)
    b, _ = stored(target)
    assert np.array_equal(a[:, :, [0, 1, 3]], b[:, :, [0, 1, 3]]) and not np.array_equal(a[:, :, 2], b[:, :, 2])


def test_a_failed_write_leaves_the_old_file(tmp_path, monkeypatch):
    path = tmp_path / "orm.exr"
    user_image(path, "half", 4)
    old = path.read_bytes()
    # OpenImageIO failing to make a writer.
    monkeypatch.setattr(oiio.ImageOutput, "create", staticmethod(lambda name: None))
    with pytest.raises(ImageWriteError, match="orm.exr"):
        write_channel(path, "R", ao_map())
    monkeypatch.undo()
    assert path.read_bytes() == old and os.listdir(tmp_path) == [path.name]
    # A read-only file is not replaced.
    os.chmod(path, 0o444)
    with pytest.raises(ImageWriteError, match="read-only"):
        write_channel(path, "R", ao_map())
    os.chmod(path, 0o644)
    assert path.read_bytes() == old


def test_a_full_disk_leaves_the_old_file(tmp_path):
    with small_filesystem(tmp_path / "disk", size=1 << 20) as disk:
        path = disk / "orm.png"
        user_image(path, "uint16", 4, rng=np.random.default_rng(2))
        old = path.read_bytes()
        fill(disk, leave=len(old) // 3)
        with pytest.raises(ImageWriteError, match="orm.png"):
            write_channel(path, "G", ao_map())
        assert path.read_bytes() == old and listing(disk) == ["orm.png"]


def test_bad_input_is_refused_by_name_before_anything_is_written(tmp_path):
    rgb = tmp_path / "rgb.png"
    user_image(rgb, "uint8", 3)
    grey = tmp_path / "grey.exr"
    user_image(grey, "half", 1)
    old = rgb.read_bytes()
    text = tmp_path / "notes.png"
    text.write_text("not an image")
    jpg = tmp_path / "photo.jpg"
    jpg.write_bytes(b"")
    for path, channel, size, match in [
        (rgb, "A", (W, H), r"rgb.png'? has no channel A: its channels are R, G, B"),
        (grey, "R", (W, H), r"grey.exr'? has no channel R: its channels are Y"),
        (rgb, "R", (W + 1, H), r"rgb.png'? is 37 x 23 pixels, not the 38 x 23"),
        (rgb, "X", (W, H), r"channel must be one of R, G, B, A"),
        (tmp_path / "missing.png", "R", (W, H), r"missing.png'?: it does not exist"),
        (text, "R", (W, H), r"notes.png'?: it cannot be read as an image"),
        (jpg, "R", (W, H), r"photo.jpg'?: only .exr, .png, .tif, .tiff"),
    ]:
        with pytest.raises(ChannelError, match=match):
            check_channel(path, channel, size)
        with pytest.raises(ChannelError, match=match):
            write_channel(path, channel, np.zeros(size[::-1], np.float32))
    assert check_channel(rgb, "g", (W, H)) == ("G", 1, (W, H))
    with pytest.raises(ChannelError, match="not finite"):
        write_channel(rgb, "R", np.full((H, W), np.nan, np.float32))
    with pytest.raises(ChannelError, match="float array"):
        write_channel(rgb, "R", np.zeros((H, W), np.uint8))
    assert rgb.read_bytes() == old
    assert sorted(os.listdir(tmp_path)) == ["grey.exr", "notes.png", "photo.jpg", "rgb.png"]


@pytest.mark.parametrize("shape", ["flat", "grid"])
def test_pack_channel_replaces_one_channel_of_in_memory_pixels(shape):
    rng = np.random.default_rng(4)
    pixels = rng.random((H, W, 4)).astype(np.float32)
    given = pixels.reshape(-1) if shape == "flat" else pixels
    values = ao_map()
    out = pack_channel(given, 0, values)
    assert out.shape == given.shape and out.dtype == np.float32
    grid = out.reshape(H, W, 4)
    assert grid[:, :, 1:].tobytes() == pixels[:, :, 1:].tobytes()
    assert np.array_equal(grid[:, :, 0], values)
    assert np.array_equal(pack_channel(given, "A", values.reshape(-1)).reshape(H, W, 4)[:, :, 3], values)
    assert given.reshape(H, W, 4)[:, :, 0].tobytes() == pixels[:, :, 0].tobytes()  # a new array: the input is kept


def test_pack_channel_refuses_what_does_not_fit():
    pixels = np.zeros(H * W * 3, np.float32)
    with pytest.raises(ChannelError, match="no channel A"):
        pack_channel(pixels, "A", np.zeros((H, W)))
    with pytest.raises(ChannelError, match="does not fit"):
        pack_channel(pixels, 0, np.zeros((H, W + 1)))
    with pytest.raises(ChannelError, match="does not fit"):
        pack_channel(np.zeros((H, W, 4), np.float32), 0, np.zeros((W, H * 2)))


# -- the add-on's Channel and Into (mc_ao.outputs.channel), without Blender: Into is a file ------------

def test_the_add_on_writes_the_map_into_a_copy_of_the_into_file(tmp_path):
    from mc_ao import baking, service
    from mc_ao.settings import BakeSettings
    from test_maps import arrays, service_run, unwrapped_box

    source = tmp_path / "orm.tif"
    before = user_image(source, "uint16", 4)
    old = source.read_bytes()
    out = tmp_path / "out"
    out.mkdir()
    settings = BakeSettings(resolution=W, height=H, samples=8, margin=1, threads=1, processes=1, channel="G",
                            into=str(source))
    assert baking.channel_problem(settings, {}) is None
    target = arrays(unwrapped_box(), "crate")
    jobs = [baking.Job("crate", "crate_AO", target, [], quantity="ao")]
    plan = service.plan(settings, jobs, str(out), [("PNG", 16)])
    (outcome,) = service_run(plan)
    assert outcome.status == "ok", outcome.error or outcome.trace
    assert sorted(p.name for p in out.iterdir()) == ["crate_AO.png", "orm.tif"]
    assert source.read_bytes() == old  # the Into file is an input: never written
    after, spec = stored(out / "orm.tif")
    assert after[:, :, [0, 2, 3]].tobytes() == before[:, :, [0, 2, 3]].tobytes()
    ao = outcome.results[None].ao
    assert np.array_equal(after[:, :, 1], np.rint(ao[::-1].astype(np.float64) * 65535).astype(np.uint16))
    assert spec.get_string_attribute("Artist") == "someone else"
    # UDIM tiles: refused before any work.
    from core.base.errors import FileWriteError

    with pytest.raises(FileWriteError, match="takes a plain image, not UDIM tiles"):
        service.plan(replace(settings, use_udim=True), jobs, str(out), [("PNG", 16)])
    # A channel the file does not have, or another size: refused before any work, naming the file.
    bad = BakeSettings(resolution=W, height=H, channel="A", into=str(tmp_path / "rgb.png"))
    user_image(tmp_path / "rgb.png", "uint8", 3)
    assert "rgb.png' has no channel A" in baking.channel_problem(bad, {})
    assert "is 37 x 23 pixels, not the 24 x 24" in baking.channel_problem(
        BakeSettings(resolution=24, channel="R", into=str(source)), {})
