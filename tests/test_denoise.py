"""The surface-space denoiser (core.post.denoise): its guide, and its properties on exact scenes.

Every scene is baked at 16 samples with core.bake_ao and denoised; the exact texel AO comes from
core.montecarlo.analytic. Sizes are 64^2, seeds fixed, nothing timed. Each statistical bound says what it
allows for noise, so that it holds for any seed.
"""

import math

import numpy as np
import pytest

from core import Mesh, MeshError, bake_ao
from core.post import denoise as D
from core.montecarlo.analytic import plane_beside_box_ao, polygon_form_factor, regular_polygon, texel_mean
from scenes import box, plane

W = 64
SAMPLES = 16
SEEDS = range(4)
#: The error's calibration is checked on more bakes: its statistics are of correlated texels.
Z_SEEDS = range(8)
LID = regular_polygon(0.3, 0.25, 64, centre=(0.5, 0.5))
SIDE_LID = regular_polygon(0.3, 0.25, 64, centre=(0.35, 0.5))
BOX = ((0.3, 0.3, 0.0), (0.7, 0.6, 0.25))


def lid(verts):
    return Mesh(verts, np.array([[0, i, i + 1] for i in range(1, len(verts) - 1)]), name="lid")


def split_plane(mirrored=False):
    """The unit plane cut along x = 0.5 into two UV islands: the left half maps to u in [0, 0.5]
    as is, the right half turned by 180 degrees into u in [0.5, 1] (``mirrored``: flipped in u
    alone, a chart of the opposite orientation). The seam (x = 0.5) runs along u = 0.5 on the left
    island and u = 1 (the image's border) on the right; at u = 0.5 the image puts the left island's
    seam beside the right island's far edge (x = 1), far away on the surface."""
    P = np.array([[0, 0, 0], [.5, 0, 0], [1, 0, 0], [0, 1, 0], [.5, 1, 0], [1, 1, 0]], float)
    F = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]])
    UV = P[F][:, :, :2].copy()
    UV[2:] = np.stack([1.5 - UV[2:, :, 0], UV[2:, :, 1] if mirrored else 1.0 - UV[2:, :, 1]], -1)
    return Mesh(P, F, UV, name="split")


