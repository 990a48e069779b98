"""Image files for bake results through OpenImageIO: atomic writes, bottom-up rows, linear values.

OpenImageIO is imported inside the functions, never at module level: some Blender builds (Debian's,
for one) ship without its Python module, and baking must work there; only file output needs it.

Conventions shared by every function here:

- Arrays are (H, W) or (H, W, C) with row 0 = v = 0 = the *bottom* row, Blender's pixel order.
  Image files store the top scanline first, so rows are flipped on the way in and out.
- AO is linear data. Integer formats get the linear value clipped to [0, 1] and rounded to the
  nearest code (``round(x * (2**bits - 1))``); no sRGB transfer function is applied anywhere.
  The files are tagged ``oiio:ColorSpace = "lin_rec709"``: OpenImageIO 3.0 resolves that name
  (like its aliases "linear" and "lin_srgb") to "Linear Rec.709 (sRGB)", and its PNG writer turns
  it into a ``gAMA`` chunk of 1.0, the PNG way of saying "not gamma-encoded". "Raw" would name data
  more exactly, but then the PNG writer emits no ``gAMA`` and PNG readers fall back to assuming
  sRGB. TIFF and EXR files get no colour-space tag from OpenImageIO 3.0 (EXR is linear by
  definition). Blender 5.0 ignores every such tag: it loads any PNG or TIFF as "sRGB" (checked with
  bpy 5.0.1, for the tags lin_rec709, linear, Raw and Non-Color) and an EXR as "Linear Rec.709",
  so whoever loads these files into Blender must set the image's colour space to "Non-Color".
- Metadata is a dict of ``str -> str | int | float | bool``. Each item is written as a text
  attribute ``mc_ao:<key>`` (text because OpenImageIO's PNG writer silently drops int and float
  attributes, and EXR would keep a float in 32 bits), and the whole dict once more as a JSON record
  in ``ImageDescription``, the only free-form field that OpenImageIO's TIFF writer keeps (it drops
  unknown attributes silently). The record spells infinities as ``Infinity``, as Python's json
  does. What survives where (OpenImageIO 3.0):

  ====  =====================  ==============  ==============
        ``mc_ao:<key>`` text   JSON record     ``Software``
  ====  =====================  ==============  ==============
  EXR   yes                    yes             yes
  PNG   yes (tEXt chunks)      yes             yes
  TIFF  no (dropped)           yes             yes
  ====  =====================  ==============  ==============

  :func:`read_image` rebuilds the dict with its original types from the JSON record, and falls back
  to the text attributes (values then come back as ``str``) when the record is missing, for example
  after another tool rewrote the description.
"""

from __future__ import annotations

import errno as _errno
import json
import os
import pathlib
import re
import numpy as np

from .._version import OUTPUT_VERSION, __version__
from .atomicfile import PendingFile, backup_of, io_error, remove_quietly, roll_back
from .filenames import same_file
from ..base.errors import McAoError, SettingsError, ImageWriteError

__all__ = [
    "ImageReadError",
    "FORMATS",
    "METADATA_PREFIX",
    "COLOR_SPACE",
    "write_image",
    "read_image",
    "write_ao",
    "import_oiio",
    "write_spec",
]


class ImageReadError(McAoError, OSError):
    """An image file could not be read (missing, unreadable, not an image, no OpenImageIO)."""


#: Supported extensions -> (allowed ``bits`` values, default). Keys are lower case.
FORMATS = {
    ".exr": (("half", "float"), "half"),
    ".png": ((8, 16), 8),
    ".tif": ((8, 16, "float"), 8),
    ".tiff": ((8, 16, "float"), 8),
}
#: Namespace of the per-key metadata attributes.
METADATA_PREFIX = "mc_ao:"
#: Value of ``oiio:ColorSpace`` on every file written (see the module docstring for why).
COLOR_SPACE = "lin_rec709"

# OpenImageIO pixel type names and the numpy dtype handed to it (equal types: no conversion by OIIO,
# except half, which OIIO rounds from float32 to nearest).
_PIXEL_TYPES = {
    8: ("uint8", np.uint8),
    16: ("uint16", np.uint16),
    "half": ("half", np.float32),
    "float": ("float", np.float32),
}
_CHANNEL_NAMES = {1: ("Y",), 2: ("Y", "A"), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}
# PNG tEXt keywords are at most 79 Latin-1 characters; keep keys short, plain and prefix-free.
_KEY_RE = re.compile(r"[A-Za-z_][A-Za-z0-9_.\-]{0,63}\Z")
_RECORD_KEY = "mc_ao"  # ImageDescription = {"mc_ao": {...metadata...}}


