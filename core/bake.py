"""The per-texel ambient occlusion baker: UV rasterisation, hemisphere sampling, Embree occlusion rays.

For a surface point x with shading normal n, AO(x) = (1/pi) * integral over the hemisphere of
V(x, w) cos(theta) dw, V = 1 where the ray from x along w meets nothing within max_distance. A texel's
value is the mean AO over the part of the surface its square covers (see :mod:`core.raster`).

Estimators: cosine-weighted directions (p = cos/pi) give the term V(w), variance AO(1 - AO), exactly
0 on open surfaces; uniform directions (p = 1/(2 pi)) give 2 cos(theta) V(w). Both estimate the same
AO.

Rays leave from the surface point pushed off along the geometric normal, on the side the shading
normal faces, by an offset that scales with the scene's size and the point's distance from the origin
(float32 rays lose absolute precision with both). A direction from the shading hemisphere that points
below the geometric surface (possible where interpolated normals bend away from the face) counts as
occluded without being traced: that is what a ray leaving the true surface would meet first, the
surface itself, and it keeps AO continuous across smooth-shaded terminators.
"""

import math
import os
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np

from ._version import __version__
from .errors import BakeCancelled, BakeMemoryError, MeshError, SettingsError
from .margin import dilate
from .mesh import Mesh
from .patterns import SOURCE_NAMES, TexelPattern
from . import raster as R
from .raster import bin_triangles, prepare, rasterize_tile
from .stats import RunningStats, z_for_confidence
from .warps import TWO_PI, basis_components, concentric_disk_xy

DISTRIBUTIONS = ("cosine", "uniform")
#: Largest image side the baker accepts (the same as Blender's image size limit).
MAX_RESOLUTION = 65536
#: Most samples per texel. Chunks stay bounded for any count (a texel's samples are traced in
#: pieces), but the sample tables grow with it: 2^20 keeps them to tens of MiB, and a reference
#: bake rarely needs a tenth of it.
MAX_SAMPLES = 1 << 20
#: Samples of one texel traced in one piece; more are traced in pieces of this many.
SAMPLE_PIECE = 1 << 16
#: Offsets off the surface: relative to the scene's bounding-box diagonal and to |position|.
EPS_SCENE = 1e-6
EPS_POSITION = 2.0 ** -18


@dataclass
class BakeResult:
    """What a bake returns. Arrays are (H, W), row 0 is v = 0 (Blender's pixel order).

    ao : float32 in [0, 1]; covered texels hold their estimate, margin texels the dilated value,
        the rest 0.
    mask : bool, texels a UV triangle covers.
    stderr : float32, each covered texel's standard error (0 elsewhere).
    samples : int32, samples taken per covered texel (0 elsewhere).
    rays : rays traced (directions below the geometric surface are not traced).
    seconds : wall time of the bake; trace_seconds : time inside embreex, summed over threads.
    metadata : settings and version, for image files.
    report : counts of what the input held: degenerate UV triangles skipped, triangles of zero area
        in space skipped (they have no surface), triangles with UVs
        outside [0, 1] (only their part inside the image is baked), texels covered by more than one
        UV island (averaged over all surfaces covering them), covered texels.
    """

    ao: np.ndarray
    mask: np.ndarray
    stderr: np.ndarray
    samples: np.ndarray
    rays: int
    seconds: float
    trace_seconds: float
    threads: int
    metadata: dict = field(default_factory=dict)
    report: dict = field(default_factory=dict)

    @property
    def rays_per_second(self):
        return self.rays / self.seconds if self.seconds > 0 else float("nan")


def _positive_int(value, what, lo=1):
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise SettingsError(f"{what} must be an integer, got {value!r}")
    if value < lo:
        raise SettingsError(f"{what} must be at least {lo}, got {value}")
    return int(value)


def _resolution(resolution):
    if isinstance(resolution, (int, np.integer)) and not isinstance(resolution, bool):
        resolution = (resolution, resolution)
    try:
        w, h = resolution
    except (TypeError, ValueError):
        raise SettingsError(f"resolution must be an integer or a (width, height) pair, got {resolution!r}") from None
    w = _positive_int(w, "resolution width")
    h = _positive_int(h, "resolution height")
    if w > MAX_RESOLUTION or h > MAX_RESOLUTION:
        raise SettingsError(f"resolution {w} x {h} exceeds the largest supported side, {MAX_RESOLUTION}")
    return w, h


