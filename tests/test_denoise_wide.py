"""The denoiser's wide candidates (core.post.denoise.wide) against the slow obvious computation.

Each wide candidate is a least-squares plane over the texels of one island in a rectangle of cells
around the texel's cell: here the plane is fitted texel by texel with numpy's lstsq, its variance is
the sum of the squared derivatives times each input's variance (the fit is linear in the map: its
derivatives are its response to each input alone), and its bias estimate is the fine result's
squared residual from its own plane, averaged over the rectangle. Small maps, nothing random except
the values, nothing timed.
"""

import numpy as np
import pytest

from core.post.denoise import wide as Wd

H = W = 24
#: One shape per cell side, so each texel's wide candidate is one fixed fit (the choice among shapes
#: of a side would depend on the bias estimate).
SHAPES = ((4, 2), (8, 16))


def flat_normals(h=H, w=W):
    n = np.zeros((h, w, 3))
    n[..., 2] = 1.0
    return n


def islands():
    """Two islands whose cells (of either side) each hold one island, a gutter between them, an
    uncovered corner, a diagonal border and holes (cells partly covered, so their first moments are
    not zero)."""
    isl = np.full((H, W), -1)
    isl[:, :12] = 0
    isl[:, 16:] = 1
    isl[20:, 20:] = -1
    isl[:4, :4] = -1
    r, c = np.mgrid[0:H, 0:W]
    isl[(r - c > 15) & (c < 12)] = -1
    isl[5, 7] = isl[10, 9] = isl[13, 18] = -1
    return isl


def fits(y, var, isl, pilot, pilot_var, normal=None, shapes=SHAPES):
    """WideFits' candidates laid out per texel: a list per cell side of (F, V, B^2), each (H, W)."""
    mask = isl >= 0
    f = Wd.WideFits(y, var, mask, isl, flat_normals() if normal is None else normal, pilot, pilot_var,
                    shapes=shapes)
    out = None
    for rows, cands in f.bands():
        if out is None:
            out = [[np.full((f.H, f.W), np.nan) for _ in range(3)] for _ in cands]
        for o, c in zip(out, cands):
            for a, b in zip(o, c):
                a[rows] = b
    return [[a[:H, :W] for a in o] for o in out]


def rectangle(i, j, shape, isl):
    """The texels of the slow fit for texel (i, j): the covered texels of its island in the cells of
    the shape's rectangle around its cell."""
    s = Wd.cell_side(shape)
    rx, ry = shape[0] // s, shape[1] // s
    ci, cj = i // s, j // s
    rows = slice(max((ci - ry) * s, 0), min((ci + ry + 1) * s, H))
    cols = slice(max((cj - rx) * s, 0), min((cj + rx + 1) * s, W))
    sel = np.zeros((H, W), bool)
    sel[rows, cols] = True
    return sel & (isl == isl[i, j])


def slow_plane(values, sel, i, j):
    """Least-squares plane through values[sel] (texel centres), its value at (i, j), and the
    weights l of that value (value = sum l y)."""
    r, c = np.nonzero(sel)
    X = np.stack([np.ones(len(r)), c - j, r - i], axis=1).astype(np.float64)
    pinv = np.linalg.pinv(X)
    l = pinv[0]
    return float(l @ values[r, c]), l, (r, c)


@pytest.fixture(scope="module")
def setup():
    rng = np.random.default_rng(5)
    isl = islands()
    Y, X = np.mgrid[0:H, 0:W] + 0.5
    y = np.where(isl >= 0, 0.3 + 0.4 * rng.random((H, W)), 0)
    var = np.where(isl >= 0, 0.001 + 0.004 * rng.random((H, W)), 0)
    pilot = np.where(isl >= 0, 0.5 + 0.01 * X - 0.02 * Y + 0.002 * (X - 12) ** 2 + 0.05 * (isl == 1), 0)
    pilot_var = np.where(isl >= 0, 1e-4, 0)
    return isl, y, var, pilot, pilot_var


def test_a_plane_is_fitted_exactly_up_to_the_islands_border():
    isl = islands()
    Y, X = np.mgrid[0:H, 0:W] + 0.5
    plane = np.where(isl == 0, 0.2 + 0.01 * X + 0.015 * Y, 0.9 - 0.02 * X)
    out = fits(plane, np.full((H, W), 1e-3), isl, plane, np.zeros((H, W)))
    for F, V, B2 in out:
        used = np.isfinite(F)
        assert used.sum() > 100
        np.testing.assert_allclose(F[used], plane[used], atol=1e-9)
        # a plane is its own fit: no bias
        np.testing.assert_allclose(B2[used], 0, atol=1e-12)


