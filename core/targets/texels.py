"""A bake of an image's texels: the layout (UV triangles, tiles, surface table), the tiles, the images.

:class:`TexelBake` is a bake set up after its prologue (:class:`core.pipeline.prologue.Prologue`): the
target's UV triangles and surface table, its tiles, and after :meth:`TexelBake.trace_setup` the
tracing (scene, pattern, kernel, start stage, tile baker). The same object bakes tiles in this
process and in a worker process, which builds it again from the same request and this process's
layout (:func:`layout_data`): the same tiles, the same bits. :class:`ImageStore` holds one quantity's images, filled tile by tile. UDIM tiles are
images of their own (:mod:`core.geometry.uvtiles`), baked one after another.
"""

import functools
import threading

import numpy as np

from ..engine.estimators import ErrorModel
from ..engine.kernel import Kernel
from ..engine.patterns import TexelPattern
from ..engine.scheduler import is_cancelled
from ..engine.thickness import quantity_settings
from ..engine.tilebaker import SurfaceStart, TileBaker, TileOut
from ..geometry import raster as R
from ..geometry.raster import bin_triangles, prepare
from ..geometry.surface import SurfaceTable
from ..highpoly.stage import HighPolyStage
from ..post import bent as bent_mod
from ..post.denoise import tile_guide
from .maps import MapsBake


