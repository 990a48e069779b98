"""The start stage of a selected-to-active bake: the tile baker's samples start at the high-poly points the
matching rays find (see :mod:`core.highpoly`); the check before baking, and the report."""

import math
import threading

import numpy as np

from ..montecarlo import warps
from ..base.errors import MeshError
from ..engine.adaptive import replicate_samples
from ..engine.estimators import TexelEstimates
from ..engine.kernel import TileContext
from ..geometry.mesh import corner_positions
from ..geometry.raster import rasterize_tile
from ..geometry.surface import SurfaceTable, point_table, point_units
from ..engine.tilebaker import ChunkSums
from ..tracing.tracer import FAR, Clock
from .extrusion import extruded, towards
from .scene import HighPolyScene, LowPoints


#: Directions traced per sample point (the most: fewer when the sample counts are not multiples).
DIRECTIONS_PER_POINT = 64
#: Points spread over the low-poly surface (by area) that the check before a bake casts matching rays from.
PRECHECK_POINTS = 1 << 12
_TAG_PRECHECK = 31


def directions_per_point(samples, min_samples, adaptive, replicates=1):
    """Directions per sample point: the largest power of two up to :data:`DIRECTIONS_PER_POINT` that
    divides each replicate's share of the sample count (:func:`core.engine.adaptive.replicate_samples`)
    and, with adaptive sampling, each replicate's share of the minimum (the first round): every round
    of every replicate is then whole points (the later rounds' counts are powers of two at least
    twice the first, or the share: :class:`core.engine.adaptive.SamplingPlan`)."""
    g = DIRECTIONS_PER_POINT
    for cap in replicate_samples(samples, replicates):
        g = math.gcd(g, int(cap))
    if adaptive:
        g = math.gcd(g, max(1, -(-int(min(min_samples, samples)) // int(replicates))))
    return g


class MatchedEstimates(TexelEstimates):
    """A selected-to-active tile's estimates, with per texel the sample points its matching rays were
    cast from (``points``, all replicates) and those that found no high-poly surface (``missed``)."""

    def __init__(self, count, replicates=1):
        super().__init__(count, replicates)
        self.points = np.zeros(count, np.int64)
        self.missed = np.zeros(count, np.int64)


class HighPolyStart:
    """The start stage of a selected-to-active bake (see :mod:`core.engine.tilebaker`): each sample point of
    a texel on the low-poly surface casts its matching ray, and the ``per_point`` samples of a point
    that found the high-poly surface start there, with the high-poly's normal: the hits are units of
    constant points (:func:`core.geometry.surface.point_table`) that the one kernel traces as it traces mesh
    vertices. Point j of a texel takes the position of the texel's sample j (u2, u3, through the
    kernel's own placement, :meth:`core.engine.kernel.Kernel.positions`) and the directions of its samples
    j g .. j g + g - 1; misses are not traced and not counted.
    """

    grouped = True
    locate = False
    located_curved = False  # no sample is located: the hits take the smooth form (curved())

    def __init__(self, stage, settings):
        self.stage, self.points, self.scene = stage, stage.points, stage.scene
        self.per_point = stage.g
        self.lock = threading.Lock()
        self.matching_rays = 0
        self.behind = 0  # matching rays that met the high-poly from behind (they started inside it)
        self.missed = 0
        self.partial = 0
        self.found = 0
        # The check before the bake (HighPolyStage) counts as matching too.
        self.match_seconds = stage.check_seconds
        self.match_cpu_seconds = stage.check_cpu_seconds

    def estimates(self, count, replicates):
        return MatchedEstimates(count, replicates)

    def contact(self, frag, width, samples):
        return np.zeros(len(frag.texels), bool)  # contact is found per matched point (HighPolyScene)

    def curved(self, units, unit, located):
        return np.zeros(len(unit), bool)  # the hits take the smooth form, whatever the low-poly's

    def keep(self, est, texels):
        """A texel none of whose points found the high-poly surface takes no further rounds."""
        return ~((est.points[texels] > 0) & (est.n[texels] == 0))

    def run(self, kernel, tile, curved, unit, first, k, squares, located, vectors, replicates):
        """Pieces of ``k`` sample points from ``first`` of each piece's unit: their matching rays, then
        ``per_point`` AO rays from each point that found the high-poly surface, through the kernel."""
        units, scene, g = tile.units, self.scene, self.per_point
        npieces = len(unit)
        inside, stage = Clock(), Clock()
        with stage:
            a, b = kernel.positions(tile, unit, first, k, squares, replicates)
            tri = np.repeat(units.tri[unit], k)
            _, origins, directions, usable = self.points.rays(tri, a.reshape(-1), b.reshape(-1))
            cast = np.flatnonzero(usable)
            with inside:
                found, htri, hq, hn, hgn = scene.match(origins[cast], directions[cast])
                point = cast[found]  # index (piece * k + j) of every point that hit
                behind = int(np.count_nonzero(np.einsum("ij,ij->i", scene.face_normals(htri), directions[point]) > 0))
                hcorners = scene.corners(htri)
                touch = None
                if (scene.contact.scenes or scene.tracer.ground is not None) and len(point):
                    touch = scene.contact.touching(scene.owner(htri), hcorners, hq, hgn)
        nh = len(point)
        piece = point // k
        hits = np.bincount(piece, minlength=npieces)
        with self.lock:
            self.matching_rays += len(cast)
            self.behind += behind
            self.missed += npieces * k - nh
            self.match_seconds += stage.wall
            self.match_cpu_seconds += stage.cpu
        work = npieces * k * g
        if nh == 0:
            zero = np.zeros(npieces)
            if vectors is not None:
                vectors[...] = 0.0
            return ChunkSums(hits * g, zero, zero, vectors, work, len(cast), inside.wall, inside.cpu, hits)
        # The hits as units of constant points, in the smooth form (one call for all of them).
        table = point_table(hq, hn, hgn, hcorners, smooth=True)
        ids = np.arange(nh, dtype=np.int64)
        hit_tile = TileContext(table, point_units(ids, units.texel[unit][piece]), tile.keys, tile.texel_ids,
                               np.zeros(tile.texels, bool), scene.tracer.offset, tris=ids, blocked=touch,
                               inward=tile.inward)
        vec = None if vectors is None else np.empty((nh, 3))
        s1, s2, rays, sec, cpu = kernel.run(hit_tile, True, ids, (first[piece] + point % k) * g, g, nh, vectors=vec,
                                            replicates=None if replicates is None else replicates[piece])
        s1 = np.bincount(piece, weights=s1, minlength=npieces)
        s2 = np.bincount(piece, weights=s2, minlength=npieces)
        if vectors is not None:
            for c in range(3):
                vectors[:, c] = np.bincount(piece, weights=vec[:, c], minlength=npieces)
        return ChunkSums(hits * g, s1, s2, vectors, work, len(cast) + rays, inside.wall + sec, inside.cpu + cpu, hits)

    def commit(self, est, texel, k, hits, replicate):
        np.add.at(est.points, texel, k)
        np.add.at(est.missed, texel, k - hits)

    # -- the whole bake --------------------------------------------------------------------------------

    def lost(self, est):
        """Per texel of a finished tile: none of its points matched (uncovered, left to the margin)."""
        lost = est.n == 0
        with self.lock:
            self.partial += int(np.count_nonzero((est.missed > 0) & ~lost))
            self.found += int(np.count_nonzero(~lost))
        return lost

    def counters(self):
        """What this process counted (summed over worker processes by :func:`finish_report`)."""
        return {"matching_rays": self.matching_rays, "behind": self.behind, "missed": self.missed,
                "partial": self.partial,
                "matching_seconds": self.match_seconds, "matching_cpu_seconds": self.match_cpu_seconds,
                "directions_per_point": self.per_point,
                "nothing_matched": self.stage.nothing_matched() if self.matching_rays and not self.found else None}


#: More than this share of the matching rays meeting the high-poly from behind gets a warning.
BEHIND_WARNING = 0.01


def finish_report(counters, miss, mask, s2a=None):
    """The report entries of a selected-to-active bake from its counters (one process's, or several
    added up), with the extrusion used and the warnings of ``s2a`` (the normalised input); raises
    MeshError when no texel matched at all."""
    if counters["matching_rays"] and not mask.any():
        raise MeshError(counters["nothing_matched"] or "no matching ray found the high-poly surface")
    extra = {}
    warnings = []
    if s2a is not None:
        world = s2a.world
        extra["extrusion"] = world.extrusion if world.cage is None else 0.0
        if s2a.measure is not None:
            extra["extrusion_served"] = s2a.measure.served
        behind = counters.get("behind", 0)
        rays = counters["matching_rays"]
        if rays and behind > BEHIND_WARNING * rays:
            low, highs = world.target.name, ", ".join(repr(h.name) for h in world.highs)
            if world.cage is not None:
                fix = (f"make the cage {world.cage.name!r} enclose the high-poly surface everywhere, without "
                       "reaching past other parts of it")
            elif world.auto:
                fix = (f"the automatic extrusion ({world.extrusion:.4g}) serves "
                       f"{100.0 * s2a.measured().served:.1f}% of the points it measured: the high-poly is too far "
                       f"from {low!r} in places for any one extrusion; use a cage")
            else:
                need = s2a.measured().extrusion * s2a.unit
                fix = (f"the extrusion is {world.extrusion:.4g}, and about {need:.4g} fits these meshes: leave it "
                       "automatic (None), set it near that, or use a cage")
            warnings.append(
                f"{low!r}: {100.0 * behind / rays:.1f}% of the matching rays met the high-poly surface of {highs} from "
                f"behind: they started inside it (an extrusion smaller than how far it bulges out of {low!r}) or "
                f"behind another part of it (an extrusion reaching past a far wall), and those texels bake the wrong "
                f"side (bright or dark blobs); {fix}")
    extra["matching_rays_behind"] = counters.get("behind", 0)
    extra["warnings"] = warnings
    return dict(extra, **{"matching_rays": counters["matching_rays"], "missed_matching_rays": counters["missed"],
            "missed_texels": int(miss.sum()), "partly_missed_texels": counters["partial"],
            "directions_per_point": counters["directions_per_point"],
            "matching_seconds": counters["matching_seconds"],
            "matching_cpu_seconds": counters["matching_cpu_seconds"]})


class HighPolyStage:
    """Everything a selected-to-active bake sets up before its tiles: the high-poly scene, the
    low-poly's points, and the check that some matching ray finds the high-poly surface at all.

    Parameters
    ----------
    s2a : a normalised :class:`SelectedToActive`; target : the normalised target; occluders : the
    normalised occluders (target, cage and high-poly meshes left out); uvtris, table, bins : the
    target's UV triangles, surface table and tiles (:mod:`core.geometry.raster`, :mod:`core.geometry.surface`);
    settings : :class:`core.engine.settings.BakeSettings`; unit : world length of one unit of the frame;
    cancelled : callable, True to stop (checked while scanning).
    """

    def __init__(self, s2a, target, occluders, uvtris, table, bins, settings, unit, cancelled=lambda: False,
                 ground=None, occluding=True):
        self.s2a, self.target, self.uvtris, self.table, self.unit = s2a, target, uvtris, table, unit
        self.s = settings
        self.g = directions_per_point(settings.samples, settings.min_samples, settings.adaptive,
                                      settings.replicates)
        self.scene = HighPolyScene(s2a, occluders, settings.ignore_backfaces, settings.falloff,
                                   settings.max_distance / unit, ground=ground, occluding=occluding)
        cage_table = None
        if s2a.cage is not None:
            cage = s2a.cage
            cage_table = SurfaceTable.build(cage, uvtris)
        self.points = LowPoints(s2a, table, cage_table)
        self._probe = None
        clock = Clock()
        with clock:
            found = self._any_match(bins, cancelled)
        self.check_seconds, self.check_cpu_seconds = clock.wall, clock.cpu
        if not found:
            raise MeshError(self.nothing_matched())

    def start(self):
        """The start stage the tile baker traces this bake's tiles with."""
        return HighPolyStart(self, self.s)

    # -- the check before baking -----------------------------------------------------------------------

    def _surface_points(self):
        """PRECHECK_POINTS points on the target's bakeable triangles, spread by area (stratified,
        deterministic): (triangle, barycentric weights (n, 3))."""
        valid = np.flatnonzero(self.uvtris.valid)
        if not len(valid):
            return valid, np.zeros((0, 3))
        area = self.target.areas[valid]
        cdf = np.cumsum(area)
        cdf /= cdf[-1]
        n = PRECHECK_POINTS
        from ..montecarlo.hashing import hash_uniform

        k = np.arange(n, dtype=np.uint64)
        u = (np.arange(n) + hash_uniform(np.uint64(1), k, np.uint64(_TAG_PRECHECK))) / n
        tri = valid[np.minimum(np.searchsorted(cdf, u, side="right"), len(valid) - 1)]
        w0, w1 = warps.square_to_triangle(hash_uniform(np.uint64(2), k, np.uint64(_TAG_PRECHECK)),
                                          hash_uniform(np.uint64(3), k, np.uint64(_TAG_PRECHECK)))
        return tri, np.stack([w0, w1, 1.0 - w0 - w1], axis=1)

    def _point_rays(self, tri, w):
        m = self.target
        p = np.einsum("ij,ijk->ik", w, corner_positions(m.positions, m.triangles[tri]))
        if self.s2a.cage is None:
            n = np.einsum("ij,ijk->ik", w, m.normals[tri])
            return p, extruded(p, n, m.face_normals[tri], self.s2a.extrusion)
        c = np.einsum("ij,ijk->ik", w, corner_positions(self.s2a.cage.positions, self.s2a.cage.triangles[tri]))
        return p, towards(c, p)

    def _any_match(self, bins, cancelled):
        """Whether some matching ray finds the high-poly surface: first from points spread over the
        surface by area; where none does, from every texel the bake covers (one point each), so that a
        high-poly matching only a small part of the low-poly is not refused."""
        tri, w = self._surface_points()
        if not len(tri):
            return True  # nothing to bake: the bake says so itself
        p, (origin, direction, usable) = self._point_rays(tri, w)
        self._probe = (p, origin, direction, usable)
        if self.scene.match(origin[usable], direction[usable])[0].any():
            return True
        s = self.s
        for ty, tx in sorted(bins):
            if cancelled():
                from ..base.errors import BakeCancelled

                raise BakeCancelled("the bake was cancelled before it started")
            frag = rasterize_tile(self.uvtris, bins[(ty, tx)], s.width, s.height, *s.tile_bounds((ty, tx)),
                                  locate=False)
            full = frag.full_tri >= 0
            t_full = frag.full_tri[full]
            xy_full = np.stack([frag.texels[full] % s.width, frag.texels[full] // s.width], axis=1) + 0.5
            xy_sub = frag.sub_xy.mean(axis=1)
            t = np.concatenate([t_full, frag.sub_tri])
            xy = np.concatenate([xy_full, xy_sub]).astype(np.float64)
            if not len(t):
                continue
            origin = self.table.take("origin", t)
            a = xy[:, 0] - origin[:, 0]
            b = xy[:, 1] - origin[:, 1]
            _, origin, direction, usable = self.points.rays(t, a, b)
            if self.scene.match(origin[usable], direction[usable])[0].any():
                return True
        return False

    def nothing_matched(self):
        """Why no matching ray found the high-poly surface, and what to change (world units)."""
        world = getattr(self.s2a, "world", self.s2a)
        low = world.target.name
        highs = ", ".join(repr(h.name) for h in world.highs)
        unit = self.unit
        head = f"no matching ray from {low!r} found the high-poly surface of {highs}, so nothing could be baked"
        if self._probe is None:
            return head
        p, origin, direction, usable = self._probe
        if not usable.any():
            return (f"{head}: the cage {world.cage.name!r} lies on {low!r} itself; move its vertices outwards, "
                    f"so that it encloses the high-poly surface")
        o, d = origin[usable], direction[usable]
        far = self._distances(o, d)
        if far.size:
            need = float(far.min()) * unit
            return (f"{head}: the nearest high-poly surface along the rays lies {need:.4g} from where they start, "
                    f"beyond the max ray distance {world.max_ray_distance:.4g}; raise the max ray distance above "
                    f"{need:.4g}, or set it to 0 (no limit)")
        back = self._distances(o, -d)
        if back.size:
            if world.cage is not None:
                return (f"{head}: the high-poly surface lies outside the cage {world.cage.name!r} (the rays go "
                        f"from the cage towards {low!r}); enlarge the cage so that it encloses the high-poly surface")
            gap = float(np.quantile(back, 0.99)) * unit + world.extrusion
            return (f"{head}: the high-poly surface lies outside {low!r}, up to {gap:.4g} above it along its "
                    f"normals, farther than the extrusion ({world.extrusion:.4g}) pushes the rays out; raise the "
                    f"extrusion above {gap:.4g}")
        return (f"{head}: no high-poly surface lies along {low!r}'s normals at all; the high-poly objects must "
                f"lie over {low!r}'s surface (move them onto it, or check that the right objects are selected)")

    def _distances(self, origins, directions):
        """Distances to the nearest high-poly surface along rays, no length limit (hits only)."""
        out = self.scene.match_scene.run(np.ascontiguousarray(origins, np.float32),
                                         np.ascontiguousarray(directions, np.float32),
                                         dists=np.full(len(origins), FAR, np.float32), output=True)
        return out["tfar"][out["primID"] >= 0].astype(np.float64)


__all__ = [
    "DIRECTIONS_PER_POINT", "PRECHECK_POINTS", "directions_per_point", "MatchedEstimates", "HighPolyStart",
    "BEHIND_WARNING", "finish_report", "HighPolyStage"
]
