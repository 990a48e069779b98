"""The error map and adaptive sampling against exact answers.

The error a bake reports must be the error it makes: z = (ao - exact) / stderr over the texels of
scenes whose AO is known in closed form has mean 0 and standard deviation 1, for every sample source,
at few and at many samples. Adaptive sampling at target t must leave at most 5% of the texels more
than t from the exact value. The parts (Student's t quantile, window sums, the replicate variance)
are checked against references first.
"""

import math

import numpy as np
import pytest
from scipy import stats as sps

from core import Mesh, bake_ao
from core.montecarlo.analytic import plane_beside_box_ao, polygon_form_factor, regular_polygon, texel_mean
from core.engine.estimators import POOL_BLOCK, POOL_RADIUS, TexelEstimates, TexelWindows, t_quantile, window_sums
from core.engine.patterns import TexelPattern
from scenes import box, plane

SOURCES = ["sobol", "halton", "stratified", "independent"]
QUAD = np.array([[0, 1, 2], [0, 2, 3]])


# --- the parts -----------------------------------------------------------------------------------

@pytest.mark.parametrize("p", [0.9, 0.95, 0.975, 0.995])
def test_t_quantile_matches_scipy(p):
    dof = np.array([1, 2, 3, 4, 5, 8, 10, 16, 24, 50, 100, 1000, 1e6])
    got = t_quantile(p, dof)
    want = sps.t.ppf(p, dof)
    rel = np.abs(got - want) / want
    assert np.all(rel[dof <= 2] < 1e-9) and np.all(rel[dof >= 3] < 1e-2)
    assert np.all(rel[dof >= 10] < 5e-5) and np.all(rel[dof >= 50] < 1e-7)


@pytest.mark.parametrize("p", [0.9, 0.975])
def test_t_quantile_of_a_tile_of_whole_degrees_of_freedom_is_each_value_alone(p):
    # More than a few hundred whole numbers go through a table of each of them: the same values as
    # one at a time, and as scipy's.
    rng = np.random.default_rng(4)
    for top in (2, 24, 75, 4096):
        dof = rng.integers(0, top + 1, 5000).astype(np.float64)
        got = t_quantile(p, dof)
        alone = np.array([t_quantile(p, np.array([d]))[0] for d in dof[:400]])
        np.testing.assert_array_equal(got[:400], alone)
        ok = dof >= 10
        np.testing.assert_allclose(got[ok], sps.t.ppf(p, dof[ok]), rtol=5e-5)
    # Not whole, negative, or beyond the table: value by value.
    for dof in (rng.random(1000) * 30, np.full(1000, 5000.0)):
        np.testing.assert_array_equal(t_quantile(p, dof), [t_quantile(p, np.array([d]))[0] for d in dof])


