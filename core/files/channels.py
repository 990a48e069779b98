"""One channel of an existing image file written, the others byte-identical: channel packing.

AO written into one channel (R, G, B or A) of an image that holds other data in the rest (glTF's
occlusion-roughness-metallic texture keeps occlusion in red). The other channels must come out
exactly as they were: the file is read in its own sample type (8- or 16-bit codes, half or float),
one channel is replaced, and the file is written again in the same format, sample types, channel
names and attributes, through the same temporary-file, read-back and rename as every other file
(:mod:`core.files.atomicfile`; the old file is intact until the new one is complete and checked).
"""

import os
import pathlib

import numpy as np

from ..base.errors import ChannelError, ImageWriteError
from .imageio import FORMATS, import_oiio, write_spec

#: The channels a value can be written into, by name; a channel index names the same ones.
CHANNELS = ("R", "G", "B", "A")
#: Integer sample types read and written as their codes (float files go through float32: exact for half).
_CODES = {"uint8": np.uint8, "uint16": np.uint16}


def _channel_name(channel):
    """'R', 'G', 'B' or 'A' for a channel name (any case) or index 0..3; ChannelError otherwise."""
    if isinstance(channel, (int, np.integer)) and not isinstance(channel, bool) and 0 <= channel < len(CHANNELS):
        return CHANNELS[int(channel)]
    if isinstance(channel, str) and channel.upper() in CHANNELS:
        return channel.upper()
    raise ChannelError(f"channel must be one of {', '.join(CHANNELS)} (or 0 to 3), got {channel!r}")


def _size(size):
    try:
        w, h = (size, size) if isinstance(size, (int, np.integer)) else size
        return int(w), int(h)
    except (TypeError, ValueError):
        raise ChannelError(f"size must be (width, height) in pixels, got {size!r}") from None


def _open_channel(oiio, name, channel, size):
    """(ImageInput, spec, channel index) of ``name`` after every check of :func:`check_channel`."""
    if pathlib.Path(name).suffix.lower() not in FORMATS:
        raise ChannelError(f"cannot write channel {channel} of {name!r}: only {', '.join(sorted(FORMATS))} files are "
                           "rewritten with their other channels exactly as they are (another format may be lossy "
                           "or keep what OpenImageIO cannot write back)")
    if not os.path.isfile(name):
        why = "it does not exist" if not os.path.exists(name) else "it is not a file"
        raise ChannelError(f"cannot write channel {channel} of {name!r}: {why}")
    config = oiio.ImageSpec()
    config.attribute("oiio:UnassociatedAlpha", 1)  # stored values, never premultiplied
    inp = oiio.ImageInput.open(name, config)
    if inp is None:
        raise ChannelError(f"cannot write channel {channel} of {name!r}: it cannot be read as an image "
                           f"({oiio.geterror() or 'unknown error'})")
    try:
        spec = inp.spec()
        if inp.seek_subimage(1, 0) or inp.seek_subimage(0, 1):
            raise ChannelError(f"cannot write channel {channel} of {name!r}: it holds several images or MIP levels, "
                               "and only the first would be written back")
        inp.seek_subimage(0, 0)
        if spec.deep:
            raise ChannelError(f"cannot write channel {channel} of {name!r}: it is a deep image")
        names = [n.upper() for n in spec.channelnames]
        if channel not in names:
            raise ChannelError(f"{name!r} has no channel {channel}: its channels are {', '.join(spec.channelnames)}")
        fmt = str(spec.format)
        if fmt not in _CODES and fmt not in ("half", "float"):
            raise ChannelError(f"cannot write channel {channel} of {name!r}: its samples are {fmt}, not 8- or 16-bit "
                               "integers, half or float")
        w, h = _size(size)
        if (spec.width, spec.height) != (w, h):
            raise ChannelError(f"{name!r} is {spec.width} x {spec.height} pixels, not the {w} x {h} of the map to "
                               f"write into its channel {channel}: bake at its size, or choose an image of the map's")
        return inp, spec, names.index(channel)
    except BaseException:
        inp.close()
        raise


