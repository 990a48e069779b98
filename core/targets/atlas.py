"""Several targets into one image (an atlas): the bake of its parts, and what each part depends on.

An atlas bakes each of its targets as that target would be baked alone: in its own frame, with the
other targets (those that occlude others) and the occluders as its occluders, over every texel its
UVs cover. Its texels therefore depend on nothing but its own mesh, the settings and the meshes its
rays can reach, which is what lets a rebake keep the texels of every target whose
:func:`fingerprints` did not change and still give the bits of baking the whole atlas again; and
its error estimate, adaptive rounds, denoiser and bent normals never see another target's texels.

:class:`AtlasBake` is the parts as one bake for the executor (:mod:`core.execution`): tile keys are
(target index, tile key), and a part (its prologue, scene and tracing) is set up when its first tile
is baked here and let go after its last (worker processes keep the few they used last), so a bake of
many targets never holds every target's scene at once.
"""

import hashlib
import threading
from collections import OrderedDict

import numpy as np

from .._version import OUTPUT_VERSION
from ..geometry.mesh import Mesh
from ..engine.tilebaker import TileOut

#: Request options whose value never changes a target's texels (how the work is shared out, what
#: is done with the texels after the bake, or the quantities baked beside it).
NOT_IN_FINGERPRINT = ("threads", "workers", "tile_size", "chunk_rays", "margin", "empty_ok", "quantities",
                      "quantity", "ground", "tiles", "merge")


def _update(h, value):
    """Add ``value`` to the hash ``h``: arrays by dtype, shape and bytes; meshes by their arrays;
    containers item by item; anything else by its repr."""
    if isinstance(value, np.ndarray):
        a = np.ascontiguousarray(value)
        h.update(f"a{a.dtype.str}{a.shape};".encode())
        h.update(memoryview(a).cast("B"))
    elif isinstance(value, Mesh):
        h.update(b"mesh;")
        for a in (value.positions, value.triangles, value.uvs, value.given_normals()):
            _update(h, a)
    elif isinstance(value, dict):
        h.update(f"d{len(value)};".encode())
        for k in sorted(value, key=str):
            _update(h, str(k))
            _update(h, value[k])
    elif isinstance(value, (list, tuple)):
        h.update(f"l{len(value)};".encode())
        for v in value:
            _update(h, v)
    elif hasattr(value, "__dataclass_fields__"):
        _update(h, {k: getattr(value, k) for k in value.__dataclass_fields__})
    else:
        h.update(f"v{value!r};".encode())


def digest(*values):
    """A hex digest of ``values`` (:func:`_update`)."""
    h = hashlib.blake2b(digest_size=16)
    for v in values:
        _update(h, v)
    return h.hexdigest()


def occluder_digest(mesh):
    """What of a mesh changes how it occludes: its positions (in world space: the transform too) and
    triangles (their winding decides a back face)."""
    return digest(mesh.positions, mesh.triangles)


def settings_digest(request, quantity, ground_height):
    """What of the request changes a target's texels of ``quantity``: every option but those that
    only share out the work or act after the bake (:data:`NOT_IN_FINGERPRINT`), the ground's world
    height as resolved, and the version of what a bake writes."""
    plain = {k: v for k, v in request.to_dict().items() if k not in NOT_IN_FINGERPRINT and k != "kind"}
    return digest(plain, quantity, ground_height, OUTPUT_VERSION)


def fingerprint(own, settings, occluders):
    """One target's fingerprint from its parts' digests: ``own`` (its mesh, UVs, normals, high-poly
    meshes and cage), ``settings`` (:func:`settings_digest`) and ``occluders`` ({name: digest} of the
    meshes within its reach)."""
    return digest(own, settings, occluders)


class Atlas:
    """Several targets baked into one image: ``core.bake_ao(Atlas([a, b, ...]), occluders, ...)``, the
    same as ``core.bake_ao([a, b, ...], ...)`` with what a plain list cannot say.

    targets : the meshes (distinct names: an atlas tells its targets apart by name).
    occluding : None (every target occludes the others), or one flag per target: False for a target
        that occludes only itself (Blender's "Occludes Other Objects" off).
    keep : None, or the ``record`` of an earlier bake of the atlas (:class:`core.files.atlasrecord.AtlasRecord`;
        {quantity: record} for several quantities): every target whose fingerprint did not change
        keeps its texels from it, and the targets it holds that this list does not name keep theirs.
    """

    def __init__(self, targets, occluding=None, keep=None):
        self.targets = list(targets)
        self.occluding = None if occluding is None else list(occluding)
        self.keep = keep

    @classmethod
    def of(cls, value):
        """An :class:`Atlas` of ``value`` (an Atlas, or a list of meshes)."""
        return value if isinstance(value, cls) else cls(value)

    def __repr__(self):
        return f"Atlas({[getattr(t, 'name', t) for t in self.targets]!r})"