def _brute_window_sums(v, x, y, W, H):
    dense = np.zeros((H, W))
    dense[y, x] = v
    B, r = POOL_BLOCK, POOL_RADIUS
    return np.array([dense[max(yy - r, yy // B * B):min(yy + r, yy // B * B + B - 1) + 1,
                           max(xx - r, xx // B * B):min(xx + r, xx // B * B + B - 1) + 1].sum()
                     for xx, yy in zip(x, y)])


def test_window_sums_equal_a_brute_force_sum_within_blocks():
    rng = np.random.default_rng(1)
    W, H = 48, 40
    keep = rng.random((H, W)) < 0.7  # texels not covered are missing from the lists
    y, x = np.nonzero(keep)
    v = rng.random(len(x))
    (got,) = window_sums([v], x, y)
    np.testing.assert_allclose(got, _brute_window_sums(v, x, y, W, H), rtol=1e-12, atol=1e-12)


def test_texel_windows_set_up_once_sum_any_rows_of_the_same_texels():
    # A tile's windows are set up once and summed over every round: any number of rows, in any
    # order of calls, each the brute-force sum (and the same as window_sums built for one call).
    rng = np.random.default_rng(5)
    W, H = 64, 48
    y, x = np.nonzero(rng.random((H, W)) < 0.6)
    x, y = x + 32, y + 16  # a tile away from the image's corner
    windows = TexelWindows(x, y)
    for k in (1, 3, 3, 2, 1):
        v = rng.random((k, len(x)))
        got = windows.sums(v)
        for j in range(k):
            np.testing.assert_allclose(got[j], _brute_window_sums(v[j], x - 32, y - 16, W, H), rtol=1e-12, atol=1e-12)
        np.testing.assert_array_equal(got, window_sums(v, x, y))
        np.testing.assert_array_equal(got, window_sums(v, windows, None))
    assert TexelWindows(x[:0], y[:0]).sums(np.zeros((2, 0))).shape == (2, 0)


def test_replicate_variance_is_unbiased_for_equal_and_unequal_replicates():
    # Replicate means of independent normal samples: E[estimate] = var(mean) = sigma^2 / N.
    rng = np.random.default_rng(2)
    sigma, texels = 0.3, 20000
    for sizes in ([8, 8], [13, 12], [5, 5, 5, 5], [9, 8, 8]):
        est = TexelEstimates(texels, len(sizes))
        for r, k in enumerate(sizes):
            x = rng.normal(0.5, sigma, (texels, k))
            est.add(np.arange(texels), k, x.sum(axis=1), (x * x).sum(axis=1), r)
        v = est.replicate_variance()
        want = sigma ** 2 / sum(sizes)
        # The mean of the estimates over 20000 texels: within 4 standard errors of the truth.
        se = v.std() / math.sqrt(texels)
        assert abs(v.mean() - want) < 4 * se, (sizes, v.mean(), want)


def test_replicates_of_a_texel_draw_distinct_patterns_and_keys():
    for samples in (16, 4096, 1 << 19):
        pattern = TexelPattern("sobol", 3, samples, pool_points=max(2 * samples, 1 << 12))
        texels = np.arange(4096)
        a, b = pattern.keys(texels, 0), pattern.keys(texels, 1)
        assert pattern.patterns >= 2
        assert np.all(a.pattern != b.pattern)
        chance = 1.0 / pattern.length  # two independent orders agree this often
        assert np.mean(a.order == b.order) < chance + 0.01 and np.mean(np.all(a.shift == b.shift, axis=1)) < 0.01


# --- calibration against exact answers -----------------------------------------------------------

W = 32
LID = regular_polygon(0.3, 0.25, 64, centre=(0.5, 0.5))
BOX = ((0.3, 0.3, 0.0), (0.7, 0.6, 0.25))
BIG_LID = np.array([[-1.0, -1.0, 0.3], [2.0, -1.0, 0.3], [2.0, 2.0, 0.3], [-1.0, 2.0, 0.3]])


def _scene(name):
    """(occluders, max_distance, exact texel AO (W, W), seeds) of an analytic scene."""
    if name == "polygon":  # a plane under a hovering 64-gon: 1 - F by Lambert's formula
        lid = Mesh(LID, np.array([[0, i, i + 1] for i in range(1, 63)]), name="lid")
        return [lid], math.inf, texel_mean(lambda p: 1.0 - polygon_form_factor(p, LID), W, W), 4
    if name == "box":  # a closed box resting on the plane: 1 - the form factors of its faces
        return [box(*BOX)], math.inf, plane_beside_box_ao(*BOX, W, W), 4
    # The truncated cone: a plane under a large lid at h = 0.3, AO distance 0.5: (h / d)^2. Every
    # texel sees the same integrand, so texels that share a pattern of the pool make the same error:
    # more bakes for the same power.
    return [Mesh(BIG_LID, QUAD, name="lid")], 0.5, np.full((W, W), 0.36), 8


_EXACT = {}


def exact(name):
    if name not in _EXACT:
        _EXACT[name] = _scene(name)
    return _EXACT[name]


@pytest.mark.slow
@pytest.mark.parametrize("scene", ["polygon", "box", "cone"])
@pytest.mark.parametrize("samples", [64, 1024])
@pytest.mark.parametrize("source", SOURCES)
def test_the_error_map_is_the_error_it_makes(scene, samples, source):
    occluders, distance, truth, seeds = exact(scene)
    z = []
    for seed in range(seeds):
        r = bake_ao(plane(), occluders, resolution=W, samples=samples, max_distance=distance, margin=0,
                    source=source, seed=seed, threads=2)
        partly = (truth > 1e-9) & (truth < 1 - 1e-9)  # texels whose exact AO is 0 or 1 make no error
        assert np.all(r.stderr[partly] > 0)
        with np.errstate(invalid="ignore", divide="ignore"):
            z.append(((r.ao - truth) / r.stderr)[partly])
    z = np.concatenate(z)
    # The bounds asked of the error map. Over 4096 (cone: 8192) values the estimates' own noise is about 0.02 on
    # the standard deviation and 0.02-0.04 on the mean (texels sharing a pool pattern correlate).
    assert 0.85 <= z.std() <= 1.15, z.std()
    assert abs(z.mean()) < 0.1, z.mean()


def test_one_replicate_overstates_the_error_of_a_quasi_monte_carlo_source():
    # What replicates are for: without them the error map is the independent-sample formula, which
    # Owen-scrambled Sobol' beats by far (measured sd of z about 0.4 at 64 samples, 0.25 at 1024).
    occluders, distance, truth, _ = exact("polygon")
    r = bake_ao(plane(), occluders, resolution=W, samples=1024, margin=0, seed=1, replicates=1)
    assert ((r.ao - truth) / r.stderr).std() < 0.5


@pytest.mark.parametrize("distribution", ["cosine", "uniform"])
def test_without_replicates_the_error_is_the_sample_formula_of_the_rays_traced(distribution):
    # With one replicate a texel's error is sqrt(s^2 / n), s^2 the unbiased sample variance
    # (ddof 1) of its n terms: here recomputed from the very rays the bake traced (a flat plane's
    # terms: V for cosine directions, 2 cos(theta) V for uniform ones, cos(theta) the direction's z).
    n = 12
    rays = []
    r = bake_ao(plane(), [box((0.3, 0.3, 0.2), (0.7, 0.7, 0.4))], resolution=4, samples=n, margin=0, seed=3,
                replicates=1, distribution=distribution,
                on_rays=lambda b: rays.append((b.texels.copy(), ~b.occluded, b.directions[:, 2].astype(np.float64))))
    texels = np.concatenate([t for t, _, _ in rays])
    terms = np.concatenate([v for _, v, _ in rays]).astype(np.float64)
    if distribution == "uniform":
        terms *= 2 * np.concatenate([z for _, _, z in rays])
    want = np.zeros(16)
    for t in range(16):
        x = terms[texels == t]
        assert len(x) == n
        want[t] = x.std(ddof=1) / math.sqrt(n)
    assert np.count_nonzero(want) >= 4 and np.ptp(want) > 0
    np.testing.assert_allclose(r.stderr.reshape(-1), want, rtol=1e-5, atol=1e-7)


# --- adaptive sampling keeps its promise ---------------------------------------------------------

@pytest.mark.slow
@pytest.mark.parametrize("scene", ["polygon", "box"])
@pytest.mark.parametrize("source", SOURCES)
def test_adaptive_sampling_keeps_its_promise(scene, source):
    # At target t at most 5% of the texels may be more than t from the exact AO (the interval is
    # 95%); the cap is high enough that hardly any texel needs it (a texel the box's footprint cuts
    # has a step inside it, which the stratified source converges on slowly).
    occluders, distance, truth, _ = exact(scene)
    target = {"independent": 0.03, "stratified": 0.02}.get(source, 0.015)
    misses, samples = [], []
    for seed in range(2):
        r = bake_ao(plane(), occluders, resolution=W, samples=8192, min_samples=16, target_error=target,
                    max_distance=distance, margin=0, source=source, seed=seed, threads=2)
        misses.append(np.mean(np.abs(r.ao - truth) > target))
        samples.append(r.samples)
    m = 2 * W * W
    assert np.mean(misses) <= 0.05 + 3 * math.sqrt(0.05 * 0.95 / m), misses
    assert np.mean([np.mean(s == 8192) for s in samples]) < 0.01


def test_open_and_fully_occluded_texels_stop_at_the_minimum():
    # The box resting on the plane: under it AO is exactly 0, far from it almost 1 at a small AO
    # distance. Texels whose whole window agrees stop at min_samples.
    lo, hi = BOX
    r = bake_ao(plane(), [box(lo, hi)], resolution=W, samples=4096, min_samples=16, target_error=0.01,
                max_distance=0.05, margin=0, seed=3)
    x = (np.arange(W) + 0.5) / W
    X, Y = np.meshgrid(x, x)
    inside = (X > lo[0] + 3 / W) & (X < hi[0] - 3 / W) & (Y > lo[1] + 3 / W) & (Y < hi[1] - 3 / W)
    far = (np.minimum.reduce([np.abs(X - lo[0]), np.abs(X - hi[0])]) > 0.2) | \
          (np.minimum.reduce([np.abs(Y - lo[1]), np.abs(Y - hi[1])]) > 0.2)
    far &= ~((X > lo[0]) & (X < hi[0]) & (Y > lo[1]) & (Y < hi[1]))
    assert inside.any() and far.any()
    assert np.all(r.ao[inside] == 0) and np.all(r.samples[inside] == 16)
    assert np.all(r.ao[far] == 1) and np.all(r.samples[far] == 16)


@pytest.mark.slow
def test_texels_beside_a_resting_box_get_their_own_error():
    # Under the box AO is exactly 0 and every sample agrees. Beside it the AO drops steeply to the
    # wall: a texel there must not take its variance from the agreeing texels under the box (which
    # would understate its error by up to half): it pools over the texels whose samples vary.
    occluders, distance, truth, _ = exact("box")
    inside = truth < 1e-9
    near = np.zeros_like(inside)
    for dy in range(-2, 3):
        for dx in range(-2, 3):
            near |= np.roll(np.roll(inside, dy, 0), dx, 1)
    rim = near & ~inside & (truth < 1)
    z = []
    for seed in range(8):
        r = bake_ao(plane(), occluders, resolution=W, samples=64, margin=0, seed=seed, threads=2)
        z.append(((r.ao - truth) / r.stderr)[rim])
    z = np.concatenate(z)
    assert z.size > 500 and z.std() < 1.22, z.std()  # pooled over every texel: 1.34