class TexelBake:
    """A texel bake set up after its prologue: the layout (UV triangles, surface table, tiles), and after
    :meth:`trace_setup` the tracing (scene, pattern, kernel, start stage, tile baker). The same object
    bakes tiles in this process and in a worker process (:mod:`core.execution.pool`), which builds it again
    from the same input and settings and this process's UV triangles and tiles (``layout``): the same
    tiles, the same bits."""

    def __init__(self, pro, s, bent_normals=False, guide=False, layout=None):
        self.pro, self.bent_normals, self.guide = pro, bool(bent_normals), bool(guide)
        self.goal, self.again = None, False
        if layout is not None:  # a worker process's bake: the parent's UV triangles and tiles (the same bits)
            self.uvtris, self.s, self.bins = layout_of(layout), s, layout["bins"]
        else:
            self.uvtris = prepare(pro.target, s.width, s.height)
            self.s = s.fit_tiles(R.uv_centres(self.uvtris))  # automatic tiles of dense meshes: fewer triangles each
            self.bins = bin_triangles(self.uvtris, s.width, s.height, self.s.tile_shape)
        # Planned work: a tile's texels are unknown before rasterising, so count each tile's bounding
        # rectangle's texels times samples, and credit what it did not cover as it is rasterised.
        self.planned = sum(self.rect(key)[2] for key in self.bins) * self.s.samples

    def lane(self, s, bent_normals=False):
        """The bake of another quantity over this one's layout (UV triangles, tiles, surface table:
        taken once), with settings ``s`` (:func:`core.engine.thickness.quantity_settings` of this bake's)."""
        out = object.__new__(TexelBake)
        out.pro, out.uvtris, out.bins, out.planned = self.pro, self.uvtris, self.bins, self.planned
        out.s, out.bent_normals, out.root, out.guide = s, bool(bent_normals), self, False
        out.goal, out.again = None, False
        return out

    def aim(self, goal, again=False):
        """Bake each texel's count decided before the bake: ``goal`` (H * W,) int, the samples each
        replicate of a texel takes (0: the texel is not baked, and its tile leaves it out), or one int
        for every texel. ``again``: a second pass over texels baked before (its tiles return no guide,
        count no overlaps). The counts are kept (and sent to worker processes) in 16 bits where they fit."""
        if goal is not None and np.ndim(goal) == 0:
            goal = int(goal)
        elif goal is not None:
            goal = np.asarray(goal).reshape(-1)
            goal = goal.astype(np.uint16 if goal.max(initial=0) < 2 ** 16 else np.int32)
        self.goal = goal
        self.again = bool(again)
        if again:
            self.guide = False
        if "baker" in self.__dict__:
            self.baker.goal = self.goal

    @functools.cached_property
    def table(self):
        """The target's surface table, built where tiles are baked (a parent whose workers bake them
        never needs it: hundreds of bytes a triangle it does not hold)."""
        root = self.__dict__.get("root")  # another quantity's bake over the same layout (:meth:`lane`)
        return root.table if root is not None else SurfaceTable.build(self.pro.target, self.uvtris)

    def rect(self, key):
        """Rows, columns and texel count of tile ``key``."""
        x0, y0, x1, y1 = self.s.tile_bounds(key)
        return slice(y0, y1), slice(x0, x1), (x1 - x0) * (y1 - y0)

    def trace_setup(self, shared, cancel, on_rays=None, pattern=None):
        """The tracing: scene, sample pattern (``pattern``: another quantity's of the same bake, the
        same points), kernel, start stage and tile baker."""
        pro, s = self.pro, self.s
        stage = None if pro.s2a is None else HighPolyStage(
            pro.s2a, pro.target, pro.occluders, self.uvtris, self.table, self.bins, s, pro.unit,
            lambda: is_cancelled(cancel), ground=pro.ground_height(s)[1],
            occluding=s.quantity == "ao")
        tracer = pro.tracer(s) if stage is None else stage.scene.tracer
        tracer.constant_answer = s.constant_answer
        if pattern is None:
            pattern = TexelPattern(s.source, s.seed, s.replicate_samples, pool_points=s.pool_points())
        self.pattern = pattern
        kernel = Kernel(pattern, tracer, s.distribution, on_rays=on_rays)
        # Located samples take one matrix form for the whole bake (see core.engine.kernel.TileContext).
        curved = bool(np.any(self.table.smooth[self.uvtris.valid]))
        self.start = (SurfaceStart(self.table, tracer, located_curved=curved)
                      if stage is None else stage.start())
        self.baker = TileBaker(self.uvtris, self.table, kernel, tracer, pattern, s, shared, self.start,
                               bent=self.bent_normals)
        self.baker.goal = self.goal
        self.errors = ErrorModel(s, grouped=self.start.grouped)
        self.shared = shared

    def layout(self, key):
        """Tile ``key``'s fragments and sample units (:meth:`core.engine.tilebaker.TileBaker.layout`)."""
        return self.baker.layout(key, self.bins[key])

    def tile(self, key, directions=True, layout=None):
        """Bake tile ``key``: its :class:`TileOut`. ``directions``: turn bent-normal sums into unit
        directions here (False: leave the sums, for the process that assembles the images);
        ``layout``: the tile's :meth:`layout`, taken already for another quantity."""
        s, w = self.s, self.s.width
        frag, est, sums = self.baker.bake(key, self.bins[key], layout)
        self.shared.advance((self.rect(key)[2] - len(frag.texels)) * s.samples)
        t = frag.texels
        if not len(t):
            e = np.zeros(0, np.float32)
            return TileOut(key, t, e, e, np.zeros(0, np.int32), np.zeros(0, bool))
        rows, cols = t // w, t % w
        lost = self.start.lost(est)
        se = self.errors.stderr(est, cols, rows).astype(np.float32)
        se[lost] = 0.0
        out = TileOut(key, t, np.clip(est.mean, 0.0, 1.0).astype(np.float32), se, est.n.astype(np.int32), lost,
                      0 if self.again else int((frag.coverage > 1.0 + R.OVERLAP_REPORT_AREA).sum()))
        if self.guide:  # what the denoiser needs of these texels, from their fragments
            out.guide = tile_guide(frag, self.uvtris, self.pro.target, w)
        if sums is not None:
            out.sums = sums
            out.tri = bent_mod.primary_pieces(frag, w)
            out.weights = bent_mod.barycentric(self.table.corners_xy, out.tri, cols + 0.5, rows + 0.5)
        if self.goal is not None:
            # A bake of decided counts: the tile's texels that took none are not in its output.
            keep = out.samples > 0
            if not keep.all():
                for name in ("texels", "ao", "stderr", "samples", "lost", "sums", "tri", "weights"):
                    v = getattr(out, name)
                    if v is not None:
                        setattr(out, name, v[keep])
        if sums is not None and directions:
            self.directions(out)
        return out

    def directions(self, out):
        """The tile's bent normals from its sums, in the bake's space (:func:`core.post.bent.texel_directions`)."""
        out.bent = bent_mod.texel_directions(out.sums, out.tri, out.weights, self.pro.target.normals,
                                             self.pro.bent_space)
        out.sums = out.tri = out.weights = None