def available_memory():
    """Bytes of memory available to a new allocation (MemAvailable on Linux), or None if unknown."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    try:
        return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")
    except (ValueError, OSError, AttributeError):
        return None


def estimate_memory(width, height, triangles, threads, chunk_rays, samples=1):
    """Peak bytes a bake needs: output planes, margin work, per-thread chunks, sample tables, triangles.

    A chunk holds at most ``max(chunk_rays, SAMPLE_PIECE)`` rays (a texel with more samples is
    traced in pieces), but the sample sources keep tables as long as the largest sample count: the base
    sequence (Sobol', Halton) and, for stratified points, one key per stratum of the texels in a
    chunk.
    """
    texels = width * height
    planes = texels * (4 + 4 + 4 + 1)          # ao, stderr, samples, mask
    margin_work = texels * (4 + 4 + 1 + 1)      # dilation sums, counts and masks
    per_ray = 600                               # float64 temporaries of one chunk, generously
    chunks = threads * max(chunk_rays, min(samples, SAMPLE_PIECE)) * per_ray
    tables = samples * 48 + threads * samples * 24
    tris = triangles * 300                      # texel-space corners, affine maps, Embree buffers
    return planes + margin_work + chunks + tables + tris


def interval_half_width(n, mean, m2, z, binary, bound):
    """Half-width of the confidence interval adaptive sampling stops on, per texel.

    A texel whose samples all agree has zero sample variance, yet 16 open rays out of 16 do not
    prove AO = 1: a texel with AO 0.9 shows that 19% of the time. So for the cosine estimator, whose
    terms are 0 or 1, the interval is Agresti and Coull's: add z^2/2 successes and z^2/2 failures,
    p~ = (k + z^2/2) / (n + z^2), half-width z sqrt(p~ (1 - p~) / (n + z^2)). It never collapses, and
    an all-open texel stops once n is about 2.7 / target (the "rule of three"). Other estimators
    (uniform directions, falloff) use the sample variance, and the same bound, scaled to the terms'
    range [0, bound], when every sample agrees.
    """
    n = np.asarray(n, dtype=np.float64)
    z2 = z * z
    safe = np.maximum(n, 1.0)

    def agresti_coull(p):
        pt = (p * n + z2 / 2.0) / (n + z2)
        return z * np.sqrt(pt * (1.0 - pt) / (n + z2))

    if binary:
        return agresti_coull(np.clip(mean, 0.0, 1.0))
    var = np.nan_to_num(RunningStats.from_moments(n, mean, m2).variance)  # 0 where n < 2
    sample = z * np.sqrt(var / safe)
    return np.where(var > 0, sample, bound * agresti_coull(np.clip(mean / bound, 0.0, 1.0)))


def auto_tile_size(width, height, samples, threads):
    """A power of two between 16 and 256: about 2^17 rays per tile, so fixed costs (rasterising a
    tile, a few dozen numpy calls per chunk) stay small next to tracing, and at least four tiles per
    thread, so threads share the work evenly."""
    side = 2 ** round(math.log2(math.sqrt((1 << 17) / samples)))
    enough = 2 ** math.floor(math.log2(max(1.0, math.sqrt(width * height / (4 * threads)))))
    return int(min(max(min(side, enough), 16), 256))


def _cancelled(cancel):
    if cancel is None:
        return False
    if hasattr(cancel, "is_set"):
        return cancel.is_set()
    return bool(cancel())


class _Shared:
    """State the worker threads share: progress, cancellation, errors, timing.

    Progress is reported on the bake's own events (each chunk of rays traced, each tile finished),
    never throttled by a clock: what a caller sees does not depend on how fast the machine is.
    Callers that draw a progress bar throttle their drawing themselves.
    """

    def __init__(self, total_work, progress, cancel):
        self.lock = threading.Lock()
        self.total = max(total_work, 1)
        self.done = 0
        self.progress = progress
        self.cancel = cancel
        self.stop = threading.Event()
        self.trace_seconds = 0.0
        self.rays = 0

    def check(self):
        if self.stop.is_set():
            raise _Stop()
        if _cancelled(self.cancel):
            self.stop.set()
            raise _Stop()

    def advance(self, work, rays=0, trace_seconds=0.0):
        with self.lock:
            self.done += work
            self.rays += rays
            self.trace_seconds += trace_seconds
            if self.progress is not None and work > 0:
                self.progress(min(self.done / self.total, 1.0))


class _Stop(Exception):
    """Raised inside workers once the bake is cancelled or another worker failed."""


def _embree_scene(meshes):
    """A committed Embree scene of ``meshes`` (one geometry), and its positions and triangles."""
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    positions = np.concatenate([m.positions for m in meshes])
    offsets = np.cumsum([0] + [len(m.positions) for m in meshes[:-1]])
    tris = np.concatenate([m.triangles + o for m, o in zip(meshes, offsets)])
    scene = rtcore_scene.EmbreeScene()
    mesh = TriangleMesh(scene, positions.astype(np.float32), tris.astype(np.int32))
    # Commit (build the BVH) now, once, before any worker thread traces.
    scene.run(np.zeros((1, 3), np.float32), np.array([[0, 0, 1]], np.float32), query="OCCLUDED",
              dists=np.ones(1, np.float32))
    return scene, mesh, positions


class _Tracer:
    """Occlusion queries against the committed Embree scene of the target and its occluders.

    Contact: a face of another object lying on the target's surface (a box resting on a floor) sits
    where the pushed-off ray origin cannot see it: the origin starts inside the box. Cycles, which
    starts rays on the surface and skips only the triangle they leave, finds that face at distance 0
    and calls the point occluded, which is right for a point in contact. To agree, samples are first
    probed against a second scene of the occluders alone with a ray of length 2 * offset crossing the
    surface along the normal: a hit means other geometry coincides with the surface there, and the
    sample is occluded in every direction.
    """

    def __init__(self, meshes, ignore_backfaces, falloff, max_distance):
        self.scene, self._mesh, positions = _embree_scene(meshes)
        self.face_normals = np.concatenate([m.face_normals for m in meshes])
        self.contact_scene = _embree_scene(meshes[1:])[:2] if len(meshes) > 1 else None
        lo, hi = positions.min(axis=0), positions.max(axis=0)
        self.extent = float(np.linalg.norm(hi - lo))
        self.ignore_backfaces = ignore_backfaces
        self.falloff = falloff
        self.max_distance = max_distance
        self.tfar = np.float32(min(max_distance, 1e37))

    def contact(self, points, normals):
        """Per surface point (n, 3), whether another object's surface crosses the segment of length
        2 * offset through it along its unit geometric normal (n, 3): whether something touches it."""
        points = np.asarray(points, dtype=np.float64)
        e = self.offset(np.abs(points).max(axis=1))
        below = (points - normals * e[:, None]).astype(np.float32)
        hit = self.contact_scene[0].run(below, np.ascontiguousarray(normals, dtype=np.float32), query="OCCLUDED",
                                        dists=(2.0 * e).astype(np.float32))
        return hit >= 0

    def offset(self, max_abs):
        """Distance to push ray origins off the surface, given each point's largest |coordinate|."""
        return EPS_SCENE * self.extent + EPS_POSITION * max_abs

    def visibility(self, org, dirs):
        """Per ray, 1 for unoccluded within max_distance, 0 for occluded, between with falloff."""
        n = len(org)
        o32 = np.ascontiguousarray(org, dtype=np.float32)
        d32 = np.ascontiguousarray(dirs, dtype=np.float32)
        if not self.ignore_backfaces and self.falloff == 0:
            hit = self.scene.run(o32, d32, query="OCCLUDED", dists=np.full(n, self.tfar, np.float32))
            return (hit < 0).astype(np.float64)
        # Hit distances are needed: walk past back faces, weigh hits by distance.
        remaining = np.full(n, self.tfar, np.float32)
        travelled = np.zeros(n)
        vis = np.ones(n)
        todo = np.arange(n)
        for _ in range(64):
            if not len(todo):
                break
            out = self.scene.run(o32[todo], d32[todo], dists=remaining[todo].copy(), output=True)
            prim = out["primID"]
            hit = prim >= 0
            t = out["tfar"].astype(np.float64)
            if self.ignore_backfaces:
                back = hit & (np.einsum("ij,ij->i", self.face_normals[np.maximum(prim, 0)], dirs[todo]) > 0)
            else:
                back = np.zeros_like(hit)
            front = hit & ~back
            idx = todo[front]
            dist = travelled[idx] + t[front]
            if self.falloff > 0:
                vis[idx] = 1.0 - np.clip(1.0 - dist / self.max_distance, 0.0, 1.0) ** self.falloff
            else:
                vis[idx] = 0.0
            # Back-face hits: continue from just past the hit point with the distance left.
            cont = todo[back]
            if len(cont):
                hit_at = org[cont] + dirs[cont] * t[back, None]
                step = t[back] + self.offset(np.abs(hit_at).max(axis=1))
                travelled[cont] += step
                o32[cont] = (org[cont] + dirs[cont] * travelled[cont, None]).astype(np.float32)
                remaining[cont] = np.maximum(self.tfar - travelled[cont], 0).astype(np.float32)
                cont = cont[remaining[cont] > 0]
            todo = cont
        return vis


def _affine(col, tab, first, dx, dy):
    """One component of a per-triangle affine map of the packed table (core.raster.TABLE_*): the
    value at the origin plus dx and dy times its derivatives, which sit 3 and 6 columns further."""
    return col(tab, first) + dx * col(tab, first + 3) + dy * col(tab, first + 6)


class _TileBaker:
    def __init__(self, tris, mesh, tracer, pattern, settings, width, height, shared):
        self.tris, self.mesh, self.tracer, self.pattern = tris, mesh, tracer, pattern
        self.s = settings
        # The terms of each estimator: cosine-weighted without falloff gives 0 or 1; uniform gives
        # 2 cos(theta) V in [0, 2]; falloff gives values in [0, 1].
        self.binary = settings["distribution"] == "cosine" and settings["falloff"] == 0
        self.bound = 2.0 if settings["distribution"] == "uniform" else 1.0
        self.width, self.height = width, height
        self.shared = shared

    def _surface(self, frag, sel, ux, uy, k):
        """Surface samples of the chunk as float32 component planes (3, g, k): position, unit shading
        normal and geometric normal oriented to the shading normal's side.

        Texels inside one triangle (the common case) gather that triangle's row of the packed table
        once per texel and broadcast it over their k samples; split texels pick a sub-triangle per
        sample and gather per sample. Component planes, not (n, 3) arrays, keep numpy's inner loops
        long.
        """
        W = self.width
        g = len(sel)
        full = frag.full_tri[sel]
        simple = full >= 0
        # float32 throughout: rounding the position (6e-8 |p|) stays far below the ray offset
        # (EPS_SCENE * extent + EPS_POSITION * |p|), so rays never start behind the surface.
        pos = np.empty((3, g, k), np.float32)
        nrm = np.empty((3, g, k), np.float32)
        gn = np.empty((3, g, k), np.float32)

        def fill(rows, tab, dx, dy, col):
            for c in range(3):
                pos[c, rows] = _affine(col, tab, R.TABLE_P0 + c, dx, dy)
                nrm[c, rows] = _affine(col, tab, R.TABLE_N0 + c, dx, dy)
                gn[c, rows] = col(tab, R.TABLE_FN + c)

        if simple.any():
            # bake() orders texels simple-first, so the simple rows are a prefix: views, not copies.
            n_simple = int(simple.sum())
            rows = slice(0, n_simple) if simple[:n_simple].all() else np.flatnonzero(simple)
            tri = full[rows]
            tex = frag.texels[sel[rows]]
            cx = ((tex % W) - self.tris.origin_xy[tri, 0]).astype(np.float32)[:, None]
            cy = ((tex // W) - self.tris.origin_xy[tri, 1]).astype(np.float32)[:, None]
            if k >= 32:
                # Gather each texel's row once and broadcast it over its k samples.
                fill(rows, self.tris.table[tri], cx + ux[rows], cy + uy[rows], lambda t, i: t[:, i, None])
            else:
                # Few samples per texel: broadcasting over a short inner axis is slow in numpy, so
                # repeat the rows per sample and work on long flat arrays instead.
                shape = (len(tri), k)
                tab = np.repeat(np.take(self.tris.table_t, tri, axis=1), k, axis=1)
                fill(rows, tab, cx + ux[rows], cy + uy[rows], lambda t, i: t[i].reshape(shape))
        if not simple.all():
            rows = np.flatnonzero(~simple)
            t_loc = np.repeat(sel[rows], k)
            a, b = ux[rows].ravel(), uy[rows].ravel()
            j = np.searchsorted(frag.sub_key, t_loc + a, side="right")
            j = np.clip(j, frag.sub_start[t_loc], frag.sub_start[t_loc + 1] - 1)
            lo = np.where(j > frag.sub_start[t_loc], frag.sub_cdf[np.maximum(j - 1, 0)], 0.0)
            a = np.clip((a - lo) / np.maximum(frag.sub_cdf[j] - lo, 1e-300), 0.0, 1.0)
            # Heitz 2019's low-distortion square-to-triangle map (pbrt-v4's SampleUniformTriangle).
            first = a < b
            b0 = np.where(first, a / 2, a - b / 2)
            b1 = np.where(first, b - a / 2, b / 2)
            b2 = 1.0 - b0 - b1
            c3 = frag.sub_xy[j]
            tab = np.take(self.tris.table_t, frag.sub_tri[j], axis=1)  # (23, samples)
            dx = b0 * c3[:, 0, 0] + b1 * c3[:, 1, 0] + b2 * c3[:, 2, 0] - tab[R.TABLE_ORIGIN]
            dy = b0 * c3[:, 0, 1] + b1 * c3[:, 1, 1] + b2 * c3[:, 2, 1] - tab[R.TABLE_ORIGIN + 1]
            shape = (len(rows), k)
            if rows[0] == g - len(rows):
                rows = slice(g - len(rows), g)  # the split rows are the suffix
            fill(rows, tab, dx.reshape(shape), dy.reshape(shape), lambda t, i: t[i].reshape(shape))
        ln = np.sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2])
        ok = ln > np.float32(1e-12)
        inv = np.float32(1) / np.where(ok, ln, np.float32(1))
        n = nrm
        for c in range(3):
            n[c] = np.where(ok, nrm[c] * inv, gn[c])
        flip = (gn[0] * n[0] + gn[1] * n[1] + gn[2] * n[2]) < 0
        gn[:, flip] *= -1.0
        return pos, n, gn

    def _values(self, frag, sel, start, k):
        s = self.s
        u = self.pattern.points_by_dim(frag.texels[sel], start, k).astype(np.float32)  # (4, g, k)
        p, n, gn = self._surface(frag, sel, u[2], u[3], k)
        u0, u1 = u[0], u[1]
        if s["distribution"] == "cosine":
            lx, ly = concentric_disk_xy(u0, u1)  # Malley: lift the disk onto the hemisphere
            lz = np.sqrt(np.maximum(np.float32(0), np.float32(1) - lx * lx - ly * ly))
        else:
            lz = u0
            r = np.sqrt(np.maximum(np.float32(0), np.float32(1) - lz * lz))
            phi = np.float32(TWO_PI) * u1
            lx, ly = r * np.cos(phi), r * np.sin(phi)
        sx, sy, sz, tx, ty, tz = basis_components(n[0], n[1], n[2])
        d = np.empty((3, len(sel), k), np.float32)
        d[0] = lx * sx + ly * tx + lz * n[0]
        d[1] = lx * sy + ly * ty + lz * n[1]
        d[2] = lx * sz + ly * tz + lz * n[2]
        above = (d[0] * gn[0] + d[1] * gn[1] + d[2] * gn[2]) > 0
        eps = self.tracer.offset(np.maximum(np.maximum(np.abs(p[0]), np.abs(p[1])), np.abs(p[2])))
        probe_seconds = 0.0
        near = frag.contact[sel]
        if near.any():
            # Samples where another object's face lies on the surface are occluded (see _Tracer);
            # only texels whose coarse probes found contact (see _contact_texels) are probed per sample.
            rows = np.flatnonzero(near)
            t0 = time.perf_counter()
            touching = self.tracer.contact(p[:, rows].reshape(3, -1).T, gn[:, rows].reshape(3, -1).T)
            probe_seconds = time.perf_counter() - t0
            above[rows] &= ~touching.reshape(len(rows), k)
        # Usually every direction is above the surface: then take the planes whole, not by index.
        idx = slice(None) if above.all() else np.flatnonzero(above.ravel())
        n_rays = above.size if isinstance(idx, slice) else len(idx)
        org = np.empty((n_rays, 3), np.float32)
        dirs = np.empty((n_rays, 3), np.float32)
        e = eps.ravel()[idx]
        for c in range(3):
            org[:, c] = p[c].ravel()[idx] + gn[c].ravel()[idx] * e
            dirs[:, c] = d[c].ravel()[idx]
        vis = np.zeros(above.size)
        t0 = time.perf_counter()
        vis[idx] = self.tracer.visibility(org, dirs)
        dt = time.perf_counter() - t0 + probe_seconds
        vis = vis.reshape(len(sel), k)
        if s["distribution"] == "uniform":
            vis *= 2.0 * lz
        return vis, n_rays, dt

    def _contact_texels(self, frag):
        """Per texel, whether another object's surface touches this one somewhere in the texel.

        Probes (see _Tracer) at the corners and centre of texels inside one triangle, and at the
        corners and centroid of every sub-triangle of split texels: contact is a property of the
        position, not of the direction, so texels that no probe finds in contact skip the per-sample
        probes. Contact smaller than these probe points are apart can go unnoticed.
        """
        n_tex = len(frag.texels)
        if self.tracer.contact_scene is None or n_tex == 0:
            return np.zeros(n_tex, bool)
        if self.s["samples"] <= 8:
            return np.ones(n_tex, bool)  # as few samples as probe points: probe the samples themselves
        W = self.width
        corners = np.array([[0, 0], [1, 0], [0, 1], [1, 1], [0.5, 0.5]])
        simple = np.flatnonzero(frag.full_tri >= 0)
        tex = frag.texels[simple]
        xy_s = (np.stack([tex % W, tex // W], 1)[:, None, :] + corners[None]).reshape(-1, 2)
        tri_s = np.repeat(frag.full_tri[simple], len(corners))
        own_s = np.repeat(simple, len(corners))
        c3 = frag.sub_xy
        xy_p = np.concatenate([c3, c3.mean(axis=1, keepdims=True)], axis=1).reshape(-1, 2)
        tri_p = np.repeat(frag.sub_tri, 4)
        own_p = np.repeat(frag.sub_texel, 4)
        xy = np.concatenate([xy_s, xy_p])
        tri = np.concatenate([tri_s, tri_p])
        own = np.concatenate([own_s, own_p])
        tab = np.take(self.tris.table_t, tri, axis=1).astype(np.float64)
        dx = xy[:, 0] - self.tris.origin_xy[tri, 0]
        dy = xy[:, 1] - self.tris.origin_xy[tri, 1]
        row = lambda t, i: t[i]  # noqa: E731
        pos = np.stack([_affine(row, tab, R.TABLE_P0 + c, dx, dy) for c in range(3)], axis=1)
        fn = np.stack([tab[R.TABLE_FN + c] for c in range(3)], axis=1)
        hit = self.tracer.contact(pos, fn)
        return np.bincount(own[hit], minlength=n_tex) > 0

    def bake(self, key, tri_ids):
        s, shared = self.s, self.shared
        ty, tx = key
        tile = s["tile"]
        x0, y0 = tx * tile, ty * tile
        x1, y1 = min(x0 + tile, self.width), min(y0 + tile, self.height)
        frag = rasterize_tile(self.tris, tri_ids, self.width, self.height, x0, y0, x1, y1)
        frag.contact = self._contact_texels(frag)
        n_tex = len(frag.texels)
        stats = RunningStats(n_tex)
        if n_tex == 0:
            return frag, stats
        adaptive = s["target_error"] > 0
        total = s["samples"]
        k = min(s["min_samples"], total) if adaptive else total
        start = 0
        # Texels inside one triangle first: chunks then hold them as a contiguous block (see _surface).
        active = np.argsort(frag.full_tri < 0, kind="stable")
        z = z_for_confidence(0.95)
        while len(active):
            # A texel with more than SAMPLE_PIECE samples is traced in pieces of that many, so a
            # chunk holds at most max(chunk_rays, SAMPLE_PIECE) rays. The pieces do not depend on
            # chunk_rays, so neither do the sums (bit for bit). Stratified points sort one key per
            # stratum of every texel in the chunk, so their chunks hold fewer texels.
            step = min(k, SAMPLE_PIECE)
            per_texel = max(step, total) if s["source"] == "stratified" else step
            g = max(1, s["chunk_rays"] // per_texel)
            for c0 in range(0, len(active), g):
                sel = active[c0:c0 + g]
                for j0 in range(0, k, step):
                    shared.check()
                    m = min(step, k - j0)
                    values, rays, dt = self._values(frag, sel, start + j0, m)
                    part = RunningStats.from_moments(stats.n[sel], stats.mean[sel], stats.m2[sel]).add(values)
                    stats.n[sel], stats.mean[sel], stats.m2[sel] = part.n, part.mean, part.m2
                    shared.advance(len(sel) * m, rays, dt)
            start += k
            if not adaptive or start >= total:
                break
            half = interval_half_width(stats.n[active], stats.mean[active], stats.m2[active], z,
                                       binary=self.binary, bound=self.bound)
            active = active[half > s["target_error"]]
            k = min(start, total - start)  # double each round: Sobol' prefixes stay powers of two
        # Credit the work the adaptive stop saved, so progress reaches 1.
        shared.advance(n_tex * total - int(stats.n.sum()))
        return frag, stats


def _validate(target, occluders, resolution, samples, min_samples, target_error, max_distance, distribution,
              source, margin, seed, threads, falloff):
    if not isinstance(target, Mesh):
        raise SettingsError(f"the target must be a core.Mesh, got {type(target).__name__}")
    if target.uvs is None:
        raise MeshError(f"mesh {target.name!r} has no UVs: the baker needs a UV map to know where each texel lies")
    occluders = list(occluders or ())
    for o in occluders:
        if not isinstance(o, Mesh):
            raise SettingsError(f"occluders must be core.Mesh objects, got {type(o).__name__}")
    w, h = _resolution(resolution)
    samples = _positive_int(samples, "samples")
    if samples > MAX_SAMPLES:
        raise SettingsError(f"samples must be at most {MAX_SAMPLES} per texel, got {samples}")
    min_samples = _positive_int(min_samples, "min_samples")
    try:
        target_error = float(target_error)
        max_distance = float(max_distance)
        falloff = float(falloff)
    except (TypeError, ValueError):
        raise SettingsError("target_error, max_distance and falloff must be numbers") from None
    if not (math.isfinite(target_error) and target_error >= 0):
        raise SettingsError(f"target_error must be a finite number >= 0 (0 turns adaptive sampling off), got {target_error}")
    if not (max_distance > 0):  # also refuses NaN
        raise SettingsError(f"max_distance must be positive (inf for unlimited), got {max_distance}")
    if not (math.isfinite(falloff) and falloff >= 0):
        raise SettingsError(f"falloff must be a finite number >= 0, got {falloff}")
    if falloff > 0 and not math.isfinite(max_distance):
        raise SettingsError("a distance falloff needs a finite max_distance to fall off over")
    if distribution not in DISTRIBUTIONS:
        raise SettingsError(f"unknown distribution {distribution!r}; choose one of {', '.join(DISTRIBUTIONS)}")
    if source not in SOURCE_NAMES:
        raise SettingsError(f"unknown sample source {source!r}; choose one of {', '.join(SOURCE_NAMES)}")
    margin = _positive_int(margin, "margin", lo=0)
    seed = _positive_int(seed, "seed", lo=0)
    if threads is None:
        threads = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
    threads = _positive_int(threads, "threads")
    return dict(occluders=occluders, width=w, height=h, samples=samples, min_samples=min(min_samples, samples),
                target_error=target_error, max_distance=max_distance, distribution=distribution, source=source,
                margin=margin, seed=seed, threads=threads, falloff=falloff)


#: Occluders farther than this many target sizes from the target are refused: float32 rays cannot
#: hold both (and so far away they cannot occlude it measurably).
MAX_SCENE_SPAN = 1e15


def _normalized_scene(target, occluders):
    """The target and its occluders in a frame centred on the target and scaled to its size.

    AO does not depend on the unit (max_distance scales with it), but float32 rays do: a scene
    modelled in metres at 1e13 or at 1e-14 loses the offsets that keep rays off their own surface.
    In this frame the target spans about 1 around the origin whatever units the input used.
    Occluders that are the target again (the same object or the same surface) are dropped: a
    surface coinciding with the target would hide every ray.

    Returns (target, occluders, unit): the world length of one unit of the new frame.
    """
    kept = []
    for o in occluders:
        if o is target or target.same_geometry(o) or any(o is k or k.same_geometry(o) for k in kept):
            continue
        kept.append(o)
    lo, hi = target.positions.min(axis=0), target.positions.max(axis=0)
    with np.errstate(over="ignore", invalid="ignore"):
        unit = float(np.max(hi - lo))
    if not math.isfinite(unit):
        raise MeshError(f"mesh {target.name!r} spans more than the largest float ({unit}); scale it down")
    if unit <= 0 or unit < np.finfo(np.float64).tiny * 1e3:
        unit = 1.0  # a point: every triangle is degenerate and skipped anyway
    centre = (lo + hi) / 2.0
    scene = []
    for o in kept:
        m = o.transformed(centre, unit)
        far = float(np.abs(m.positions).max())
        if not far < MAX_SCENE_SPAN:
            raise MeshError(
                f"occluder {o.name!r} reaches {far:.3g} times the size of {target.name!r} away from it; "
                "ray tracing in single precision cannot hold both: leave it out of the occluders"
            )
        scene.append(m)
    return target.transformed(centre, unit), scene, unit


def bake_ao(target, occluders=(), resolution=(1024, 1024), samples=256, *, min_samples=16, target_error=0.0,
            max_distance=float("inf"), distribution="cosine", source="sobol", margin=16, seed=0, threads=None,
            ignore_backfaces=False, falloff=0.0, progress=None, cancel=None, on_tile=None,
            tile_size=None, chunk_rays=1 << 16):
    """Bake ambient occlusion of ``target`` into a (H, W) texture over its UVs.

    Parameters
    ----------
    target : Mesh with UVs. It always occludes itself.
    occluders : Meshes (UVs not needed) that also block rays, in the same world space.
    resolution : int or (width, height) in texels.
    samples : the most samples per texel (every texel takes exactly this many when adaptive is off).
    min_samples : with adaptive sampling, what every texel takes before it may stop.
    target_error : adaptive sampling when > 0: a texel stops once the half-width of its 95%
        confidence interval is at most this (in AO units, e.g. 0.01), after doubling rounds from
        ``min_samples``. The interval never takes agreeing samples as proof (see
        :func:`interval_half_width`): a fully open texel under cosine sampling stops at the first
        round of at least about 2.7 / target_error samples, so with ``min_samples`` at that or above
        open texels stop at the minimum. 0 turns adaptive sampling off.
    max_distance : occluders farther than this along a ray do not count (world units).
    distribution : 'cosine' (importance sampling, default) or 'uniform' (weight 2 cos theta).
    source : 'sobol' (Owen-scrambled, default), 'stratified', 'independent' or 'halton'.
    margin : texels to extend each UV island by, from the nearest covered texel.
    seed : non-negative integer; the same seed gives a bit-identical result for any thread count.
    threads : worker threads (None: every core this process may use).
    ignore_backfaces : hits on the back of a triangle (its winding's normal facing along the ray)
        do not occlude; the ray continues past them.
    falloff : 0 for plain AO; p > 0 weighs a hit at distance t by (1 - t / max_distance)^p, so
        distant occluders darken less (needs a finite max_distance).
    progress : called as progress(fraction) from worker threads, one call at a time, after every
        chunk of rays and every finished tile (not on a clock: the calls a bake makes do not depend
        on the machine's speed), and once with 1.0 at the end. Throttle any drawing in the callback.
    cancel : a threading.Event or a callable returning True to stop; checked between chunks of
        rays. A cancelled bake raises BakeCancelled and returns nothing.
    on_tile : called as on_tile(rows, cols, ao_block) from worker threads when a tile of texels is
        final (before margin dilation); ``rows``, ``cols`` are slices of the (H, W) result.
    tile_size, chunk_rays : texels per side of the unit of work a thread takes (None: chosen from
        samples and resolution), and rays traced per call into Embree (bounds memory). Neither
        changes the result: texels draw their samples by (texel, index) alone.

    Returns
    -------
    BakeResult

    Raises
    ------
    MeshError, MeshTypeError, SettingsError, BakeMemoryError (before any heavy work), BakeCancelled.
    """
    t_start = time.perf_counter()
    cfg = _validate(target, occluders, resolution, samples, min_samples, target_error, max_distance,
                    distribution, source, margin, seed, threads, falloff)
    target, cfg["occluders"], unit = _normalized_scene(target, cfg["occluders"])
    max_distance_world = cfg["max_distance"]
    cfg["max_distance"] = cfg["max_distance"] / unit
    w, h = cfg["width"], cfg["height"]
    tri_total = target.triangle_count + sum(o.triangle_count for o in cfg["occluders"])
    chunk_rays = _positive_int(chunk_rays, "chunk_rays")
    need = estimate_memory(w, h, tri_total, cfg["threads"], chunk_rays, cfg["samples"])
    avail = available_memory()
    if avail is not None and need > avail:
        raise BakeMemoryError(f"a {w} x {h} bake of {tri_total} triangles needs about {need / 2**30:.2f} GiB, "
                              f"but only {avail / 2**30:.2f} GiB is available; lower the resolution")
    if _cancelled(cancel):
        raise BakeCancelled("the bake was cancelled before it started")

    if tile_size is None:
        tile_size = auto_tile_size(w, h, cfg["samples"], cfg["threads"])
    tile_size = _positive_int(tile_size, "tile_size")
    tris = prepare(target, w, h)
    bins = bin_triangles(tris, w, h, tile_size)
    tracer = _Tracer([target] + cfg["occluders"], ignore_backfaces, cfg["falloff"], cfg["max_distance"])
    pattern = TexelPattern(cfg["source"], cfg["seed"], cfg["samples"])
    settings = dict(cfg, tile=tile_size, chunk_rays=chunk_rays)
    # Planned work: texel-samples of every tile's bounding rectangle is unknown before rasterising,
    # so count each tile's texels times samples as it is rasterised, against an upper bound.
    planned = sum(min(tile_size, w - kx * tile_size) * min(tile_size, h - ky * tile_size)
                  for ky, kx in bins) * cfg["samples"]
    shared = _Shared(planned, progress, cancel)
    baker = _TileBaker(tris, target, tracer, pattern, settings, w, h, shared)

    ao = np.zeros((h, w), np.float32)
    se = np.zeros((h, w), np.float32)
    count = np.zeros((h, w), np.int32)
    mask = np.zeros((h, w), bool)
    coverage_over = 0
    keys = sorted(bins)

    def work(key):
        nonlocal coverage_over
        frag, stats = baker.bake(key, bins[key])
        ty, tx = key
        rect = min(tile_size, w - tx * tile_size) * min(tile_size, h - ty * tile_size)
        shared.advance(rect * cfg["samples"] - len(frag.texels) * cfg["samples"])
        if len(frag.texels):
            rows, cols = frag.texels // w, frag.texels % w
            ao[rows, cols] = np.clip(stats.mean, 0.0, 1.0)
            se[rows, cols] = np.nan_to_num(stats.stderr, nan=0.0)
            count[rows, cols] = stats.n
            mask[rows, cols] = True
            with shared.lock:
                coverage_over += int((frag.coverage > 1.0 + R.OVERLAP_REPORT_AREA).sum())
            if on_tile is not None:
                r = slice(ty * tile_size, min((ty + 1) * tile_size, h))
                c = slice(tx * tile_size, min((tx + 1) * tile_size, w))
                with shared.lock:
                    on_tile(r, c, ao[r, c].copy())

    def guarded(key):
        try:
            work(key)
        except _Stop:
            pass
        except BaseException:
            shared.stop.set()
            raise

    if cfg["threads"] == 1 or len(keys) <= 1:
        for key in keys:
            guarded(key)
    else:
        with ThreadPoolExecutor(max_workers=cfg["threads"], thread_name_prefix="mc_ao") as pool:
            for f in [pool.submit(guarded, key) for key in keys]:
                f.result()
    if shared.stop.is_set():
        raise BakeCancelled("the bake was cancelled; nothing was written")
    if progress is not None:
        progress(1.0)

    if cfg["margin"] > 0:
        ao = dilate(ao, mask, cfg["margin"])
    seconds = time.perf_counter() - t_start
    metadata = {
        "samples": cfg["samples"], "min_samples": cfg["min_samples"], "target_error": cfg["target_error"],
        "sample_source": cfg["source"], "distribution": cfg["distribution"], "seed": cfg["seed"],
        "max_distance": max_distance_world, "falloff": cfg["falloff"], "ignore_backfaces": bool(ignore_backfaces),
        "margin": cfg["margin"], "resolution": f"{w}x{h}", "version": __version__, "rays": shared.rays,
    }
    report = {"covered_texels": int(mask.sum()), "degenerate_uv_triangles": tris.degenerate,
              "degenerate_triangles": tris.degenerate_space,
              "uv_outside_triangles": tris.outside, "overlapping_texels": coverage_over}
    return BakeResult(ao=ao, mask=mask, stderr=se, samples=count, rays=shared.rays, seconds=seconds,
                      trace_seconds=shared.trace_seconds, threads=cfg["threads"], metadata=metadata,
                      report=report)


__all__ = ["bake_ao", "BakeResult", "DISTRIBUTIONS", "MAX_SAMPLES", "estimate_memory", "available_memory", "interval_half_width"]
