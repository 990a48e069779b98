"""Per-vertex AO as a PLY mesh file: what ``scripts/bake_ao.py --target vertex-colors`` writes.

A binary little-endian PLY (the format Blender, MeshLab, Houdini and most DCC tools import) of the
baked mesh with its AO per vertex:

    ply
    format binary_little_endian 1.0
    comment mc_ao {"mc_ao": {...the bake's metadata...}}
    element vertex V
    property float x            object-space position (the evaluated mesh, modifiers applied)
    property float y
    property float z
    property float ao           the AO, linear, in [0, 1]
    property uchar red          the AO as an 8-bit sRGB-encoded grey: what Blender's byte colour
    property uchar green        attributes store (and what PLY importers read as vertex colours)
    property uchar blue
    element face F
    property list uchar int vertex_indices
    end_header

For AO per face corner, every corner is a vertex of its own (faces keep their corners apart): the
file has one vertex per corner. Metadata is the same dict the image files carry (:mod:`core.files.imageio`),
as one JSON record in a ``comment`` line; :func:`read_ply` gives it back with its types. Files are
written atomically (:mod:`core.files.atomicfile`): complete and read back before they replace anything.
"""

import json
import os

import numpy as np

from .._version import OUTPUT_VERSION, __version__
from .atomicfile import write_file
from ..base.errors import ImageWriteError, McAoError, SettingsError

_VERTEX = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("ao", "<f4"),
                    ("red", "u1"), ("green", "u1"), ("blue", "u1")])


class PlyReadError(McAoError, OSError):
    """A PLY file could not be read (missing, not a PLY file mc_ao wrote)."""


def srgb_bytes(linear):
    """Linear values in [0, 1] -> 8-bit sRGB codes (Blender's ``linearrgb_to_srgb``, rounded)."""
    x = np.clip(np.asarray(linear, dtype=np.float64), 0.0, 1.0)
    s = np.where(x < 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return np.rint(s * 255.0).astype(np.uint8)


def _faces(face_sizes, face_vertices):
    sizes = np.asarray(face_sizes, dtype=np.int64)
    verts = np.asarray(face_vertices, dtype=np.int64)
    if sizes.ndim != 1 or np.any(sizes < 3) or np.any(sizes > 255) or sizes.sum() != len(verts):
        raise SettingsError("faces must have 3 to 255 corners each, and face_vertices one index per corner")
    return sizes, verts


def write_ply(path, positions, face_sizes, face_vertices, ao, metadata=None):
    """Write the mesh (``positions`` (V, 3); faces as ``face_sizes`` (F,) and their corners'
    ``face_vertices`` (sum of sizes,)) with ``ao`` (V,) per vertex to ``path``, atomically."""
    positions = np.asarray(positions, dtype=np.float64)
    ao = np.asarray(ao, dtype=np.float64)
    if positions.ndim != 2 or positions.shape[1] != 3 or ao.shape != (len(positions),):
        raise SettingsError(f"positions must be (V, 3) and ao (V,), got {positions.shape} and {ao.shape}")
    sizes, verts = _faces(face_sizes, face_vertices)
    if len(verts) and (verts.min() < 0 or verts.max() >= len(positions)):
        raise SettingsError("face_vertices index vertices that do not exist")
    record = dict(metadata or {})
    record.setdefault("version", __version__)
    record.setdefault("output_version", OUTPUT_VERSION)
    text = json.dumps({"mc_ao": record}, sort_keys=True)
    if "\n" in text:
        raise SettingsError("metadata must fit on one line")
    header = (f"ply\nformat binary_little_endian 1.0\ncomment mc_ao {text}\nelement vertex {len(positions)}\n"
              "property float x\nproperty float y\nproperty float z\nproperty float ao\n"
              "property uchar red\nproperty uchar green\nproperty uchar blue\n"
              f"element face {len(sizes)}\nproperty list uchar int vertex_indices\nend_header\n").encode("utf-8")
    vertex = np.empty(len(positions), _VERTEX)
    vertex["x"], vertex["y"], vertex["z"] = positions.T.astype(np.float32)
    vertex["ao"] = ao.astype(np.float32)
    grey = srgb_bytes(ao)
    vertex["red"] = vertex["green"] = vertex["blue"] = grey
    # Faces: per face one count byte, then its indices as int32.
    face_bytes = bytearray()
    starts = np.concatenate([[0], np.cumsum(sizes)])
    dtype_cache = {}
    for k in np.unique(sizes):
        dtype_cache[int(k)] = np.dtype([("n", "u1"), ("v", "<i4", (int(k),))])
    if len(sizes) and np.all(sizes == sizes[0]):
        rec = np.empty(len(sizes), dtype_cache[int(sizes[0])])
        rec["n"] = sizes[0]
        rec["v"] = verts.reshape(len(sizes), int(sizes[0]))
        face_bytes = rec.tobytes()
    else:
        for f, k in enumerate(sizes):
            rec = np.empty(1, dtype_cache[int(k)])
            rec["n"] = k
            rec["v"] = verts[starts[f]:starts[f + 1]]
            face_bytes += rec.tobytes()
    data = header + vertex.tobytes() + bytes(face_bytes)

    def write(temp):
        with open(temp, "wb") as f:
            f.write(data)

    def verify(temp):
        got = read_ply(temp)
        if not (np.array_equal(got[3], vertex["ao"]) and np.array_equal(got[2], verts)):
            raise ValueError("it reads back differently")

    return write_file(path, write, verify=verify, error=ImageWriteError)


def read_ply(path):
    """(positions (V, 3) float32, face sizes (F,), face vertices, ao (V,) float32, metadata) of a
    PLY file :func:`write_ply` wrote."""
    name = os.fspath(path)
    try:
        with open(name, "rb") as f:
            data = f.read()
    except OSError as exc:
        raise PlyReadError(f"cannot read {name!r}: {exc.strerror or exc}") from None
    end = data.find(b"end_header\n")
    if not data.startswith(b"ply\n") or end < 0:
        raise PlyReadError(f"cannot read {name!r}: not a PLY file")
    header = data[:end].decode("utf-8", "replace").splitlines()
    metadata, counts = {}, {}
    for line in header:
        if line.startswith("comment mc_ao "):
            try:
                metadata = json.loads(line[len("comment mc_ao "):])["mc_ao"]
            except (ValueError, KeyError, TypeError):
                metadata = {}
        elif line.startswith("element "):
            _, kind, n = line.split()
            counts[kind] = int(n)
    if "format binary_little_endian 1.0" not in header or "property float ao" not in header:
        raise PlyReadError(f"cannot read {name!r}: not a PLY file of per-vertex AO written by mc_ao")
    body = data[end + len(b"end_header\n"):]
    nv, nf = counts.get("vertex", 0), counts.get("face", 0)
    vertex = np.frombuffer(body, _VERTEX, count=nv)
    offset = nv * _VERTEX.itemsize
    sizes, verts = [], []
    for _ in range(nf):
        k = body[offset]
        sizes.append(k)
        verts.append(np.frombuffer(body, "<i4", count=k, offset=offset + 1))
        offset += 1 + 4 * k
    if offset != len(body):
        raise PlyReadError(f"cannot read {name!r}: it is cut short or has trailing data")
    positions = np.stack([vertex["x"], vertex["y"], vertex["z"]], axis=1)
    return (positions, np.array(sizes, np.int64), np.concatenate(verts) if verts else np.zeros(0, np.int64),
            vertex["ao"].copy(), metadata)


__all__ = ["write_ply", "read_ply", "srgb_bytes", "PlyReadError"]
