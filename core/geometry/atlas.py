"""Several targets in one image (an atlas): which target owns each texel, where two targets' UVs
overlap, and which meshes a target's rays can reach.

Ownership. A texel that the UV islands of two targets share (tight atlases share border texels
without overlapping) goes to the target covering more of its area; equal areas go to the first
target by name (then by its place in the list), never by the order objects were selected. A
target's coverage of a texel is the area its UV triangles cover inside it, as its own bake
rasterises them (:func:`coverage`): 1 for a texel inside one island, less at an island's border,
more where its own islands overlap.

Overlaps. Where two targets' UVs truly overlap (stacked UVs), their coverages of a texel add up to
more than the texel (above 1 + :data:`core.geometry.raster.OVERLAP_REPORT_AREA`); such texels are
counted per pair, and owned by the same rule.

Reach. AO rays leave a surface and end at the bake's ``max_distance``: a mesh whose bounding box is
farther than that from a target's bounding box can never occlude it (:func:`within_reach`).
"""

from dataclasses import dataclass, field

import numpy as np

from . import raster as R
from .raster import bin_triangles, prepare, rasterize_tile

#: Side of the square tiles :func:`coverage` rasterises in (the coverage does not depend on it).
LAYOUT_TILE = 256
#: A reach a little longer than the distance: rays leave from points pushed off their surface, and
#: a mesh taken in for nothing costs a rebake at most.
REACH_SLACK = 1e-3


def name_rank(names):
    """Each target's place when a tie is broken: by name, then by its place in the list ((n,) int32,
    0 first)."""
    order = sorted(range(len(names)), key=lambda i: (str(names[i]), i))
    rank = np.empty(len(names), np.int32)
    rank[order] = np.arange(len(names), dtype=np.int32)
    return rank


def coverage(mesh, width, height, uvtris=None, locate=True):
    """The texels the UV triangles of ``mesh`` cover in a ``width`` x ``height`` image and how much of
    each: (texels (n,) int64 flat indices, ascending; area (n,) float64, texel units). ``uvtris``:
    the mesh's :func:`core.geometry.raster.prepare` if already made; ``locate`` as its bake's
    rasteriser (the covered texels are exactly the ones its bake covers)."""
    uvtris = prepare(mesh, width, height) if uvtris is None else uvtris
    bins = bin_triangles(uvtris, width, height, LAYOUT_TILE)
    texels, areas = [], []
    for (ty, tx), tri_ids in bins.items():
        x0, y0 = tx * LAYOUT_TILE, ty * LAYOUT_TILE
        frag = rasterize_tile(uvtris, tri_ids, width, height, x0, y0, min(x0 + LAYOUT_TILE, width),
                              min(y0 + LAYOUT_TILE, height), locate=locate)
        texels.append(frag.texels)
        areas.append(frag.coverage)
    if not texels:
        return np.zeros(0, np.int64), np.zeros(0)
    t, a = np.concatenate(texels).astype(np.int64), np.concatenate(areas)
    order = np.argsort(t, kind="stable")
    return t[order], a[order]


@dataclass
class Ownership:
    """Who owns each texel of an atlas (:func:`owners`).

    owner : (H, W) int32, the index of the owning target for each covered texel, -1 elsewhere.
    rank : (n,) int32, each target's place in ties (:func:`name_rank`).
    overlaps : [(i, j, texels)] per pair of targets (i before j by rank) whose UVs truly overlap.
    shared : texels covered by two targets or more (overlapping or sharing a border).
    covered : (n,) texels each target covers (owned or not).
    """

    owner: np.ndarray
    rank: np.ndarray
    overlaps: list = field(default_factory=list)
    shared: int = 0
    covered: np.ndarray = None

    def owned(self, i):
        """Flat indices of the texels target ``i`` owns."""
        return np.flatnonzero(self.owner.reshape(-1) == i)


