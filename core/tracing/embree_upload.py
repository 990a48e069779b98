"""Triangle meshes into an embreex scene through Embree's C API, one memmove per buffer.

embreex's ``TriangleMesh`` fills Embree's vertex and index buffers element by element with Python
indexing of untyped arrays (``tri_indices[i][0]``), about 1.4 us per triangle: 1.4 s for a
1M-triangle target, more than Embree's own BVH build of it (0.35 s here). This module does the same
calls as ``TriangleMesh._build_from_indices`` (``rtcNewGeometry``, ``rtcSetNewGeometryBuffer`` for
the vertices at a 16-byte stride and for the UINT3 indices, ``rtcCommitGeometry``,
``rtcAttachGeometry``, ``rtcReleaseGeometry``) through ``ctypes``, copying each buffer at once.

It needs two things embreex does not publish, both checked before use and at the first call, with
embreex's own ``TriangleMesh`` as the fallback (:func:`available` says which path is taken and
:func:`reason` why):

- the Embree library embreex's scenes come from (Blender has its own, and depending on how it was
  linked embreex calls that one or its vendored copy): on Linux the mapped file holding the virtual
  table of a scene embreex made, elsewhere the one library shipped beside the package
  (``embreex.libs``, ``embreex/.dylibs``);
- the scene handle inside an ``EmbreeScene``: its extension type is ``RTCScene scene_i; int
  is_committed; EmbreeDevice device`` after the object header. The layout is verified on every
  scene: the public ``is_committed`` must read back at the offset after the handle, and the
  object after it must be an ``EmbreeDevice``.

A self-test then builds a small scene both ways and compares Embree's answers for rays that hit and
miss; any difference, error code or exception turns the fast path off for the process.
``MC_AO_EMBREE_UPLOAD=0`` in the environment turns it off too.
"""

import ctypes
import os
import struct
import sys
import threading
from pathlib import Path

import numpy as np

# Embree 4 (rtcore_common.h, rtcore_geometry.h, rtcore_buffer.h).
RTC_GEOMETRY_TYPE_TRIANGLE = 0
RTC_BUFFER_TYPE_INDEX = 0
RTC_BUFFER_TYPE_VERTEX = 1
RTC_FORMAT_UINT3 = 0x5003
RTC_FORMAT_FLOAT3 = 0x9003
RTC_ERROR_NONE = 0
RTC_SCENE_FLAG_ROBUST = 1 << 2  # rtcore_scene.h

_lock = threading.Lock()
_state = {"lib": None, "ok": None, "reason": ""}


def _mapped_files():
    """(start, end, path) of every file mapped into this process (Linux), or None elsewhere."""
    if not sys.platform.startswith("linux"):
        return None
    out = []
    try:
        with open("/proc/self/maps") as f:
            for line in f:
                parts = line.split(None, 5)
                if len(parts) == 6 and parts[5].startswith("/"):
                    lo, hi = parts[0].split("-")
                    out.append((int(lo, 16), int(hi, 16), parts[5].strip()))
    except OSError:
        return None
    return out


def _library_path():
    """Path of the Embree library embreex's extension uses, or None.

    There can be more than one Embree in the process, and the one embreex calls is not always its
    own: the ``bpy`` module maps Blender's ``libembree4.so.4`` privately and embreex uses its
    vendored copy, but a Blender executable that links Embree with global symbols (Debian's 4.3,
    tests/gui/check_embree.py) makes embreex's calls land in Blender's library although the vendored
    copy is mapped too. On Linux the right one is found by where the C++ object behind a new embreex
    scene points: its virtual table lies in the library that made it. Elsewhere it is the copy
    vendored beside the package (``embreex.libs`` on Windows, ``embreex/.dylibs`` on macOS); the
    self-test, which builds a scene both ways and compares every answer, guards that guess.
    """
    from embreex import rtcore_scene

    maps = _mapped_files()
    if maps is not None:
        probe = rtcore_scene.EmbreeScene()
        vtable = ctypes.c_void_p.from_address(_scene_handle(probe)).value
        del probe
        for lo, hi, path in maps:
            if lo <= vtable < hi:
                return path if "embree" in Path(path).name else None
        return None
    import embreex

    pkg = Path(embreex.__file__).resolve().parent
    for folder in (pkg.parent / "embreex.libs", pkg / ".dylibs"):
        found = sorted(folder.glob("*embree4*"))
        if len(found) == 1:
            return str(found[0])
    return None


def _load():
    path = _library_path()
    if path is None:
        raise OSError("the Embree library embreex loaded was not found")
    lib = ctypes.CDLL(path)
    vp, u, sz, i = ctypes.c_void_p, ctypes.c_uint, ctypes.c_size_t, ctypes.c_int
    sig = {
        "rtcGetSceneDevice": (vp, [vp]),
        "rtcReleaseDevice": (None, [vp]),
        "rtcGetDeviceError": (i, [vp]),
        "rtcNewGeometry": (vp, [vp, i]),
        "rtcSetNewGeometryBuffer": (vp, [vp, i, u, i, sz, sz]),
        "rtcCommitGeometry": (None, [vp]),
        "rtcAttachGeometry": (u, [vp, vp]),
        "rtcReleaseGeometry": (None, [vp]),
        "rtcGetSceneFlags": (i, [vp]),
    }
    for name, (res, args) in sig.items():
        fn = getattr(lib, name)
        fn.restype, fn.argtypes = res, args
    return lib


_PTR = struct.calcsize("P")
_HEADER = 2 * _PTR  # ob_refcnt, ob_type