def test_each_fit_is_the_least_squares_plane_of_its_island_in_its_rectangle(setup):
    isl, y, var, pilot, pilot_var = setup
    out = fits(y, var, isl, pilot, pilot_var)
    checked = 0
    for shape, (F, V, B2) in zip(SHAPES, out):
        for i, j in zip(*np.nonzero(np.isfinite(F))):
            sel = rectangle(i, j, shape, isl)
            want, l, (r, c) = slow_plane(y, sel, i, j)
            assert F[i, j] == pytest.approx(want, abs=1e-9)
            # the variance: squared weights times each texel's variance (the texels are independent)
            assert V[i, j] == pytest.approx(float(np.sum(l * l * var[r, c])), rel=1e-7)
            checked += 1
    assert checked > 300


def test_the_bias_is_the_fine_results_residual_from_its_plane_averaged_over_the_rectangle(setup):
    isl, y, var, pilot, pilot_var = setup
    out = fits(y, var, isl, pilot, pilot_var)
    for shape, (F, V, B2) in zip(SHAPES, out):
        used = np.isfinite(F)
        for i, j in list(zip(*np.nonzero(used)))[::7]:
            # every texel of the rectangle whose own cell fits: its residual from its cell's plane
            sel = rectangle(i, j, shape, isl)
            total, count = 0.0, 0
            for a, b in zip(*np.nonzero(sel)):
                if not used[a, b]:
                    continue
                # the plane of the texel's cell (fitted over the cell's rectangle) at the texel
                lpc, _, _ = slow_plane(pilot, rectangle(a, b, shape, isl), a, b)
                total += (lpc - pilot[a, b]) ** 2 - Wd.PILOT_DEBIAS * pilot_var[a, b]
                count += 1
            assert B2[i, j] == pytest.approx(max(total / count, 0.0), rel=1e-6, abs=1e-12), (shape, i, j)


def test_no_fit_reaches_another_island(setup):
    isl, y, var, pilot, pilot_var = setup
    base = fits(y, var, isl, pilot, pilot_var)
    other = np.where(isl == 1, 1.0 - y, y)  # island 1's values changed, island 0's kept
    moved = fits(other, var, isl, np.where(isl == 1, 0.1, pilot), pilot_var)
    for (F0, V0, B0), (F1, V1, B1) in zip(base, moved):
        zero = isl == 0
        assert np.isfinite(F0[zero]).sum() > 100
        np.testing.assert_array_equal(F0[zero], F1[zero])
        np.testing.assert_array_equal(B0[zero], B1[zero])


def test_a_fold_in_the_rectangle_stops_the_fit(setup):
    isl, y, var, pilot, pilot_var = setup
    n = flat_normals()
    # island 0 folds by 60 degrees at x = 6: one folded texel among a rectangle's 60 spreads its
    # normals by 1 - |mean normal| > FLATNESS
    n[:, 6:] = (np.sin(np.pi / 3), 0.0, np.cos(np.pi / 3))
    F = fits(y, var, isl, pilot, pilot_var, normal=n)[0][0]
    Fflat = fits(y, var, isl, pilot, pilot_var)[0][0]
    cols = np.broadcast_to(np.arange(W)[None, :], (H, W))
    crossing = np.zeros((H, W), bool)
    for i, j in zip(*np.nonzero(isl == 0)):
        c = cols[rectangle(i, j, SHAPES[0], isl)]
        crossing[i, j] = c.min() < 6 <= c.max()
    assert crossing.sum() > 50 and np.isfinite(Fflat[crossing]).all()
    assert not np.isfinite(F[crossing]).any()
    np.testing.assert_array_equal(F[(isl == 0) & ~crossing], Fflat[(isl == 0) & ~crossing])


def test_a_line_of_texels_holds_no_plane():
    isl = np.full((H, W), -1)
    isl[9, 2:22] = 0
    d = np.arange(2, 22)
    isl[d, d] = 1  # a slanted line
    y = np.where(isl >= 0, 0.5, 0.0)
    out = fits(y, np.full((H, W), 1e-3), isl, y, np.zeros((H, W)))
    for F, V, B2 in out:
        # no plane, or one whose variance rules it out
        assert np.all(~np.isfinite(F) | (V > 1.0))


def test_bands_and_threads_give_the_same_bits(setup, monkeypatch):
    isl, y, var, pilot, pilot_var = setup
    mask = isl >= 0

    def run(threads):
        f = Wd.WideFits(y, var, mask, isl, flat_normals(), pilot, pilot_var, shapes=Wd.SHAPES)
        return [np.concatenate([c[k][0] for _, c in f.bands(threads)]) for k in range(2)]

    whole = run(1)
    monkeypatch.setattr(Wd, "BAND_CELLS", 1)
    for threads in (1, 3):
        for a, b in zip(whole, run(threads)):
            np.testing.assert_array_equal(a, b)
