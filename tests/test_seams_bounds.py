"""Fix Seams within its value range: the texels the fix holds at a bound are held there while the
others are solved again, so the texels inside the range are the least-squares solution of the fix's
objective with the held ones fixed at the bound (the dense solution, built row by row here), not
one solved against values past the bound and cut afterwards."""

import numpy as np

from core import bake_ao
from core.geometry import seams as G
from core.post import fixseams as F
from seam_scenes import charts


def dense_solution(values, stderr, mask, L, held):
    """The minimiser of fix_seams' objective over the texels the lookups read, texels of zero error
    and ``held`` ({flat index: value}) fixed: rows sqrt(weight) x (lookup A - lookup B) per point and
    sqrt(weight) x (x_i - y_i) per free texel, in units of the median error of the free covered texels."""
    flat_v, flat_s, flat_m = values.reshape(-1).astype(float), stderr.reshape(-1).astype(float), mask.reshape(-1)
    fixed = dict(held)
    texels = np.unique(L.index)
    free = np.array([t for t in texels if not (flat_m[t] and flat_s[t] == 0) and t not in fixed])
    col = {t: i for i, t in enumerate(free)}
    s_ref = np.median(flat_s[free][flat_m[free]])
    rows, rhs = [], []
    for k in range(L.points):
        row, const = np.zeros(len(free)), 0.0
        for t, w in zip(L.index[k], L.weight[k]):
            if t in col:
                row[col[t]] += w
            else:
                const += w * fixed.get(t, flat_v[t])
        sw = np.sqrt(F.SEAM_WEIGHT * L.length[k]) / s_ref
        rows.append(sw * row)
        rhs.append(-sw * const)
    for i, t in enumerate(free):
        row = np.zeros(len(free))
        sw = 1 / flat_s[t] if flat_m[t] else np.sqrt(F.MARGIN_WEIGHT) / s_ref
        row[i] = sw
        rows.append(row)
        rhs.append(sw * flat_v[t])
    return free, np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)[0]


def test_texels_inside_the_range_are_solved_with_the_ones_past_it_held_at_the_bound():
    target, occ, _, _ = charts(width=24, grid=2, cell=10, gap=2)
    r = bake_ao(target, occ, resolution=24, samples=16, seed=3, margin=2)
    # One error for every covered texel: the objective's unit (their median) is the same whichever
    # texels are held.
    stderr = np.where(r.mask, np.float32(0.05), r.stderr).astype(np.float32)
    L = G.seam_lookups(target, 24)
    _, x = dense_solution(r.ao, stderr, r.mask, L, {})
    lo, hi = float(np.quantile(x, 0.03)), float(np.quantile(x, 0.97))  # a few texels past each bound
    out, _, info = F.fix_seams(r.ao, stderr, r.mask, L, value_range=(lo, hi), tolerance=1e-10)
    assert 1 < info.rounds < F.BOUND_ROUNDS  # held texels, and the last solve crossed no bound
    flat = out.reshape(-1)
    at = np.array([t for t in info.texels if flat[t] in (np.float32(lo), np.float32(hi))])
    assert len(at) >= 2
    free, x = dense_solution(r.ao, stderr, r.mask, L, {t: float(flat[t]) for t in at})
    assert ((x >= lo - 1e-6) & (x <= hi + 1e-6)).all()
    np.testing.assert_allclose(flat[free], x, atol=2e-6)