def import_oiio(error_class):
    """Return the OpenImageIO module, or raise ``error_class`` saying it is missing."""
    try:
        import OpenImageIO
    except ImportError as exc:
        raise error_class(
            "the OpenImageIO Python module is not available in this Python "
            f"({exc}); baking works without it, but writing or reading image files needs it"
        ) from exc
    return OpenImageIO


_io_error = io_error


def _format_of(path):
    ext = pathlib.Path(path).suffix.lower()
    if ext not in FORMATS:
        supported = ", ".join(sorted(FORMATS))
        raise SettingsError(
            f"unsupported image extension {ext or '(none)'!r} in {os.fspath(path)!r}; "
            f"supported: {supported}"
        )
    return ext


def _check_bits(ext, bits):
    allowed, default = FORMATS[ext]
    if bits is None:
        return default
    if isinstance(bits, np.integer):
        bits = int(bits)
    if isinstance(bits, bool) or not isinstance(bits, (int, str)) or bits not in allowed:
        raise SettingsError(
            f"bits={bits!r} is not valid for {ext} files; valid: "
            + ", ".join(repr(b) for b in allowed)
            + f" (default {default!r})"
        )
    return bits


def _check_pixels(pixels, bits):
    """Validate and convert to the (H, W, C) array handed to OIIO, top row first."""
    a = np.asarray(pixels)
    if not np.issubdtype(a.dtype, np.floating):
        raise SettingsError(
            f"pixels must be a floating-point array (linear values, [0, 1] for AO); got dtype {a.dtype}"
        )
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[0] < 1 or a.shape[1] < 1 or not 1 <= a.shape[2] <= 4:
        raise SettingsError(
            f"pixels must have shape (H, W) or (H, W, C) with H, W >= 1 and 1 <= C <= 4; "
            f"got {np.shape(pixels)}"
        )
    a = a[::-1]  # row 0 = bottom in memory, top scanline first in the file
    oiio_type, dtype = _PIXEL_TYPES[bits]
    if dtype is np.float32:
        return np.ascontiguousarray(a, dtype=np.float32), oiio_type
    nan = np.isnan(a)
    if nan.any():
        raise SettingsError(
            f"pixels contain {int(nan.sum())} NaN value(s), which a {bits}-bit integer image "
            "cannot store; use a float format (.exr) or replace them"
        )
    scale = float(np.iinfo(dtype).max)
    # Linear quantisation: code = round(clip(x, 0, 1) * (2^bits - 1)), ties to even.
    q = np.rint(np.clip(a.astype(np.float64), 0.0, 1.0) * scale).astype(dtype)
    return np.ascontiguousarray(q), oiio_type


def _check_metadata(metadata):
    """Return a plain dict of str -> str/int/float/bool, with mc_ao:version and mc_ao:output_version
    (:data:`core._version.OUTPUT_VERSION`) filled in."""
    out = {}
    for key, value in (metadata or {}).items():
        if not isinstance(key, str) or not _KEY_RE.match(key):
            raise SettingsError(
                f"metadata key {key!r} must be a string of letters, digits, '_', '.' or '-' "
                "(at most 64, not starting with a digit); the 'mc_ao:' prefix is added on writing"
            )
        if isinstance(value, np.generic):
            value = value.item()
        if not isinstance(value, (str, int, float)):  # bool is an int
            raise SettingsError(
                f"metadata value for {key!r} must be str, int, float or bool; got {type(value).__name__}"
            )
        out[key] = value
    out.setdefault("version", __version__)
    out.setdefault("output_version", OUTPUT_VERSION)
    return out


def _text(value):
    # repr keeps every bit of a float ('0.1', 'inf'); str for the rest.
    return repr(value) if isinstance(value, float) else str(value)


def _make_spec(oiio, ext, shape, oiio_type, metadata):
    h, w, c = shape
    spec = oiio.ImageSpec(w, h, c, oiio_type)
    spec.channelnames = _CHANNEL_NAMES[c]
    spec.alpha_channel = {2: 1, 4: 3}.get(c, -1)
    if spec.alpha_channel >= 0:
        # Alpha here is data (a mask, say), not coverage. Without this, OIIO takes the array as
        # premultiplied and divides colour by alpha for PNG (clipping at 1), and multiplies on read.
        spec.attribute("oiio:UnassociatedAlpha", 1)
    spec.attribute("oiio:ColorSpace", COLOR_SPACE)
    spec.attribute("Software", f"mc_ao {__version__}")
    # No write time: OpenImageIO stamps EXR and TIFF files with one unless DateTime is set (to ""
    # here, which writes none), and a rebake must give the same bytes (farm retries compare them).
    spec.attribute("DateTime", "")
    if ext in (".exr", ".tif", ".tiff"):
        spec.attribute("compression", "zip")  # lossless, whatever OIIO's default becomes
    for key, value in metadata.items():
        spec.attribute(METADATA_PREFIX + key, _text(value))
    spec.attribute("ImageDescription", json.dumps({_RECORD_KEY: metadata}, sort_keys=True))
    return spec


