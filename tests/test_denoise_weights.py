"""The denoiser's weights and the variance it propagates, across a UV seam, against the slow obvious
computation: the filter's derivatives, one texel at a time.

With the AO term held flat (``range_sigmas`` huge, so no weight depends on the values), each candidate
is a linear smoother F_i = sum_j w_ij y_j / W_i, and the texel's choice among them does not move under a
small change of one input. So a finite difference of the output in y_j is J_ij = w_ij / W_i, and

- the propagated variance of every texel is sum_j J_ij^2 sigma_j^2 (the module docstring's V_k), across
  the seam too (a neighbour on the other island counts with its own sigma);
- the weights are the documented ones: w_ij / w_ii = exp(-|p_i - p_j|^2 (s_i^-2 + s_j^-2) / 2 / (2 h^2))
  exp(-beta (1 - n_i . n_j)), h the chosen candidate's bandwidth, p, n, s the texels' surface points,
  normals and world sizes; a neighbour across the seam at its real place on the surface.

The scene: a plane folded by 10 degrees along x = 0.5, its halves two UV islands (the right one turned
by 180 degrees, as tests/test_denoise.py's split plane), under a lid; uniform directions and the
independent source, so that every texel has an error (sigma > 0) and none is taken as exact.
"""

import math

import numpy as np
import pytest

from core import Mesh, bake_ao
from core.post import denoise as D
from test_denoise import SIDE_LID, lid

W = 16
FOLD = math.radians(10.0)
EPS = np.float32(1.0 / 64)  # a power of two: y - EPS is exact in float32


def folded_plane():
    P = np.array([[0, 0, 0], [.5, 0, 0], [1, 0, 0], [0, 1, 0], [.5, 1, 0], [1, 1, 0]], float)
    F = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]])
    UV = P[F][:, :, :2].copy()
    UV[2:] = np.stack([1.5 - UV[2:, :, 0], 1.0 - UV[2:, :, 1]], -1)
    right = P[:, 0] > 0.5
    P[right, 2] = -(P[right, 0] - 0.5) * math.sin(FOLD)
    P[right, 0] = 0.5 + (P[right, 0] - 0.5) * math.cos(FOLD)
    return Mesh(P, F, UV, name="folded")


@pytest.fixture(scope="module")
def linearised():
    target = folded_plane()
    r = bake_ao(target, [lid(SIDE_LID)], resolution=W, samples=32, margin=0, seed=3, distribution="uniform",
                source="independent", replicates=1)
    guide = D.surface_guide(target, W)
    y, se, mask = r.ao.astype(np.float32), r.stderr.astype(np.float32), r.mask
    assert mask.all() and np.all(se > 0)
    kw = dict(range_sigmas=1e6, threads=1)
    out, _, info = D.denoise(y, se, mask, guide, **kw)
    n = W * W
    J = np.zeros((n, n))
    stable = np.ones(n, bool)
    for j in range(n):
        yj = y.copy()
        yj.reshape(-1)[j] -= EPS
        oj, _, ij = D.denoise(yj, se, mask, guide, **kw)
        J[:, j] = (out.astype(np.float64) - oj).reshape(-1) / float(EPS)
        stable &= (ij.choice == info.choice).reshape(-1)
    return guide, se.astype(np.float64).reshape(-1), info, J, stable


def test_the_propagated_variance_is_the_sum_of_squared_derivatives_times_each_inputs_variance(linearised):
    guide, sigma, info, J, stable = linearised
    assert stable.mean() > 0.95 and np.any(info.choice == 1) and np.any(info.choice == 2)
    want = (J ** 2) @ (sigma ** 2)
    got = info.variance.reshape(-1).astype(np.float64)
    np.testing.assert_allclose(got[stable], want[stable], rtol=2e-3)
    # Across the seam: texels whose filter reaches the other island (their derivatives say so).
    other = guide.island.reshape(-1)[None, :] != guide.island.reshape(-1)[:, None]
    crossing = stable & (np.abs(J * other).sum(axis=1) > 0.05)
    assert crossing.sum() >= 2 * W, crossing.sum()  # both sides, every row
    np.testing.assert_allclose(got[crossing], want[crossing], rtol=2e-3)


def test_the_weights_are_the_documented_ones_across_the_seam_too(linearised):
    guide, _, info, J, stable = linearised
    p = guide.position.reshape(-1, 3).astype(np.float64)
    nrm = guide.normal.reshape(-1, 3).astype(np.float64)
    inv_s2 = 1.0 / guide.scale.reshape(-1).astype(np.float64) ** 2
    island = guide.island.reshape(-1)
    choice = info.choice.reshape(-1)
    checked = crossed = 0
    for i in np.flatnonzero(stable & (choice > 0) & (choice <= len(info.bandwidths))):
        h = info.bandwidths[choice[i] - 1]
        js = np.flatnonzero(np.abs(J[i]) > 1e-3)
        d2 = ((p[js] - p[i]) ** 2).sum(axis=1) * (inv_s2[js] + inv_s2[i]) / 2
        want = np.exp(-d2 / (2 * h * h)) * np.exp(-D.NORMAL_SHARPNESS * (1 - nrm[js] @ nrm[i]))
        np.testing.assert_allclose(J[i, js] / J[i, i], want, rtol=5e-3, atol=2e-4, err_msg=f"texel {i}")
        checked += 1
        crossed += int(np.any(island[js] != island[i]))
    assert checked > W * W // 2 and crossed >= 2 * W, (checked, crossed)