def owners(coverages, rank, width, height, held=None):
    """The :class:`Ownership` of targets whose :func:`coverage` s are ``coverages`` (in list order),
    ties broken by ``rank``. ``held`` : None, or (H, W) bool texels that no target takes (they belong
    to something kept as it is); the targets' coverage of them still counts in the overlaps."""
    n = len(coverages)
    owner = np.full(height * width, -1, np.int32)
    best = np.full(height * width, -1.0)
    count = np.zeros(height * width, np.int16 if n < (1 << 15) else np.int32)
    for i in np.argsort(rank, kind="stable"):  # the first by rank first: a later one needs more area
        t, a = coverages[i]
        better = a > best[t]
        owner[t[better]] = i
        best[t[better]] = a[better]
        count[t] += 1
    if held is not None:
        owner[held.reshape(-1)] = -1
    multi = count >= 2
    overlaps = []
    if multi.any():
        parts = []
        for i in range(n):
            t, a = coverages[i]
            sel = multi[t]
            parts.append((t[sel], a[sel]))
        order = np.argsort(rank, kind="stable")
        for x, i in enumerate(order):
            for j in order[x + 1:]:
                _, ii, jj = np.intersect1d(parts[i][0], parts[j][0], assume_unique=True, return_indices=True)
                over = int(np.count_nonzero(parts[i][1][ii] + parts[j][1][jj] > 1.0 + R.OVERLAP_REPORT_AREA))
                if over:
                    overlaps.append((int(i), int(j), over))
    covered = np.array([len(c[0]) for c in coverages], np.int64)
    return Ownership(owner.reshape(height, width), np.asarray(rank, np.int32), overlaps, int(multi.sum()), covered)


def bounds(meshes):
    """(lo (3,), hi (3,)): the bounding box of ``meshes`` (world space)."""
    lo = np.min([m.positions.min(axis=0) for m in meshes], axis=0)
    hi = np.max([m.positions.max(axis=0) for m in meshes], axis=0)
    return lo, hi


def box_gap(a, b):
    """The distance between two bounding boxes ``a`` and ``b`` ((lo, hi) each): 0 where they touch
    or overlap."""
    gap = np.maximum(0.0, np.maximum(b[0] - a[1], a[0] - b[1]))
    return float(np.sqrt(np.sum(gap * gap)))


def within_reach(a, b, distance):
    """Whether a mesh with bounding box ``b`` can occlude rays of length ``distance`` from a surface
    with bounding box ``a`` (a little longer: :data:`REACH_SLACK`); always with an unlimited distance."""
    if not np.isfinite(distance):
        return True
    return box_gap(a, b) <= distance * (1.0 + REACH_SLACK)


def id_colour(name):
    """The colour (3,) float32 of a target named ``name`` in an ID map: a saturated, bright hue drawn
    from a hash of the name, so that an object keeps its colour whatever else the atlas holds."""
    import hashlib

    h = int.from_bytes(hashlib.blake2b(str(name).encode("utf-8"), digest_size=8).digest(), "little")
    hue = (h % 3600) / 3600.0
    sat = 0.65 + 0.35 * ((h >> 12) % 100) / 100.0
    val = 0.75 + 0.25 * ((h >> 24) % 100) / 100.0
    k = (np.array([5.0, 3.0, 1.0]) + hue * 6.0) % 6.0
    return (val - val * sat * np.clip(np.minimum(k, 4.0 - k), 0.0, 1.0)).astype(np.float32)


def id_map(owner, names):
    """An ID map of an atlas: (H, W, 3) float32, each target's texels (``owner``, covered and margin)
    in its :func:`id_colour`, black where no target is."""
    colours = np.zeros((len(names) + 1, 3), np.float32)
    for i, name in enumerate(names):
        colours[i] = id_colour(name)
    return colours[np.where(owner >= 0, owner, len(names))]


__all__ = ["id_colour", "id_map", "name_rank", "coverage", "Ownership", "owners", "bounds", "box_gap", "within_reach", "LAYOUT_TILE"]