def _prepare(path, pixels, bits, metadata, overwrite, make_dirs):
    """Validate everything, then write, check and fsync a temporary file beside ``path``.

    Returns a :class:`core.files.atomicfile.PendingFile` to commit; on any failure nothing is left
    behind and the target is untouched.
    """
    target = pathlib.Path(path)
    ext = _format_of(target)
    bits = _check_bits(ext, bits)
    data, oiio_type = _check_pixels(pixels, bits)
    meta = _check_metadata(metadata)
    oiio = import_oiio(ImageWriteError)

    directory = target.parent
    if make_dirs and not directory.exists():
        try:
            os.makedirs(directory, exist_ok=True)
        except OSError as exc:
            raise _io_error(
                ImageWriteError,
                f"could not create the directory {os.fspath(directory)!r} for {os.fspath(target)!r}: {exc}",
                exc.errno,
            ) from exc
    if not directory.is_dir():
        what = "is not a directory" if directory.exists() else "does not exist"
        raise _io_error(
            ImageWriteError,
            f"cannot write {os.fspath(target)!r}: the directory {os.fspath(directory)!r} {what}"
            + ("" if make_dirs or directory.exists() else " (pass make_dirs=True to create it)"),
            _errno.ENOTDIR if directory.exists() else _errno.ENOENT,
        )
    # A hidden temporary file of a short fixed-length name in the same directory (so that the
    # final rename stays on one filesystem), ending in the real extension so that OIIO picks the
    # format from it.
    pending = PendingFile(target, overwrite=overwrite, error=ImageWriteError)
    try:
        _write_temp(oiio, pending.temp, target, ext, data, oiio_type, meta)
    except BaseException as exc:  # KeyboardInterrupt included: never leave a temp file behind
        if not isinstance(exc, Exception):
            pending.discard()
            raise
        raise pending.fail(exc) from exc
    # OpenImageIO's PNG and 8-bit TIFF writers report a file cut short by a full disk as written:
    # every file is read back and compared with what was written before it may replace the target.
    pending.finish(verify=lambda temp: _verify(oiio, temp, data, oiio_type))
    return pending


def _verify(oiio, temp, data, oiio_type):
    """Raise ValueError unless ``temp`` decodes completely to ``data`` (as stored: quantised, half)."""
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(os.fspath(temp), config)
    if inp is None:
        raise ValueError(f"it cannot be opened: {oiio.geterror() or 'unknown error'}")
    try:
        spec = inp.spec()
        h, w, c = data.shape
        if (spec.height, spec.width, spec.nchannels) != (h, w, c):
            raise ValueError(
                f"it is {spec.width}x{spec.height} with {spec.nchannels} channels, not {w}x{h} with {c}"
            )
        got = inp.read_image(oiio_type)
        if got is None:
            raise ValueError(inp.geterror() or "it cannot be decoded")
    finally:
        inp.close()
    expected = data.astype(np.float16) if oiio_type == "half" else data
    got = np.asarray(got).reshape(expected.shape)
    if got.dtype != expected.dtype or not np.array_equal(got, expected, equal_nan=got.dtype.kind == "f"):
        raise ValueError("its pixels differ from those written")


def _write_temp(oiio, temp, target, ext, data, oiio_type, meta):
    """Write the image to ``temp``; raise RuntimeError with OpenImageIO's message when it says it failed."""
    write_spec(oiio, temp, _make_spec(oiio, ext, data.shape, oiio_type, meta), data)


def write_spec(oiio, temp, spec, data):
    """Write ``data`` to ``temp`` as ``spec`` says; raise RuntimeError with OpenImageIO's message when it
    says it failed."""
    out = oiio.ImageOutput.create(os.fspath(temp))
    if out is None:
        raise RuntimeError(oiio.geterror() or "OpenImageIO has no writer for it")
    opened = False
    try:
        opened = out.open(os.fspath(temp), spec)
        if not opened or not out.write_image(data):
            raise RuntimeError(out.geterror() or oiio.geterror() or "unknown OpenImageIO error")
    except BaseException:
        if opened:
            out.close()  # the original error is the one worth reporting
        raise
    if not out.close():
        raise RuntimeError(out.geterror() or "closing the file failed")