def texel_bake(pro, s, quantities, bent_normals=False, guide=False, layout=None):
    """The bake of ``quantities`` over ``pro`` with settings ``s`` (the base quantity's,
    :func:`core.base.request.base_quantity`): a :class:`TexelBake`, or for several quantities a
    :class:`core.targets.maps.MapsBake` of lanes over its layout. The same in this process and in a worker.
    ``guide``: the base quantity's tiles also return the denoiser's guide of their texels. ``layout``:
    the UV triangles and tiles laid out already (:func:`layout_data` of the parent's bake; ``s`` then has
    its tiles), in place of the target's UVs."""
    root = TexelBake(pro, s, bent_normals and s.quantity == "ao", guide=guide, layout=layout)
    if tuple(quantities) == (s.quantity,):
        return root
    return MapsBake({q: root if q == s.quantity else root.lane(quantity_settings(root.s, q), bent_normals and q == "ao")
                     for q in quantities})


def layout_data(bake):
    """What a worker process bakes a texel bake's tiles from in place of the target's UVs, as plain data:
    the UV triangles (their float32 texel-space corners, which can be baked, which are clockwise, the
    counts of the others) and the triangles of each tile (26 bytes a triangle and the bins' 8, against
    the UVs' 48 and each worker's own layout of them)."""
    t = bake.uvtris
    return {"corners32": t.corners32, "valid": t.valid, "cw": t.cw,
            "counts": [int(t.degenerate), int(t.degenerate_space), int(t.outside)], "bins": bake.bins}


def layout_of(data):
    """:class:`core.geometry.raster.UVTriangles` of :func:`layout_data`'s plain data."""
    return R.UVTriangles(data["corners32"], data["valid"], data["cw"], *data["counts"])


class ImageStore:
    """One quantity's images, filled tile by tile (on whichever thread finished a tile)."""

    def __init__(self, bake, w, h, bent, miss, on_tile, guide=None):
        self.bake, self.on_tile, self.guide = bake, on_tile, guide
        self.ao = np.zeros((h, w), np.float32)
        self.se = np.zeros((h, w), np.float32)
        self.count = np.zeros((h, w), np.int32)
        self.mask = np.zeros((h, w), bool)
        self.bent = np.zeros((h, w, 3), np.float32) if bent else None
        self.miss = np.zeros((h, w), bool) if miss else None
        self.overlap = 0
        self.lock = threading.Lock()

    def store(self, out):
        if not len(out.texels):
            return
        t = out.texels
        self.ao.reshape(-1)[t] = out.ao
        self.se.reshape(-1)[t] = out.stderr
        self.count.reshape(-1)[t] = out.samples
        self.mask.reshape(-1)[t] = ~out.lost
        if out.sums is not None:
            self.bake.directions(out)
        if out.bent is not None:
            self.bent.reshape(-1, 3)[t] = out.bent
        if self.miss is not None:
            self.miss.reshape(-1)[t] = out.lost
        if out.guide is not None and self.guide is not None:
            for a, v in zip(self.guide, out.guide):
                a[t] = v
        with self.lock:
            self.overlap += out.overlapping
            if self.on_tile is not None:
                r, c, _ = self.bake.rect(out.key)
                self.on_tile(r, c, self.ao[r, c].copy())


__all__ = ["TexelBake", "texel_bake", "layout_data", "layout_of", "ImageStore"]