def check_channel(path, channel, size):
    """Check, before any work, that ``channel`` of the image file ``path`` can take a map of ``size``.

    Parameters
    ----------
    path : str or os.PathLike, an existing .png, .exr, .tif or .tiff file
    channel : 'R', 'G', 'B' or 'A' (any case), or 0 to 3
    size : (width, height) in pixels (or one number for a square)

    Returns
    -------
    (channel name, index of the channel in the file, (width, height))

    Raises
    ------
    ChannelError
        Naming the file and the problem: missing or unreadable, not one of the formats above, no such
        channel (the error lists those it has), another size, several subimages or MIP levels, a
        sample type other than 8- or 16-bit integers, half or float; or OpenImageIO is missing.
    """
    name = os.fspath(path)
    channel = _channel_name(channel)
    try:
        oiio = import_oiio(ChannelError)
    except ChannelError as exc:
        raise ChannelError(f"cannot write channel {channel} of {name!r}: {exc}") from exc
    inp, spec, index = _open_channel(oiio, name, channel, size)
    inp.close()
    return channel, index, (spec.width, spec.height)


def _read_samples(oiio, name, config_alpha=True):
    """The pixels of ``name`` as stored (top scanline first): integer codes for 8- and 16-bit files,
    float32 for half and float ones; and its spec."""
    config = oiio.ImageSpec()
    if config_alpha:
        config.attribute("oiio:UnassociatedAlpha", 1)
    inp = oiio.ImageInput.open(name, config)
    if inp is None:
        raise ValueError(f"it cannot be opened: {oiio.geterror() or 'unknown error'}")
    try:
        spec = inp.spec()
        fmt = str(spec.format)
        data = inp.read_image(fmt if fmt in _CODES and not len(spec.channelformats) else "float")
        if data is None:
            raise ValueError(inp.geterror() or "it cannot be decoded")
    finally:
        inp.close()
    return np.asarray(data).reshape(spec.height, spec.width, spec.nchannels), spec


def write_channel(path, channel, values, *, source=None):
    """Write ``values`` into one channel of an existing image file, every other channel unchanged.

    Parameters
    ----------
    path : str or os.PathLike
        The image to write (.png, .exr, .tif, .tiff): it keeps its format, sample types, channels,
        compression and attributes.
    channel : 'R', 'G', 'B' or 'A' (any case), or 0 to 3
    values : array_like of float, (H, W), row 0 the bottom row (as a bake's map)
        Linear values; an integer file stores ``round(clip(v, 0, 1) * (2**bits - 1))`` (no sRGB
        encoding, as :func:`write_image`), a half file the nearest half, a float file the value.
    source : None, or another image file whose other channels to take (``path`` then need not
        exist, and ``source`` is not changed): a copy of ``source`` with ``channel`` replaced.

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ChannelError
        Before anything is written: what :func:`check_channel` refuses (of ``source`` or ``path``),
        or ``values`` that are not a finite float map.
    ImageWriteError
        The file could not be written (full disk, read-only target, OpenImageIO failing): ``path``
        keeps its old bytes and no temporary file remains.

    Notes
    -----
    The new file is written beside ``path`` and read back: every channel must decode to what was meant
    (the other channels to their old samples, bit for bit) before it replaces ``path``
    (:mod:`core.files.atomicfile`).
    """
    name = os.fspath(path)
    src = name if source is None else os.fspath(source)
    channel = _channel_name(channel)
    a = np.asarray(values)
    if a.ndim != 2 or not np.issubdtype(a.dtype, np.floating):
        raise ChannelError(f"the map to write into channel {channel} of {name!r} must be a float array (H, W), got "
                           f"{a.dtype} {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ChannelError(f"the map to write into channel {channel} of {name!r} holds "
                           f"{int(np.count_nonzero(~np.isfinite(a)))} values that are not finite")
    check_channel(src, channel, (a.shape[1], a.shape[0]))
    oiio = import_oiio(ImageWriteError)
    try:
        old, spec = _read_samples(oiio, src)
    except ValueError as exc:
        raise ChannelError(f"cannot write channel {channel} of {name!r}: {src!r} cannot be read ({exc})") from exc
    index = [n.upper() for n in spec.channelnames].index(channel)
    new = old.copy()
    column = a[::-1].astype(np.float64)  # the file's top scanline first
    if new.dtype in (np.uint8, np.uint16):
        new[:, :, index] = np.rint(np.clip(column, 0.0, 1.0) * float(np.iinfo(new.dtype).max)).astype(new.dtype)
    else:
        kind = ([str(t) for t in spec.channelformats] or [str(spec.format)] * spec.nchannels)[index]
        v = column.astype(np.float32)
        if kind == "half":
            v = v.astype(np.float16).astype(np.float32)
        elif kind in _CODES:  # an integer channel of a file of mixed sample types, read as float
            top = float(np.iinfo(_CODES[kind]).max)
            v = (np.rint(np.clip(column, 0.0, 1.0) * top) / top).astype(np.float32)
        new[:, :, index] = v
    out_spec = oiio.ImageSpec(spec)
    # Alpha is written as stored, as it was read, and keeps its kind: a TIFF whose alpha is associated
    # (premultiplied: no tiff:UnassociatedAlpha) stays so; the others are written unassociated.
    if src.lower().endswith((".tif", ".tiff")) and not spec.get_int_attribute("tiff:UnassociatedAlpha", 0):
        out_spec.erase_attribute("oiio:UnassociatedAlpha")
    else:
        out_spec.attribute("oiio:UnassociatedAlpha", 1)

    def write(temp):
        write_spec(oiio, temp, out_spec, new)

    def verify(temp):
        got, got_spec = _read_samples(oiio, os.fspath(temp))
        if got.shape != new.shape or got.dtype != new.dtype:
            raise ValueError(f"it holds {got.dtype} {got.shape}, not {new.dtype} {new.shape}")
        if not np.array_equal(got, new, equal_nan=got.dtype.kind == "f"):
            raise ValueError("its pixels differ from those written")
        if [str(t) for t in got_spec.channelformats] != [str(t) for t in spec.channelformats] or \
                str(got_spec.format) != str(spec.format):
            raise ValueError(f"its samples are {got_spec.format}, not {spec.format}")

    from .atomicfile import write_file

    return write_file(name, write, verify=verify, error=ImageWriteError)