def write_image(path, pixels, *, bits=None, metadata=None, overwrite=True, make_dirs=False):
    """Write an image file atomically: the target is either untouched or completely written.

    Parameters
    ----------
    path : str or os.PathLike
        Target file. The extension picks the format: ``.exr``, ``.png``, ``.tif``/``.tiff``
        (case-insensitive).
    pixels : array_like of float, shape (H, W) or (H, W, C), 1 <= C <= 4
        Linear values, row 0 = the bottom row (v = 0), as Blender stores pixels. One channel is
        written as grey ("Y" in EXR), two as grey + alpha, three as RGB, four as RGBA. Alpha is
        stored as data, not premultiplied into the other channels.
    bits : {8, 16, 'half', 'float'}, optional
        Sample type. EXR: 'half' (default) or 'float'. PNG: 8 (default) or 16.
        TIFF: 8 (default), 16 or 'float'. Integer formats store ``round(clip(x, 0, 1) * (2**bits - 1))``
        (no sRGB encoding) and refuse NaN; float formats store values as they are.
    metadata : dict of str -> str, int, float or bool, optional
        Written as ``mc_ao:<key>`` attributes and as a JSON record (see the module docstring for
        which formats keep what). ``version`` is filled in with the package version if absent, ``output_version`` with
        :data:`core._version.OUTPUT_VERSION`.
        ``Software`` is always ``"mc_ao <version>"``.
    overwrite : bool
        If False and ``path`` exists, raise :class:`ImageWriteError` (errno EEXIST) and write nothing.
        The check and the final rename are one atomic ``link()`` where the filesystem has hard links.
    make_dirs : bool
        Create missing parent directories. Off by default, so that a mistyped output folder is an
        error rather than a new folder somewhere unexpected.

    Returns
    -------
    pathlib.Path
        ``path`` as a Path.

    Raises
    ------
    SettingsError
        Unsupported extension, ``bits`` not valid for the format, bad pixel array or metadata.
        Raised before anything touches the filesystem.
    ImageWriteError
        OpenImageIO missing or failing (a full disk included), directory missing or not writable,
        target read-only or existing with ``overwrite=False``. The message names the path and the reason; no temporary file remains
        and an existing target keeps its old bytes.

    Notes
    -----
    The image goes to a hidden temporary file in the target's directory (``.mc_ao-XXXXXXXX.tmp<ext>``,
    a fixed length whatever the target's name), is read back and compared with the pixels written
    (OpenImageIO's PNG and TIFF writers report a file cut short by a full disk as written), gets
    the permission bits of the file it replaces, is fsynced, and is then renamed over the target
    with ``os.replace`` (the directory is fsynced after); see :mod:`core.files.atomicfile`. A target
    whose write permission is off is not replaced (ImageWriteError, errno EACCES). A symbolic
    link at ``path`` is replaced by the file, not followed.
    """
    pending = _prepare(path, pixels, bits, metadata, overwrite, make_dirs)
    try:
        pending.commit()
    except BaseException:
        pending.discard()
        raise
    return pending.target


def read_image(path):
    """Read an image file written by :func:`write_image` (or any file OpenImageIO reads).

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    pixels : numpy.ndarray of float32, shape (H, W) for one channel, else (H, W, C)
        Row 0 = the bottom row (the file's last scanline). Integer files are normalised to [0, 1]
        (code / (2**bits - 1)) with no colour transform; alpha is not multiplied into the other
        channels (unassociated), so what :func:`write_image` was given comes back.
    metadata : dict
        The ``mc_ao:`` attributes without their prefix: with their original types when the file has
        the JSON record :func:`write_image` writes, else as OpenImageIO reports them (text for
        files written here). Empty if the file has none.

    Raises
    ------
    ImageReadError
        The file is missing (errno ENOENT), is not an image OpenImageIO can read, or OpenImageIO
        is not installed.
    """
    oiio = import_oiio(ImageReadError)
    name = os.fspath(path)
    if not os.path.isfile(name):
        err = _errno.ENOENT if not os.path.exists(name) else _errno.EISDIR
        raise _io_error(ImageReadError, f"cannot read {name!r}: {os.strerror(err)}", err)
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)  # return stored values, never premultiplied
    inp = oiio.ImageInput.open(name, config)
    if inp is None:
        raise _io_error(ImageReadError, f"cannot read {name!r}: {oiio.geterror()}")
    try:
        spec = inp.spec()
        data = inp.read_image("float")
        if data is None:
            raise _io_error(ImageReadError, f"cannot read {name!r}: {inp.geterror()}")
        metadata = {}
        for param in spec.extra_attribs:
            if param.name.startswith(METADATA_PREFIX):
                metadata[param.name[len(METADATA_PREFIX):]] = param.value
        record = _parse_record(spec.get_string_attribute("ImageDescription", ""))
        if record is not None:
            metadata.update(record)
    finally:
        inp.close()
    pixels = np.asarray(data, dtype=np.float32).reshape(spec.height, spec.width, spec.nchannels)
    pixels = np.ascontiguousarray(pixels[::-1])
    if spec.nchannels == 1:
        pixels = pixels[:, :, 0]
    return pixels, metadata