def _scene_handle(scene):
    """The RTCScene inside an embreex EmbreeScene, after checking the object's layout."""
    cls = type(scene)
    if cls.__name__ != "EmbreeScene" or cls.__basicsize__ != _HEADER + 3 * _PTR:
        raise TypeError(f"unexpected EmbreeScene layout (size {cls.__basicsize__})")
    base = id(scene)
    saved = scene.is_committed
    try:
        for probe in (0x5A5A1234, 0x0F0F4321):
            scene.is_committed = probe
            if ctypes.c_int.from_address(base + _HEADER + _PTR).value != probe:
                raise TypeError("EmbreeScene.is_committed is not where expected")
    finally:
        scene.is_committed = saved
    device = ctypes.c_void_p.from_address(base + _HEADER + 2 * _PTR).value
    if not device or type(ctypes.cast(device, ctypes.py_object).value).__name__ != "EmbreeDevice":
        raise TypeError("EmbreeScene.device is not where expected")
    handle = ctypes.c_void_p.from_address(base + _HEADER).value
    if not handle:
        raise TypeError("EmbreeScene has no scene handle")
    return handle


def _attach(lib, scene, positions, triangles):
    if scene.is_committed:
        raise ValueError("the scene is already committed")
    handle = _scene_handle(scene)
    device = lib.rtcGetSceneDevice(handle)
    if not device:
        raise RuntimeError("rtcGetSceneDevice failed")
    try:
        def check(what):
            code = lib.rtcGetDeviceError(device)
            if code != RTC_ERROR_NONE:
                raise RuntimeError(f"Embree error {code} in {what}")

        geom = lib.rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE)
        check("rtcNewGeometry")
        try:
            nv, nt = len(positions), len(triangles)
            vb = lib.rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, 16, nv)
            check("rtcSetNewGeometryBuffer (vertices)")
            padded = np.zeros((nv, 4), np.float32)
            padded[:, :3] = positions
            ctypes.memmove(vb, padded.ctypes.data, padded.nbytes)
            ib = lib.rtcSetNewGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, 12, nt)
            check("rtcSetNewGeometryBuffer (indices)")
            ctypes.memmove(ib, triangles.ctypes.data, triangles.nbytes)
            lib.rtcCommitGeometry(geom)
            check("rtcCommitGeometry")
            lib.rtcAttachGeometry(handle, geom)
            check("rtcAttachGeometry")
        finally:
            lib.rtcReleaseGeometry(geom)
    finally:
        lib.rtcReleaseDevice(device)


def scene_flags(scene):
    """Embree's scene flags of an embreex scene (committed or not); only after :func:`available`."""
    if not available():
        raise RuntimeError(f"the C-API upload is off: {reason()}")
    return int(_state["lib"].rtcGetSceneFlags(_scene_handle(scene)))


def _self_test(lib):
    """Embree's answers for a small mesh uploaded here and by embreex's TriangleMesh must agree."""
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    rng = np.random.default_rng(7)
    positions = rng.uniform(-1, 1, (40, 3)).astype(np.float32)
    triangles = rng.integers(0, 40, (60, 3)).astype(np.uint32)
    mine, theirs = rtcore_scene.EmbreeScene(), rtcore_scene.EmbreeScene()
    _attach(lib, mine, positions, triangles)
    TriangleMesh(theirs, positions, triangles.astype(np.int32))
    org = rng.uniform(-2, 2, (512, 3)).astype(np.float32)
    dirs = (rng.uniform(-1, 1, (512, 3)) - org / 2).astype(np.float32)
    a = mine.run(org, dirs, output=True)
    b = theirs.run(org, dirs, output=True)
    hits = int((b["primID"] >= 0).sum())
    if not (np.array_equal(a["primID"], b["primID"]) and np.array_equal(a["tfar"], b["tfar"])) or not 0 < hits < 512:
        raise RuntimeError(f"self-test: answers differ ({hits} hits)")


def available():
    """Whether :func:`attach_triangles` can be used in this process (decided once)."""
    if _state["ok"] is None:
        with _lock:
            if _state["ok"] is None:
                if os.environ.get("MC_AO_EMBREE_UPLOAD", "1") == "0":
                    _state.update(ok=False, reason="turned off by MC_AO_EMBREE_UPLOAD=0")
                else:
                    try:
                        lib = _load()
                        _self_test(lib)
                        _state.update(lib=lib, ok=True, reason="")
                    except Exception as e:  # any failure: embreex's own path
                        _state.update(ok=False, reason=f"{type(e).__name__}: {e}")
    return _state["ok"]


def reason():
    """Why the fast path is off ('' when it is on or not yet decided)."""
    return _state["reason"]


def attach_triangles(scene, positions, triangles):
    """Attach (V, 3) float32 ``positions`` and (T, 3) uint32 ``triangles`` to an uncommitted
    embreex scene as one triangle geometry; only after :func:`available` returned True."""
    if not available():
        raise RuntimeError(f"the C-API upload is off: {reason()}")
    positions = np.ascontiguousarray(positions, dtype=np.float32).reshape(-1, 3)
    triangles = np.ascontiguousarray(triangles, dtype=np.uint32).reshape(-1, 3)
    if len(triangles) and int(triangles.max()) >= len(positions):
        raise ValueError("a triangle refers to a vertex that does not exist")
    _attach(_state["lib"], scene, positions, triangles)


__all__ = ["available", "reason", "attach_triangles", "scene_flags", "RTC_SCENE_FLAG_ROBUST"]