def pack_channel(pixels, idx, values):
    """Pixels (in memory, a Blender image's) with channel ``idx`` replaced by ``values``, the others
    exactly as they were.

    Parameters
    ----------
    pixels : array_like of float, (H, W, C) or flat (H * W * C,) as Blender's ``image.pixels``
        (row 0 the bottom row, channels interleaved), 1 <= C <= 4.
    idx : the channel, 0 to C - 1 (or its name 'R', 'G', 'B', 'A')
    values : array_like of float, (H, W) or (H * W,), row 0 the bottom row

    Returns
    -------
    numpy.ndarray of float32, the shape of ``pixels``: a new array.

    Raises
    ------
    ChannelError
        ``values`` do not fit ``pixels`` (sizes), or the pixels have no channel ``idx``.
    """
    p = np.asarray(pixels, dtype=np.float32)
    v = np.asarray(values, dtype=np.float32).reshape(-1)
    if not v.size or p.size % v.size:
        raise ChannelError(f"a map of {v.size} pixels does not fit an image of {p.size} values "
                           "(width x height x channels): bake at the image's size")
    c = p.size // v.size
    if p.ndim == 3 and (p.shape[2] != c or p.shape[0] * p.shape[1] != v.size):
        raise ChannelError(f"a map of {v.size} pixels does not fit an image of {p.shape[1]} x {p.shape[0]} pixels")
    if not 1 <= c <= 4:
        raise ChannelError(f"an image of {c} channels a pixel is not an image these maps are packed into")
    name = _channel_name(idx)
    i = CHANNELS.index(name)
    if i >= c:
        raise ChannelError(f"the image has {c} channel{'s' if c > 1 else ''} ({', '.join(CHANNELS[:c])}): there is "
                           f"no channel {name} to write into")
    out = p.copy().reshape(-1, c)
    out[:, i] = v
    return out.reshape(p.shape)


__all__ = ["CHANNELS", "ChannelError", "check_channel", "write_channel", "pack_channel"]