def _parse_record(description):
    if not description.startswith("{"):
        return None
    try:
        record = json.loads(description)
    except ValueError:
        return None
    if isinstance(record, dict) and isinstance(record.get(_RECORD_KEY), dict):
        return record[_RECORD_KEY]
    return None


def write_ao(path, result, *, bits=None, stderr_path=None, stderr_bits=None, metadata=None,
             overwrite=True, make_dirs=False):
    """Write a bake result's AO map, and optionally its standard-error map, as image files.

    Parameters
    ----------
    path : str or os.PathLike
        AO image file; format and ``bits`` as in :func:`write_image`.
    result : object
        Has ``.ao`` (H, W) float in [0, 1], ``.stderr`` (H, W) float (needed only with
        ``stderr_path``), and optionally ``.metadata`` (dict; absent means ``{}``).
    stderr_path : str or os.PathLike, optional
        Second file for the per-texel standard error. Use a float format (``.exr``): standard errors
        are small (often below 1/255), so an 8-bit file would round most of them to 0, and NaN
        entries are refused by integer formats.
    stderr_bits : optional
        ``bits`` for the standard-error file; the format's default if None.
    metadata : dict, optional
        Merged over ``result.metadata`` (these values win) and written to both files, with
        ``content`` set to ``"ao"`` or ``"stderr"`` so that the two files can be told apart.
    overwrite, make_dirs : bool
        As in :func:`write_image`, for both files.

    Returns
    -------
    pathlib.Path or tuple of pathlib.Path
        The AO path, or ``(ao_path, stderr_path)`` when ``stderr_path`` is given.

    Notes
    -----
    Both files are written to temporary files first; only when both are complete are they renamed
    onto their targets, AO first. If anything fails before the renames, neither target changes. If
    the second rename fails (rare, since its temporary file is already complete in the target's
    directory; overwrite=False losing a race is one way), the AO rename is rolled back: the
    previous AO file is restored from a hard link taken before the rename, or the new AO file is
    removed if there was none. On a filesystem without hard links a previous AO file cannot be
    restored, and the error says so.
    """
    meta = dict(getattr(result, "metadata", None) or {})
    meta.update(metadata or {})
    ao_meta = dict(meta, content="ao")
    if stderr_path is None:
        return write_image(path, result.ao, bits=bits, metadata=ao_meta, overwrite=overwrite,
                           make_dirs=make_dirs)

    if same_file(path, stderr_path):  # by the file they reach: one would replace the other
        raise SettingsError(f"the AO and standard-error images have the same path {os.fspath(path)!r}"
                            + ("" if os.fspath(path) == os.fspath(stderr_path)
                               else f" (as {os.fspath(stderr_path)!r} reaches it)"))
    # Validate the second file's settings before any file is written.
    _check_bits(_format_of(stderr_path), stderr_bits)
    first = _prepare(path, result.ao, bits, ao_meta, overwrite, make_dirs)
    try:
        second = _prepare(stderr_path, result.stderr, stderr_bits, dict(meta, content="stderr"),
                          overwrite, make_dirs)
    except BaseException:
        first.discard()
        raise

    backup = None
    try:
        backup = _backup(first.target)
        first.commit()
    except BaseException:
        first.discard()
        second.discard()
        if backup:
            remove_quietly(backup)
        raise
    try:
        second.commit()
    except BaseException as exc:
        second.discard()
        restored = _roll_back(first.target, backup)
        if isinstance(exc, ImageWriteError) and not restored:
            exc.args = (exc.args[0] + f"; {os.fspath(first.target)!r} was already replaced and its "
                        "previous version could not be restored",)
        raise
    if backup:
        remove_quietly(backup)
    return first.target, second.target


def _backup(target):
    """Hard-link an existing target to a hidden name; None if there is no target, False if impossible."""
    try:
        return backup_of(target)
    except OSError:
        return False


def _roll_back(target, backup):
    """Undo a committed rename; True if the target is back to its previous state."""
    return backup is not False and roll_back(target, backup)
