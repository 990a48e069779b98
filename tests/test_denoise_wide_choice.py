"""The denoiser's choice among wide candidates of one cell side (core.post.denoise.wide) against the
slow obvious computation: each cell takes the shape whose fit has the least mean squared error over
the cell's texels, the mean of its variance at each of them plus its squared bias, each shape's
numbers taken from a WideFits of that shape alone. Cells on an island's border (partly covered, so
their first moments are not zero) included. Small maps, nothing timed."""

import numpy as np

from core.post.denoise import wide as Wd

H = W = 24
#: Shapes of one cell side (2): the choice among them is what is tested.
SHAPES = ((4, 2), (2, 6), (6, 6))


def islands():
    """Two islands, a gutter, a diagonal border and holes: many cells partly covered."""
    isl = np.full((H, W), -1)
    isl[:, :12] = 0
    isl[:, 16:] = 1
    isl[20:, 20:] = -1
    r, c = np.mgrid[0:H, 0:W]
    isl[(r - c > 15) & (c < 12)] = -1
    isl[(r + c) % 7 == 0] = -1
    isl[5, 7] = isl[10, 9] = isl[13, 18] = -1
    return isl


def candidates(y, var, isl, pilot, pilot_var, shapes):
    """The cell side 2 candidate (F, V, B^2) per texel of a WideFits of ``shapes``, each (H, W)."""
    normal = np.zeros((H, W, 3))
    normal[..., 2] = 1.0
    f = Wd.WideFits(y, var, isl >= 0, isl, normal, pilot, pilot_var, shapes=shapes)
    out = [np.full((f.H, f.W), np.nan) for _ in range(3)]
    for rows, cands in f.bands():
        for a, b in zip(out, cands[0]):
            a[rows] = b
    return [a[:H, :W] for a in out]


def test_each_cell_takes_the_shape_of_least_mean_squared_error_over_its_texels():
    rng = np.random.default_rng(11)
    isl = islands()
    Y, X = np.mgrid[0:H, 0:W] + 0.5
    y = np.where(isl >= 0, 0.3 + 0.4 * rng.random((H, W)), 0)
    var = np.where(isl >= 0, 0.001 + 0.02 * rng.random((H, W)), 0)
    pilot = np.where(isl >= 0, 0.5 + 0.01 * X - 0.02 * Y + 0.003 * (Y - 10) ** 2 + 0.05 * (isl == 1), 0)
    pilot_var = np.where(isl >= 0, 1e-4, 0)
    F, V, B2 = candidates(y, var, isl, pilot, pilot_var, SHAPES)
    each = [candidates(y, var, isl, pilot, pilot_var, (shape,)) for shape in SHAPES]
    chosen, border = set(), 0
    for ci in range(H // 2):
        for cj in range(W // 2):
            cell = (slice(2 * ci, 2 * ci + 2), slice(2 * cj, 2 * cj + 2))
            used = np.isfinite(F[cell])
            if not used.any():
                continue
            mse = []
            for Fs, Vs, Bs in each:
                ok = np.isfinite(Fs[cell])
                assert not ok.any() or np.array_equal(ok, used)  # a shape fits all the cell's texels or none
                mse.append(float(np.mean(Vs[cell][ok]) + Bs[cell][ok][0]) if ok.any() else np.inf)
            k = int(np.argmin(mse))  # the first of equals, as the code takes them
            np.testing.assert_array_equal(F[cell][used], each[k][0][cell][used])
            np.testing.assert_array_equal(V[cell][used], each[k][1][cell][used])
            chosen.add(k)
            border += used.sum() < 4
    assert len(chosen) >= 2 and border > 20  # the shapes take turns; border cells are among those checked