class _Starts:
    """The parts' start stages as one: their counters by target index (as text), each part's added up
    over the times it was set up in this process and over worker processes."""

    def __init__(self, atlas):
        self.atlas = atlas

    def counters(self):
        a = self.atlas
        with a.lock:
            out = {k: dict(v) for k, v in a.done_counters.items()}
            for i, part in a.live.items():
                _add(out.setdefault(str(i), {}), part.start.counters())
        return out


def _add(into, counters):
    for k, v in counters.items():
        if isinstance(v, dict):
            _add(into.setdefault(k, {}), v)
        elif isinstance(v, (int, float)) and not isinstance(v, bool) and isinstance(into.get(k, 0), (int, float)):
            into[k] = into.get(k, 0) + v
        else:
            into.setdefault(k, v)


class AtlasBake:
    """The parts of an atlas as one bake for :func:`core.execution.executor.bake_tiles`.

    Parameters
    ----------
    build : build(i) -> the bake of part ``i`` after its prologue, not yet traced (a
        :class:`core.targets.texels.TexelBake`, or a :class:`core.targets.maps.MapsBake` of several
        quantities).
    s : the atlas's settings (its threads are the executor's).
    planned : the planned work of every part (samples), for progress.
    layouts : {i: the bake of part i laid out without a scene} where this process has them (their
        tiles' rectangles and the parent's bent normals): None in a worker process.
    tiles : {i: how many of part i's tiles this process bakes}, or None (a worker: unknown).
    keep_live : how many parts may be set up at once (the least recently used one goes first).
    """

    def __init__(self, build, s, planned, layouts=None, tiles=None, keep_live=2):
        self.build, self.s, self.planned = build, s, planned
        self.layouts = layouts or {}
        self.left = dict(tiles or {})
        self.keep_live = max(1, int(keep_live))
        self.live = OrderedDict()  # part index -> its bake, set up
        self.busy = {}
        self.done_counters = {}
        self.lock = threading.Lock()
        self.part_locks = {}
        self.start = _Starts(self)
        self.scene_reused = False
        self.request_data = None  # a worker's: the options it baked with (core.pipeline.remote)
        self.pattern = None
        self.shared = self.cancel = self.on_rays = None

    def trace_setup(self, shared, cancel, on_rays=None):
        """Note the scheduler, cancel and ray hook every part is set up with when its first tile comes."""
        self.shared, self.cancel, self.on_rays = shared, cancel, on_rays

    def _acquire(self, i):
        with self.lock:
            plock = self.part_locks.setdefault(i, threading.Lock())
        with plock:
            with self.lock:
                part = self.live.get(i)
                if part is not None:
                    self.busy[i] = self.busy.get(i, 0) + 1
                    self.live.move_to_end(i)
                    return part
            part = self.build(i)
            if self.pattern is not None and not hasattr(part, "lanes"):
                part.trace_setup(self.shared, self.cancel, self.on_rays, pattern=self.pattern)
            else:
                part.trace_setup(self.shared, self.cancel, self.on_rays)
            if self.pattern is None and not hasattr(part, "lanes"):
                self.pattern = part.pattern  # every part draws the same points: one pool for all
            with self.lock:
                self.live[i] = part
                self.busy[i] = self.busy.get(i, 0) + 1
                self._evict()
            return part

    def _release(self, i):
        with self.lock:
            self.busy[i] -= 1
            if i in self.left:
                self.left[i] -= 1
                if self.left[i] <= 0 and not self.busy[i]:
                    self._drop(i)
            self._evict()

    def _evict(self):
        while len(self.live) > self.keep_live:
            idle = next((j for j in self.live if not self.busy.get(j)), None)
            if idle is None:
                return
            self._drop(idle)

    def _drop(self, i):
        part = self.live.pop(i, None)
        if part is not None:
            _add(self.done_counters.setdefault(str(i), {}), part.start.counters())

    def tile(self, key, directions=True):
        """Bake tile ``key`` = (part, the part's tile key): the part's :class:`TileOut`, keyed ``key``."""
        i, k = key
        part = self._acquire(i)
        try:
            out = part.tile(tuple(k), directions)
        finally:
            self._release(i)
        out.key = (i, tuple(k))
        return out

    def part_layout(self, i):
        return self.layouts[i]

    def rect(self, key):
        """Rows, columns and texel count of tile ``key`` (its part's layout)."""
        i, k = key
        return self.layouts[i].rect(tuple(k))

    def outs(self, out):
        """{quantity: TileOut} of a tile of part ``out.key[0]`` (several quantities: its lanes')."""
        layout = self.layouts[out.key[0]]
        if hasattr(layout, "outs"):
            return layout.outs(out)
        return None


def tile_out(data):
    """A :class:`TileOut` from a worker's plain data."""
    return TileOut(**data)


__all__ = ["Atlas", "AtlasBake", "fingerprint", "settings_digest", "occluder_digest", "digest", "NOT_IN_FINGERPRINT"]