def split_map(world):
    """A (W, W) map of the unit plane's world texels laid out as split_plane's UVs."""
    out = np.empty_like(world)
    out[:, :W // 2] = world[:, :W // 2]
    out[:, W // 2:] = world[::-1, W - 1:W // 2 - 1:-1]
    return out


_SCENES = {}


def scene(name):
    """(target, occluders, exact texel AO (W, W)) of an exact scene."""
    if name not in _SCENES:
        if name == "polygon":
            _SCENES[name] = plane(), [lid(LID)], texel_mean(lambda p: 1.0 - polygon_form_factor(p, LID), W, W)
        elif name == "box on plane":
            _SCENES[name] = plane(), [box(*BOX)], plane_beside_box_ao(*BOX, W, W)
        elif name == "closed box":
            _SCENES[name] = plane(), [box((-0.5, -0.5, -0.5), (1.5, 1.5, 1.0))], np.zeros((W, W))
        elif name == "seam":
            world = texel_mean(lambda p: 1.0 - polygon_form_factor(p, SIDE_LID), W, W)
            _SCENES[name] = split_plane(), [lid(SIDE_LID)], split_map(world)
    return _SCENES[name]


_BAKES = {}


def baked(name, seed, **kw):
    key = (name, seed)
    if key not in _BAKES:
        target, occ, _ = scene(name)
        _BAKES[key] = (bake_ao(target, occ, resolution=W, samples=SAMPLES, margin=0, seed=seed, fix_seams=False),
                       D.surface_guide(target, W))
    r, g = _BAKES[key]
    return (r, g) + D.denoise(r.ao, r.stderr, r.mask, g, **kw)


# --- the guide ------------------------------------------------------------------------------------

def test_guide_of_a_plane_is_its_texel_centres():
    g = D.surface_guide(plane(), (32, 16))
    assert g.covered.all() and (g.island == 0).all() and len(g.halo_row) == 0 and len(g.links) == 0
    Y, X = np.mgrid[0:16, 0:32]
    np.testing.assert_allclose(g.position[..., 0], (X + 0.5) / 32, atol=1e-6)
    np.testing.assert_allclose(g.position[..., 1], (Y + 0.5) / 16, atol=1e-6)
    np.testing.assert_allclose(g.normal[..., 2], 1.0)
    np.testing.assert_allclose(g.scale, math.sqrt(1 / (32 * 16)), rtol=1e-6)


@pytest.mark.parametrize("mirrored", [False, True])
def test_guide_links_and_halo_cross_the_seam_to_the_texel_beside_on_the_surface(mirrored):
    g = D.surface_guide(split_plane(mirrored), W, radius=4)
    assert sorted(np.unique(g.island)) == [0, 1]
    # Every row of the seam is linked, left (i, W/2 - 1) to right (W - 1 - i, W - 1), or (i, W - 1)
    # when mirrored: one texel apart.
    rows, cols = np.divmod(g.links, W)
    swap = cols[:, 0] > cols[:, 1]
    rows[swap], cols[swap] = rows[swap][:, ::-1], cols[swap][:, ::-1]
    assert len(g.links) == W
    other_row = rows[:, 0] if mirrored else W - 1 - rows[:, 0]
    assert np.all(cols[:, 0] == W // 2 - 1) and np.all(cols[:, 1] == W - 1) and np.all(rows[:, 1] == other_row)
    p = g.position.reshape(-1, 3)
    np.testing.assert_allclose(np.linalg.norm(p[g.links[:, 0]] - p[g.links[:, 1]], axis=1), 1 / W, rtol=1e-5)
    # Halo: 4 texels on each side of the seam for every row, on both islands (the right island's
    # halo lies beyond the image's border), each standing in by the texel at its unfolded place.
    assert len(g.halo_row) == 2 * 4 * W
    left = g.halo_island == g.island[0, 0]
    assert np.all((g.halo_col[left] >= W // 2) & (g.halo_col[left] < W // 2 + 4))
    assert np.all(g.halo_col[~left] >= W) and np.all(g.halo_col[~left] < W + 4)
    # Where the halo texel of the left island would lie on the plane: x = (col + 0.5) / W.
    src = p[g.halo_source[left]]
    np.testing.assert_allclose(src[:, 0], (g.halo_col[left] + 0.5) / W, atol=1e-6)
    np.testing.assert_allclose(src[:, 1], (g.halo_row[left] + 0.5) / W, atol=1e-6)
    # The right island's halo, beyond u = 1, stands in for the left half: x = 0.5 - (col - W + 0.5) / W.
    src, row = p[g.halo_source[~left]], g.halo_row[~left]
    np.testing.assert_allclose(src[:, 0], 0.5 - (g.halo_col[~left] - W + 0.5) / W, atol=1e-6)
    np.testing.assert_allclose(src[:, 1], (row + 0.5) / W if mirrored else 1.0 - (row + 0.5) / W, atol=1e-6)


def test_guide_welds_vertices_split_at_the_same_position():
    # Exporters split vertices along UV seams: the seam is still found (vertices welded by position).
    m = split_plane()
    corners = m.positions[m.triangles].reshape(-1, 3)
    split = Mesh(corners, np.arange(len(corners)).reshape(-1, 3), m.uvs, name="split vertices")
    a, b = D.surface_guide(m, 32), D.surface_guide(split, 32)
    for f in ("covered", "island", "halo_row", "halo_col", "halo_source", "links"):
        assert np.array_equal(getattr(a, f), getattr(b, f)), f


# --- exact scenes ---------------------------------------------------------------------------------

@pytest.mark.parametrize("name", ["polygon", "box on plane", "seam", "closed box"])
def test_denoised_map_is_unbiased_and_its_error_is_honest(name):
    _, _, truth = scene(name)
    err, z, raw_var, exact_bad = [], [], [], []
    for seed in Z_SEEDS:
        r, g, ao, se, info = baked(name, seed)
        e = ao.astype(np.float64) - truth
        err.append(e)
        raw_var.append(r.stderr.astype(np.float64) ** 2)
        pos = se > 0
        z.append(e[pos] / se[pos])
        # Texels that report no error are exact (exactly open or occluded), and kept as baked.
        exact_bad.append(float(np.abs(e[~pos]).max(initial=0.0)))
        assert np.array_equal(ao[~pos], r.ao[~pos])
    assert max(exact_bad) < 1e-6, exact_bad
    err = np.array(err)
    if name == "closed box":
        assert np.all(err == 0)
        return
    # The mean error is the bias plus noise: the denoised map's mean is a weighted mean of the raw
    # estimates (each row of weights sums to 1, columns to about 1), whose independent errors give
    # the mean a standard error of at most about sqrt(mean raw variance / texels). 4.4 of them:
    # two-sided 1e-5, so the bound holds for any seed; the bias itself must be within 0.002.
    se_mean = math.sqrt(np.mean(raw_var) / err.size)
    assert abs(err.mean()) < 0.002 + 4.4 * se_mean, (err.mean(), se_mean)
    z = np.concatenate(z)
    # z over 8 bakes x 4096 texels; the denoised errors are correlated over a filter's footprint
    # (about 30 texels effective), leaving ~1100 independent values: sd of the estimated sd ~0.02
    # (measured spread of 8-bake groups: 0.025), so [0.85, 1.15] is about 3.5 of them from the
    # 0.90-0.98 measured over 48 seeds (8 at a time; mean 0.94).
    assert 0.85 <= z.std() <= 1.15, z.std()
    assert np.mean(np.abs(z) > 4) < 0.01, np.mean(np.abs(z) > 4)


def _rise(profile):
    """10-90% rise (texels) of a profile that climbs from its first values to its last."""
    lo, hi = profile[:3].mean(), profile[-2:].mean()
    p = np.maximum.accumulate((profile - lo) / (hi - lo))
    x = np.arange(len(p), dtype=np.float64)
    at = lambda f: np.interp(f, p + 1e-9 * x, x)  # noqa: E731  (strictly increasing for interp)
    return at(0.9) - at(0.1)


def test_contact_edge_stays_as_sharp_as_the_converged_map():
    # Across the box's left wall (x = 0.3, inside the box's y extent away from its corners), the
    # profile averaged over 16 rows, from 5 texels under the box to 7 outside.
    _, _, truth = scene("box on plane")
    rows = slice(21, 37)
    cols = np.arange(24, 11, -1)
    want = _rise(truth[rows][:, cols].mean(axis=0))
    for seed in SEEDS:
        _, _, ao, _, _ = baked("box on plane", seed)
        got = _rise(ao[rows][:, cols].mean(axis=0))
        assert abs(got - want) <= 1.0, (got, want)


def test_texels_either_side_of_a_uv_seam_agree():
    # For texel pairs that are neighbours on the surface across the seam, the mean |difference| is
    # no larger than the exact map's plus twice the standard error of a mean of such differences
    # (from both texels' reported errors): the two sides are filtered from the same texels.
    _, _, truth = scene("seam")
    for seed in SEEDS:
        r, g, ao, se, _ = baked("seam", seed)
        a, b = g.links[:, 0], g.links[:, 1]
        f, s, t = ao.reshape(-1), se.reshape(-1), truth.reshape(-1)
        got = np.abs(f[a] - f[b]).mean()
        bound = np.abs(t[a] - t[b]).mean() + 2 * math.sqrt(np.sum(s[a] ** 2 + s[b] ** 2)) / len(a)
        assert got <= bound, (got, bound, np.abs(r.ao.reshape(-1)[a] - r.ao.reshape(-1)[b]).mean())


def test_a_converged_texel_keeps_its_value_and_a_noisy_one_borrows():
    # Arrays alone: a flat map at 0.5 with noise 0.1, and in it a 6 x 6 patch that has converged
    # (standard error 1e-3) at 0.62, 1.2 noise units above: a real feature. The patch keeps its
    # value to within a few of its own errors; the noisy texels are smoothed.
    n = 32
    rng = np.random.default_rng(7)
    truth = np.full((n, n), 0.5)
    truth[13:19, 13:19] = 0.62
    se = np.full((n, n), 0.1, np.float32)
    se[13:19, 13:19] = 1e-3
    ao = (truth + se * rng.standard_normal((n, n))).astype(np.float32)
    g = D.surface_guide(plane(), n)
    out, err, info = D.denoise(ao, se, np.ones((n, n), bool), g)
    patch = (slice(13, 19), slice(13, 19))
    assert np.all(np.abs(out[patch] - truth[patch]) < 5e-3), np.abs(out[patch] - truth[patch]).max()
    far = np.zeros((n, n), bool)
    far[:8] = True
    assert np.sqrt(np.mean((out[far] - 0.5) ** 2)) < 0.4 * 0.1
    assert np.all(info.choice[far] > 0) and np.all(info.choice[patch] == 0)


def test_denoising_is_deterministic_and_does_not_depend_on_threads(monkeypatch):
    from core.post.denoise import filter as DF
    from core.post.denoise import wide

    r, g, ao, se, info = baked("seam", 0)
    assert np.any(info.choice > len(info.bandwidths))  # the wide fits are in it
    # Several bands of the wide fits, on several threads: the same bits.
    monkeypatch.setattr(wide, "BAND_CELLS", 3)
    for threads in (1, 3):
        ao2, se2, _ = D.denoise(r.ao, r.stderr, r.mask, g, threads=threads)
        assert np.array_equal(ao, ao2) and np.array_equal(se, se2)
    # The fine filter's band height (a constant) orders its float32 additions, and nothing else.
    monkeypatch.setattr(DF, "BAND_ROWS", 5)
    ao3, se3, _ = D.denoise(r.ao, r.stderr, r.mask, g)
    np.testing.assert_allclose(ao3, ao, atol=1e-5)
    np.testing.assert_allclose(se3, se, atol=1e-5, rtol=1e-4)


def test_margin_is_filled_and_uncovered_texels_keep_their_value():
    target = Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2]]),
                  np.array([[[0.1, 0.1], [0.9, 0.1], [0.1, 0.9]]]))
    r = bake_ao(target, [lid(LID)], resolution=32, samples=SAMPLES, margin=0, seed=1)
    g = D.surface_guide(target, 32)
    assert np.array_equal(g.covered, r.mask)  # the guide covers the texels the bake covers
    out, se, _ = D.denoise(r.ao, r.stderr, r.mask, g)
    assert np.all(out[~r.mask] == r.ao[~r.mask]) and np.all(se[~r.mask] == 0)
    filled, _, _ = D.denoise(r.ao, r.stderr, r.mask, g, margin=2)
    assert np.array_equal(filled[r.mask], out[r.mask]) and np.count_nonzero(filled[~r.mask]) > 0


def test_udim_tiles_are_denoised_across_the_seam_between_them():
    # split_plane with its right half in tile 1002 (turned, u in [1.5, 2]): the seam runs along the
    # left tile's u = 0.5 and the right tile's far border. Denoised together, the texels either side
    # agree as within one image; denoised tile by tile, they do not (each side sees half a window).
    from core import bake_udim
    from core.geometry.uvtiles import shifted

    n = 32
    target = split_plane()
    uv = target.uvs.copy()
    uv[2:, :, 0] += 1.0
    target = Mesh(target.positions, target.triangles, uv, name="split over two tiles")
    r = bake_udim(target, [lid(SIDE_LID)], resolution=n, samples=SAMPLES, margin=0, seed=2)
    assert sorted(r.tiles) == [1001, 1002]
    g = D.udim_guide(target, sorted(r.tiles), n)
    assert (g.width, g.height) == (2 * n, n) and len(g.links) == n
    out = D.denoise_udim({t: (x.ao, x.stderr, x.mask) for t, x in r.tiles.items()}, g, margin=2)
    joint = np.concatenate([out[1001][0], out[1002][0]], axis=1).reshape(-1)
    err = np.concatenate([out[1001][1], out[1002][1]], axis=1).reshape(-1)
    alone = np.concatenate([D.denoise(x.ao, x.stderr, x.mask, D.surface_guide(shifted(target, t), n))[0]
                            for t, x in sorted(r.tiles.items())], axis=1).reshape(-1)
    world = texel_mean(lambda p: 1.0 - polygon_form_factor(p, SIDE_LID), n, n)
    truth = np.concatenate([world[:, :n // 2], np.zeros((n, n // 2)), np.zeros((n, n // 2)),
                            world[::-1, n - 1:n // 2 - 1:-1]], axis=1).reshape(-1)
    a, b = g.links[:, 0], g.links[:, 1]
    bound = np.abs(truth[a] - truth[b]).mean() + 2 * math.sqrt(np.sum(err[a] ** 2 + err[b] ** 2)) / len(a)
    assert np.abs(joint[a] - joint[b]).mean() <= bound
    assert np.abs(alone[a] - alone[b]).mean() > bound
    assert not r.tiles[1001].mask[:, n // 2:].any() and np.all(out[1001][0][:, n // 2:n // 2 + 2] > 0)  # margin


def grid(nv):
    """The unit plane as a grid of nv x nv vertices (smooth: one sample point per vertex)."""
    x = np.linspace(0.0, 1.0, nv)
    X, Y = np.meshgrid(x, x)
    P = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], 1)
    I, J = np.meshgrid(np.arange(nv - 1), np.arange(nv - 1))
    v0 = (J * nv + I).ravel()
    F = np.concatenate([np.stack([v0, v0 + 1, v0 + nv + 1], 1), np.stack([v0, v0 + nv + 1, v0 + nv], 1)])
    return Mesh(P, F, name="grid")


@pytest.mark.parametrize("name", ["polygon", "box on plane"])
def test_vertex_ao_is_denoised_over_the_mesh_with_an_honest_error(name):
    # Colour-attribute bakes: the grid's vertices under the polygon or beside the resting box, exact
    # AO at each vertex (the corner's sample point is nudged by 1e-4 of the mesh's size: an AO
    # change of ~1e-4); vertices under the box are exactly 0 and must stay so with zero error.
    from core import bake_vertex_ao
    from core.montecarlo.analytic import box_on_plane_point_ao
    from core.geometry.corners import all_corners

    target = grid(33)
    c = all_corners(target)
    pts = target.positions[target.triangles[c[:, 0], c[:, 1]]]
    if name == "polygon":
        occ, truth = [lid(LID)], 1.0 - polygon_form_factor(pts, LID)
    else:
        occ, truth = [box(*BOX)], box_on_plane_point_ao(pts, *BOX[:2])
    raw_err, err, z = [], [], []
    for seed in Z_SEEDS:
        r = bake_vertex_ao(target, occ, samples=SAMPLES, seed=seed)
        ao, se, info = D.denoise_vertices(target, r.ao, r.stderr, r.unit)
        _, first = np.unique(r.unit, return_index=True)
        assert len(first) == 33 * 33
        pos = se[first] > 0
        assert np.all(np.abs(ao - truth)[first][~pos] < 1e-6)
        raw_err.append((r.ao - truth)[first])
        err.append((ao - truth)[first])
        z.append(err[-1][pos] / se[first][pos])
    raw_err, err, z = np.concatenate(raw_err), np.concatenate(err), np.concatenate(z)
    assert np.sqrt(np.mean(err ** 2)) < 0.5 * np.sqrt(np.mean(raw_err ** 2))
    # As for texels: 8 x 1089 values correlated over ~15, sd of the estimated sd ~0.03.
    assert 0.85 <= z.std() <= 1.15 and np.mean(np.abs(z) > 4) < 0.01, z.std()
    assert abs(err.mean()) < 0.002 + 4.4 * np.sqrt(np.mean(raw_err ** 2) / err.size)


def test_a_mesh_without_uvs_is_refused_by_name():
    with pytest.raises(MeshError, match="'lid' has no UVs"):
        D.surface_guide(lid(LID), 16)


def test_a_guide_of_another_resolution_or_too_small_a_window_is_refused():
    g = D.surface_guide(plane(), 16)
    with pytest.raises(ValueError, match="16 x 16"):
        D.denoise(np.zeros((8, 8)), np.zeros((8, 8)), np.ones((8, 8), bool), g)
    with pytest.raises(ValueError, match="at least 2"):
        D.denoise(np.zeros((16, 16)), np.zeros((16, 16)), np.ones((16, 16), bool), g, radius=1)
    with pytest.raises(ValueError, match="halo radius"):
        D.denoise(np.zeros((16, 16)), np.zeros((16, 16)), np.ones((16, 16), bool), g, radius=4)


def test_an_open_plane_comes_back_unchanged():
    r = bake_ao(plane(), resolution=32, samples=SAMPLES, margin=0)
    out, se, info = D.denoise(r.ao, r.stderr, r.mask, D.surface_guide(plane(), 32))
    assert np.array_equal(out, r.ao) and np.all(se == 0) and np.all(info.choice == 0)
