"""Located texels: texels covered exactly once by several triangles (triangles smaller than texels,
or texels on the edges inside a UV island), whose samples spread over the whole texel and each find
their own triangle, with no clipping.

The rasteriser's classification is checked against clipping every texel (``locate=False``); the
samples, through the bake's public ``on_rays`` hook, against the exact surface (a height field whose
x, y are its UVs, so every ray origin says which triangle it was put on); the estimate against
Lambert's formula; and the result for any thread count, tiling and chunking."""

import math

import numpy as np
import pytest

from core import Mesh, bake_ao
from core.geometry.raster import LOCATED, bin_triangles, prepare, rasterize_tile
from core.montecarlo.stats import normal_quantile
from chi2 import SUITE_ALPHA, sidak
from scenes import polygon_form_factor, texel_mean

LID = np.array([[0.25, 0.25, 0.3], [0.75, 0.25, 0.3], [0.75, 0.75, 0.3], [0.25, 0.75, 0.3]])


def grid(n, lo=(0.0, 0.0), hi=(1.0, 1.0), jitter=0.3, z=0.0, seed=0, smooth=False, name="grid"):
    """An n x n quad grid over [lo, hi] (2 n^2 triangles) whose UVs are its x, y: interior vertices
    jittered by up to ``jitter`` of a cell, heights random up to ``z``, diagonals alternating."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, n + 1)
    X, Y = np.meshgrid(t, t)
    cell = 1.0 / n
    inner = (X > 0) & (X < 1) & (Y > 0) & (Y < 1)
    X = X + inner * rng.uniform(-jitter, jitter, X.shape) * cell
    Y = Y + inner * rng.uniform(-jitter, jitter, Y.shape) * cell
    X = lo[0] + X * (hi[0] - lo[0])
    Y = lo[1] + Y * (hi[1] - lo[1])
    P = np.stack([X.ravel(), Y.ravel(), rng.uniform(0.0, z, X.size) if z else np.zeros(X.size)], axis=1)
    i, j = np.meshgrid(np.arange(n), np.arange(n))
    a = (i + (n + 1) * j).ravel()
    flip = ((i + j) % 2 == 1).ravel()
    t1 = np.where(flip[:, None], np.stack([a, a + 1, a + n + 1], 1), np.stack([a, a + 1, a + n + 2], 1))
    t2 = np.where(flip[:, None], np.stack([a + 1, a + n + 2, a + n + 1], 1), np.stack([a, a + n + 2, a + n + 1], 1))
    F = np.concatenate([t1, t2])
    N = None
    if smooth:
        vn = np.concatenate([rng.uniform(-0.3, 0.3, (len(P), 2)), np.ones((len(P), 1))], axis=1)
        N = (vn / np.linalg.norm(vn, axis=1, keepdims=True))[F]
    return Mesh(P, F, P[F][:, :, :2], normals=N, name=name)


def islands():
    """Several UV islands: two jittered grids overlapping in part, one of them mirrored (clockwise
    UVs), a grid of triangles smaller than texels, and a triangle folded back over its neighbour."""
    parts = [grid(7, (0.05, 0.05), (0.55, 0.6), seed=1), grid(5, (0.45, 0.3), (0.95, 0.9), seed=2),
             grid(30, (0.1, 0.65), (0.4, 0.95), seed=3)]
    P, F, UV, off = [], [], [], 0
    for k, m in enumerate(parts):
        uv = m.uvs.copy()
        if k == 1:  # mirrored in u: clockwise UVs
            uv[:, :, 0] = 1.4 - uv[:, :, 0]
        P.append(m.positions)
        F.append(m.triangles + off)
        UV.append(uv)
        off += len(m.positions)
    F = np.concatenate(F)
    UV = np.concatenate(UV)
    # A fold: one triangle of the first grid gets a copy flipped over one of its edges.
    a, b, c = UV[40]
    fold = np.array([a, b, a + b - c])
    UV = np.concatenate([UV, fold[None]])
    F = np.concatenate([F, F[40:41]])
    return Mesh(np.concatenate(P), F, UV, name="islands")


def fragments(mesh, W, H, tile, locate=True):
    """Rasterise ``mesh`` tile by tile: {texel: (kind, candidates or sub-triangle parents, coverage)}."""
    tris = prepare(mesh, W, H)
    out = {}
    for (ty, tx), ids in bin_triangles(tris, W, H, tile).items():
        x0, y0 = tx * tile, ty * tile
        f = rasterize_tile(tris, ids, W, H, x0, y0, min(x0 + tile, W), min(y0 + tile, W if W == H else H),
                           locate=locate)
        for k, t in enumerate(f.texels):
            cand = tuple(f.loc_tri[f.loc_start[k]:f.loc_start[k + 1]])
            subs = tuple(sorted(set(f.sub_tri[f.sub_start[k]:f.sub_start[k + 1]])))
            out[int(t)] = (int(f.full_tri[k]), cand if f.full_tri[k] == LOCATED else subs, float(f.coverage[k]),
                           f.loc_edges[f.loc_start[k]:f.loc_start[k + 1]].copy())
    return out


@pytest.mark.parametrize("mesh_name, W", [("islands", 40), ("islands", 97), ("fine", 24), ("coarse", 64)])
def test_located_texels_are_covered_exactly_once(mesh_name, W):
    # Clipping every texel (the reference) finds coverage 1 in every located texel, from exactly the
    # triangles among its candidates that overlap it; every other texel comes out as the reference
    # has it; and nothing depends on the tiling.
    mesh = {"islands": islands(), "fine": grid(60, seed=4), "coarse": grid(9, seed=5)}[mesh_name]
    got = fragments(mesh, W, W, 16)
    ref = fragments(mesh, W, W, W, locate=False)
    assert got.keys() == ref.keys()
    kinds = np.array([v[0] for v in got.values()])
    assert (kinds == LOCATED).sum() > 0.05 * len(kinds)
    if mesh_name != "fine":
        assert (kinds >= 0).any()
    if mesh_name == "islands":
        assert (kinds == -1).sum() > 0.05 * len(kinds)
    for t, (kind, tri, cov, _) in got.items():
        rkind, rtri, rcov, _ = ref[t]
        if kind == LOCATED:
            # (clipping drops slivers under MIN_FRAGMENT_AREA = 1e-9 of a texel)
            assert rkind == -1 and abs(rcov - 1.0) < 1e-8, (t, rcov)
            assert set(rtri) <= set(tri) and list(tri) == sorted(tri), (t, tri, rtri)
        else:
            assert (kind, tri) == (rkind, rtri) and cov == pytest.approx(rcov, abs=1e-12), t
    # Any tiling: the same kinds, candidates and edge functions.
    for tile in (7, 32):
        other = fragments(mesh, W, W, tile)
        assert other.keys() == got.keys()
        for t, v in got.items():
            w = other[t]
            assert v[:3] == w[:3] and np.array_equal(v[3], w[3]), t


def test_island_borders_overlaps_and_folds_are_never_located():
    # Texels that an island's border crosses, or where two layers cover the same UVs (overlapping
    # islands, a folded triangle), are clipped: coverage other than 1 somewhere in them.
    mesh = islands()
    got = fragments(mesh, 64, 64, 64)
    ref = fragments(mesh, 64, 64, 64, locate=False)
    partial = [t for t, v in ref.items() if abs(v[2] - 1.0) > 1e-6]
    over = [t for t, v in ref.items() if v[2] > 1.0 + 1e-6]
    assert len(partial) > 100 and len(over) > 20
    assert all(got[t][0] == -1 for t in partial)


def _normalised(mesh, points):
    """Ray origins from the bake's frame (centred on the target, scaled to its size) back to the mesh's."""
    lo, hi = mesh.positions.min(axis=0), mesh.positions.max(axis=0)
    return points * float(np.max(hi - lo)) + (lo + hi) / 2.0


def _containing(mesh, xy):
    """The triangle of the height field (its x, y are its UVs) containing each point xy (m, 2)."""
    P = mesh.positions[mesh.triangles]
    tri = np.full(len(xy), -1)
    best = np.full(len(xy), -np.inf)
    for k in range(len(P)):
        a, b, c = P[k, :, :2]
        m = np.array([[b[0] - a[0], c[0] - a[0]], [b[1] - a[1], c[1] - a[1]]])
        l1, l2 = np.linalg.solve(m, (xy - a).T)
        inside = np.minimum(1 - l1 - l2, np.minimum(l1, l2))
        take = inside > best
        best[take] = inside[take]
        tri[take] = k
    return tri


def _record(mesh, **kw):
    batches = []

    def keep(b):
        batches.append({k: np.array(getattr(b, k)) for k in ("origins", "directions", "tfar", "texels", "samples")})

    r = bake_ao(mesh, threads=1, margin=0, on_rays=keep, **kw)
    return {k: np.concatenate([b[k] for b in batches]) for k in batches[0]}, r


@pytest.mark.parametrize("smooth", [False, True])
def test_located_samples_lie_on_their_own_triangle(smooth):
    # A height field with triangles smaller than texels: a sample put on the wrong triangle (or at
    # the wrong place in its texel) lands on another triangle's plane, off the surface.
    mesh = grid(40, z=0.05, seed=6, smooth=smooth)
    W = 16
    rays, _ = _record(mesh, resolution=W, samples=32, seed=3)
    p = _normalised(mesh, rays["origins"].astype(np.float64))
    col, row = rays["texels"] % W, rays["texels"] // W
    u, v = p[:, 0] * W - col, p[:, 1] * W - row
    assert np.all((u > -1e-5) & (u < 1 + 1e-5) & (v > -1e-5) & (v < 1 + 1e-5))
    pick = np.random.default_rng(0).choice(len(p), 3000, replace=False)
    tri = _containing(mesh, p[pick, :2])
    # Origins sit a hair above the surface, pushed along the face normal by the ray offset (a few
    # 1e-6 here); on a wrong triangle's plane they would be off by its slope times their distance
    # from the edge between them.
    fn, p0 = mesh.face_normals[tri], mesh.positions[mesh.triangles[tri, 0]]
    dist = np.einsum("ij,ij->i", p[pick] - p0, fn * np.sign(fn[:, 2:3]))
    assert np.all((dist > 0) & (dist < 1e-5)), (dist.min(), dist.max())


def test_located_sample_positions_are_uniform_over_the_texel():
    # Independent points, pooled over the located texels of a fine grid: texel-local positions are
    # uniform on the square (chi-square on 8 x 8 cells), whatever triangles they land on.
    from core.geometry.raster import prepare as _prepare

    mesh = grid(60, seed=7)
    W = 16
    frag = rasterize_tile(_prepare(mesh, W, W), np.arange(len(mesh.triangles)), W, W, 0, 0, W, W)
    located = set(frag.texels[frag.full_tri == LOCATED].tolist())
    assert len(located) > 0.8 * W * W
    rays, _ = _record(mesh, resolution=W, samples=64, seed=5, source="independent")
    sel = np.isin(rays["texels"], list(located))
    p = _normalised(mesh, rays["origins"][sel].astype(np.float64))
    t = rays["texels"][sel]
    u, v = p[:, 0] * W - t % W, p[:, 1] * W - t // W
    cells = np.clip((u * 8).astype(int), 0, 7) * 8 + np.clip((v * 8).astype(int), 0, 7)
    counts = np.bincount(cells, minlength=64)
    expect = len(u) / 64
    stat = ((counts - expect) ** 2 / expect).sum()
    # chi-square with 63 degrees of freedom, upper tail at the suite's level (Wilson-Hilferty)
    alpha = sidak(SUITE_ALPHA, 8)
    zq = normal_quantile(1 - alpha)
    crit = 63 * (1 - 2 / (9 * 63) + zq * math.sqrt(2 / (9 * 63))) ** 3
    assert stat < crit, (stat, crit)
    # ... and not a harness that passes anything: the same positions squeezed into a triangle fail.
    sq = np.clip((np.minimum(u, v) * 8).astype(int), 0, 7) * 8 + np.clip((v * 8).astype(int), 0, 7)
    bad = ((np.bincount(sq, minlength=64) - expect) ** 2 / expect).sum()
    assert bad > crit


@pytest.mark.parametrize("distribution", ["cosine", "uniform"])
def test_located_texels_match_lamberts_formula(distribution):
    # A plane of triangles smaller than texels under the lid: almost every texel is located, and the
    # estimate is unbiased against the exact texel mean of 1 - F with an honest standard error.
    W = 24
    mesh = grid(50, seed=8)
    frag = rasterize_tile(prepare(mesh, W, W), np.arange(len(mesh.triangles)), W, W, 0, 0, W, W)
    assert (frag.full_tri == LOCATED).mean() > 0.9
    truth = texel_mean(lambda p: 1.0 - polygon_form_factor(p, LID), W, W)
    lid = Mesh(LID, np.array([[0, 1, 2], [0, 2, 3]]), name="lid")
    r = bake_ao(mesh, [lid], resolution=W, samples=256, source="independent", distribution=distribution,
                margin=0, seed=3)
    z = (r.ao - truth) / r.stderr
    m = z.size
    assert abs(z.mean()) < 4 / math.sqrt(m), z.mean()
    assert 0.8 < z.var() < 1.25, z.var()
    assert np.abs(z).max() < normal_quantile(1 - 0.01 / (2 * m)) + 0.5


@pytest.mark.parametrize("smooth", [False, True])
@pytest.mark.parametrize("kw", [dict(), dict(distribution="uniform", source="halton", falloff=1.0),
                                dict(samples=64, min_samples=8, target_error=0.05)])
def test_located_bakes_are_bit_identical_for_any_threads_tiles_and_chunks(smooth, kw):
    # Triangles smaller than texels (located texels everywhere, candidates of every count), flat and
    # smooth shading, under a lid: any grouping of the work gives the same bits.
    mesh = grid(45, z=0.02, seed=9, smooth=smooth)
    lid = Mesh(np.array([[0.1, 0.1, 0.2], [0.8, 0.2, 0.25], [0.7, 0.9, 0.3]]), np.array([[0, 1, 2]]), name="lid")
    args = dict(resolution=20, samples=16, max_distance=0.6, margin=0, seed=8)
    args.update(kw)
    a = bake_ao(mesh, [lid], threads=1, **args)
    b = bake_ao(mesh, [lid], threads=2, tile_size=8, chunk_rays=100, **args)
    c = bake_ao(mesh, [lid], threads=2, tile_size=5, chunk_rays=1 << 12, **args)
    for name in ("ao", "stderr", "samples", "mask"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
        assert np.array_equal(getattr(a, name), getattr(c, name)), name
