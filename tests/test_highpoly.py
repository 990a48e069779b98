"""Selected to active (core.highpoly): the AO of high-poly meshes baked into a low-poly's UVs.

Against analytic truth (a high plane under a hovering polygon, AO = 1 - F at the projected points),
Cycles' rules for the matching rays (extrusion, cage, max ray distance, nearest hit, back faces,
misses), who occludes (never the low-poly or the cage), the directions about the high-poly's own
normal (chi-square), determinism, cancellation, and every bad input refused with a message that
names the meshes and says what to change.
"""

import math
import threading

import numpy as np
import pytest

from core import BakeCancelled, Mesh, MeshError, SettingsError, bake_ao, warps
from core.engine.estimators import interval_half_width
from core.highpoly.stage import DIRECTIONS_PER_POINT, PRECHECK_POINTS, directions_per_point
from core.montecarlo.stats import normal_quantile
from chi2 import SUITE_ALPHA, chi2_test, sidak
from core.montecarlo.analytic import regular_polygon
from scenes import QUAD, plane, polygon_form_factor, texel_mean

LID = np.array([[0.25, 0.25, 0.3], [0.75, 0.25, 0.3], [0.75, 0.75, 0.3], [0.25, 0.75, 0.3]])
GAP = 0.05  # the high plane's height above the low plane
W = 24


def lid():
    return Mesh(LID, QUAD, name="lid")


def high_plane(z=GAP, flip=False, name="high"):
    """A plane larger than the low-poly's, at height z (UVs not needed)."""
    return plane(-0.5, -0.5, 1.5, 1.5, z=z, uv=False, flip=flip, name=name)


def ao_at(p):
    """Exact AO at points of the high plane (given at z = 0): 1 - F from z = GAP."""
    return 1.0 - polygon_form_factor(p + [0.0, 0.0, GAP], LID)


@pytest.fixture(scope="module")
def truth():
    """Per texel of the low plane projected onto the high plane: the mean exact AO, and its variance
    over the texel's square (what one random sample point's position adds)."""
    mean = texel_mean(ao_at, W, W)
    return mean, texel_mean(lambda p: ao_at(p) ** 2, W, W) - mean * mean


def check_z(r, truth, what=""):
    """z-scores against the exact AO and its exact variance: no bias, the right spread, no texel far
    off, and an honest standard error.

    A texel's estimate has two parts of variance: its n cosine-weighted directions (terms 0 or 1: the
    mean over its points of AO (1 - AO), over n) and the positions of its P sample points (the
    variance of AO over the texel's square, over P), both exact from the analytic field. The baker's
    ``stderr`` estimates the first from the samples (core.highpoly: it does not see the second).
    The far-off check uses each texel's Agresti-Coull interval (core.engine.estimators) widened by the
    positions' part, at the Sidak level over all texels. The bakes it checks take one replicate: with
    two or more, ``stderr`` is the replicates' spread and holds both parts
    (test_the_error_map_holds_both_parts_with_replicates).
    """
    assert r.metadata["replicates"] == 1
    mean, var = truth
    points = r.samples / r.report["directions_per_point"]
    directions = (mean - mean * mean - var) / r.samples
    err = r.ao - mean
    z = err / np.sqrt(directions + var / points)
    m = z.size
    assert abs(z.mean()) < 4 / math.sqrt(m), (what, z.mean())
    assert 0.8 < z.var() < 1.25, (what, z.var())
    # The sample stderr against the exact directional part: each texel's relative error is at most
    # about 20% at n = 256, averaged over m texels a few tenths of a percent.
    assert abs(np.mean(r.stderr.astype(float) ** 2) / np.mean(directions) - 1) < 0.05, what
    crit = normal_quantile(1 - 0.01 / (2 * m))
    half = interval_half_width(r.samples.astype(float), r.ao.astype(float), None, crit, binary=True, bound=1.0)
    half = np.sqrt(half ** 2 + crit ** 2 * var / points)
    assert np.all(np.abs(err) < half), (what, np.abs(err / half).max())


# -- analytic ------------------------------------------------------------------------------------------

@pytest.mark.parametrize("distribution", ["cosine", "uniform"])
def test_high_plane_under_a_polygon_matches_lamberts_formula_at_the_projected_points(truth, distribution):
    r = bake_ao(plane(name="low"), [lid()], resolution=W, samples=256, source="independent", margin=0, seed=3,
                distribution=distribution, highpoly=[high_plane()], extrusion=0.1, replicates=1)
    assert r.mask.all() and not r.miss.any() and r.missed == 0
    if distribution == "cosine":
        check_z(r, truth)
    else:  # uniform terms are not 0/1: the sample variance's z-scores, as test_bake does
        mean, var = truth
        z = (r.ao - mean) / np.sqrt(r.stderr ** 2 + var / (r.samples / r.report["directions_per_point"]))
        assert abs(z.mean()) < 4 / math.sqrt(z.size) and 0.8 < z.var() < 1.25, (z.mean(), z.var())
    # The AO of the low plane itself (the lid 0.05 farther away, so lighter) is measurably different:
    # the test can tell the two points apart.
    own = texel_mean(lambda p: 1.0 - polygon_form_factor(p, LID), W, W)
    assert np.mean((r.ao - own) / r.stderr) < -5 / math.sqrt(W * W)


@pytest.mark.parametrize("low_z, extrusion", [(0.1, 0.0), (GAP, 0.0), (0.0, 0.1), (-0.1, 0.2)])
def test_the_low_plane_above_at_or_below_the_high_surface_bakes_the_same(truth, low_z, extrusion):
    # As in Cycles: the low-poly never occludes, and with an extrusion larger than the gap below the
    # high surface the matching rays find the same points, so the bakes are bit-identical.
    base = bake_ao(plane(name="low"), [lid()], resolution=W, samples=256, margin=0, seed=1,
                   highpoly=[high_plane()], extrusion=0.1)
    r = bake_ao(plane(z=low_z, name="low"), [lid()], resolution=W, samples=256, margin=0, seed=1,
                highpoly=[high_plane()], extrusion=extrusion)
    assert r.missed == 0 and r.mask.all()
    assert np.array_equal(r.ao, base.ao)
    check_z(bake_ao(plane(z=low_z, name="low"), [lid()], resolution=W, samples=256, margin=0, seed=1,
                    source="independent", highpoly=[high_plane()], extrusion=extrusion, replicates=1), truth,
            (low_z, extrusion))


def test_the_low_poly_and_the_cage_never_occlude_even_among_the_occluders(truth):
    low = plane(z=0.1, name="low")      # above the high plane: it would hide the lid
    cage = plane(z=0.2, name="cage")
    r = bake_ao(low, [lid(), low, cage], resolution=W, samples=256, margin=0, seed=2, source="independent",
                highpoly=[high_plane()], cage=cage, replicates=1)
    check_z(r, truth)


def test_extrusion_and_a_cage_of_the_extruded_low_poly_give_identical_bakes():
    # A flat-shaded low-poly (each face with its own vertices, so each moves along its own normal):
    # a tent of two tilted faces over a bumpy high-poly. The cage is the low-poly with every vertex
    # moved by the extrusion along its face's normal: the matching rays are the same rays.
    P = np.array([[0, 0, 0], [1, 0, 0.3], [1, 1, 0.3], [0, 0, 0], [1, 1, 0.3], [0, 1, 0]], float)
    F = np.array([[0, 1, 2], [3, 4, 5]])
    uv = P[F][:, :, :2]
    low = Mesh(P, F, uvs=uv, name="low")
    e = 0.15
    cage = Mesh(P + e * np.repeat(low.face_normals, 3, axis=0), F, name="cage")
    rng = np.random.default_rng(0)
    n = 12
    t = np.linspace(-0.2, 1.2, n + 1)
    X, Y = np.meshgrid(t, t)
    Z = 0.3 * X * (X < Y) + 0.3 * Y * (X >= Y) + 0.03 * rng.standard_normal(X.shape)  # the tent, bumpy
    HP = np.stack([X.ravel(), Y.ravel(), Z.ravel() - 0.02], axis=1)
    i = np.arange(n)
    a = (i[None, :] + (n + 1) * i[:, None]).ravel()
    HF = np.concatenate([np.stack([a, a + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + n + 1], 1)])
    high = Mesh(HP, HF, name="high")
    kw = dict(resolution=32, samples=128, margin=0, seed=4, highpoly=[high], max_distance=0.4)
    ex = bake_ao(low, [lid()], extrusion=e, **kw)
    for extrusion in (0.0, 0.7):  # the extrusion is not used with a cage
        cg = bake_ao(low, [lid()], cage=cage, extrusion=extrusion, **kw)
        assert ex.missed == cg.missed == 0
        assert np.array_equal(ex.ao, cg.ao) and np.array_equal(ex.mask, cg.mask)
    assert 0.2 < ex.ao[ex.mask].min() < 0.9  # the bumps occlude: the identity is not that of open planes
    # The rays matter: a cage moved sideways sends them elsewhere.
    moved = Mesh(cage.positions + [0.1, 0.0, 0.0], F, name="cage")
    assert not np.array_equal(bake_ao(low, [lid()], cage=moved, **kw).ao, ex.ao)


def test_shading_normals_of_the_high_poly_are_its_own():
    # A high plane whose corner normals lean by alpha: with nothing around, AO = (1 + cos alpha) / 2
    # (directions below the face count as occluded, test_kernel). The low-poly's own normals (+z,
    # flat) would give 1: the AO is taken about the high-poly's interpolated normal.
    alpha = math.radians(40)
    n = np.array([math.sin(alpha), 0.0, math.cos(alpha)])
    h = high_plane()
    lean = Mesh(h.positions, h.triangles, normals=np.broadcast_to(n, (2, 3, 3)), name="lean")
    r = bake_ao(plane(name="low"), resolution=16, samples=256, margin=0, seed=4, source="independent",
                highpoly=[lean], extrusion=0.1)
    exact = (1 + math.cos(alpha)) / 2
    z = (r.ao - exact) / r.stderr
    assert abs(z.mean()) < 4 / math.sqrt(z.size) and 0.75 < z.var() < 1.3, (r.ao.mean(), exact, z.var())


def test_a_high_poly_with_flipped_normals_gets_the_ao_of_its_other_side(truth):
    # Cycles shades the hit about the high-poly's own normal, whatever side the matching ray came
    # from (back faces are matched). Flipped, the high plane faces down: the AO of its underside,
    # under the lid mirrored below it, is Lambert's value again, and the lid above no longer matters.
    below = Mesh(LID * [1, 1, -1] + [0, 0, 2 * GAP], QUAD, name="lid below")
    kw = dict(resolution=W, samples=256, margin=0, seed=6, source="independent", extrusion=0.1, replicates=1)
    r = bake_ao(plane(name="low"), [lid(), below], highpoly=[high_plane(flip=True)], **kw)
    assert r.missed == 0
    check_z(r, truth)
    up = bake_ao(plane(name="low"), [below], highpoly=[high_plane()], **kw)
    assert np.all(up.ao == 1.0)


def test_several_high_poly_meshes_are_one_surface_and_the_nearest_hit_wins(truth):
    # Two halves of the high plane bake like the whole; a second plane below the first (farther from
    # the ray's origin) is never matched, and occludes nothing above the first.
    left = plane(-0.5, -0.5, 0.5, 1.5, z=GAP, uv=False, name="left")
    right = plane(0.5, -0.5, 1.5, 1.5, z=GAP, uv=False, name="right")
    kw = dict(resolution=W, samples=256, margin=0, seed=5, source="independent", extrusion=0.1, replicates=1)
    whole = bake_ao(plane(name="low"), [lid()], highpoly=[high_plane()], **kw)
    halves = bake_ao(plane(name="low"), [lid()], highpoly=[left, right], **kw)
    check_z(halves, truth)
    assert np.mean(halves.ao == whole.ao) > 0.95  # the same rays, but for the column at the seam
    stacked = bake_ao(plane(name="low"), [lid()], highpoly=[high_plane(z=0.02, name="under"), high_plane()], **kw)
    assert np.array_equal(stacked.ao, whole.ao)


def test_max_ray_distance_is_measured_from_the_extruded_point():
    # Low 0.1 above the high plane, extrusion 0.2: the rays start 0.3 above it (Cycles: 0.2 misses,
    # 0.35 hits).
    kw = dict(resolution=8, samples=64, margin=0, highpoly=[high_plane()], extrusion=0.2)
    hit = bake_ao(plane(z=GAP + 0.1, name="low"), max_ray_distance=0.35, **kw)
    assert hit.missed == 0 and hit.mask.all()
    with pytest.raises(MeshError, match=r"beyond the max ray distance 0\.2; raise the max ray distance above 0\.3,"):
        bake_ao(plane(z=GAP + 0.1, name="low"), max_ray_distance=0.2, **kw)


# -- misses ----------------------------------------------------------------------------------------------

def test_points_that_miss_are_counted_and_their_texels_left_to_the_margin():
    # The high plane covers x < 0.5 of the low plane exactly on a texel boundary: the texels of the
    # other half miss entirely (uncovered, in the miss mask, filled by the margin near the edge), and
    # every one of their points is counted.
    half = plane(-0.5, -0.5, 0.5, 1.5, z=GAP, uv=False, name="half")
    samples = 256
    r = bake_ao(plane(name="low"), [lid()], resolution=16, samples=samples, margin=0, highpoly=[half], extrusion=0.1)
    points = samples // directions_per_point(samples, 16, False)
    assert np.array_equal(r.mask[:, :8], np.ones((16, 8), bool)) and not r.mask[:, 8:].any()
    assert np.array_equal(r.miss, ~r.mask)
    assert r.missed == 16 * 8 * points == r.report["missed_matching_rays"]
    assert r.report["missed_texels"] == 128 and r.report["partly_missed_texels"] == 0
    assert r.report["matching_rays"] == 16 * 16 * points
    assert np.all(r.ao[:, 8:] == 0) and np.all(r.samples[:, 8:] == 0)
    m = bake_ao(plane(name="low"), [lid()], resolution=16, samples=samples, margin=3, highpoly=[half],
                extrusion=0.1)
    assert np.array_equal(m.ao[:, :8], r.ao[:, :8])
    assert np.all(m.ao[:, 8:11] > 0) and np.all(m.ao[:, 11:] == 0)


def test_a_texel_that_matches_in_part_averages_the_part_it_found():
    # The high plane ends a quarter into a column of texels: those texels keep the points that hit
    # (about a quarter), and their value is the mean over them alone.
    edge = 8.25 / 16
    part = plane(-0.5, -0.5, edge, 1.5, z=GAP, uv=False, name="part")
    samples = 1024
    r = bake_ao(plane(name="low"), resolution=16, samples=samples, margin=0, highpoly=[part], extrusion=0.1)
    g = directions_per_point(samples, 16, False)
    assert r.mask[:, 8].all() and not r.mask[:, 9:].any()
    assert r.report["partly_missed_texels"] == 16
    assert np.all(r.ao[:, 8] == 1.0)  # open: the mean of what was found, not diluted by the misses
    share = r.samples[:, 8] / samples
    assert np.all(r.samples[:, 8] % g == 0) and abs(share.mean() - 0.25) < 4 * math.sqrt(0.25 * 0.75 / (16 * samples / g))


# -- the error map and adaptive sampling (replicates) ------------------------------------------------------

NEAR_LID = regular_polygon(0.3, GAP + 0.05, 64, centre=(0.5, 0.5))  # 0.05 above the high plane
NEAR_W = 32


def near_lid():
    return Mesh(NEAR_LID, np.array([[0, i, i + 1] for i in range(1, 63)]), name="lid")


@pytest.fixture(scope="module")
def near_truth():
    """The exact texel AO of the high plane under the near lid, and its variance over each texel."""
    f = lambda p: 1.0 - polygon_form_factor(p + [0.0, 0.0, GAP], NEAR_LID)  # noqa: E731
    mean = texel_mean(f, NEAR_W, NEAR_W, order=8)
    return mean, texel_mean(lambda p: f(p) ** 2, NEAR_W, NEAR_W, order=8) - mean * mean


@pytest.mark.parametrize("source", ["independent", "sobol"])
@pytest.mark.parametrize("samples", [64, 256])
def test_the_error_map_holds_both_parts_with_replicates(near_truth, source, samples):
    # Each replicate draws its own sample points (positions and directions), so the spread of the
    # replicates holds the positions' part of the error too, which the spread of a texel's samples
    # cannot show (its points' blocks of directions share a position: not independent samples, even
    # from the independent source). A lid 0.05 above the high plane makes the AO change within a
    # texel: the positions' part is 20-50% of the error here.
    mean, var = near_truth
    z, err2, se2 = [], 0.0, 0.0
    for seed in range(4):
        r = bake_ao(plane(name="low"), [near_lid()], resolution=NEAR_W, samples=samples, source=source, margin=0,
                    seed=seed, highpoly=[high_plane()], extrusion=0.1, replicates=2, threads=2)
        assert r.mask.all() and r.metadata["error_estimate"] == "replicates"
        points = samples / r.report["directions_per_point"]
        # Texels whose whole window saw only open samples have no error estimate (core.engine.estimators):
        # nearly open ones only.
        assert np.all(mean[r.stderr == 0] > 0.98)
        some = r.stderr > 0
        z.append((r.ao - mean)[some] / r.stderr[some])
        err2 += np.mean((r.ao - mean)[some] ** 2)
        se2 += np.mean(r.stderr[some].astype(float) ** 2)
    directions = (mean - mean * mean - var) / samples
    assert np.mean(var / points) / np.mean(var / points + directions) > 0.2  # the positions' part matters
    z = np.concatenate(z)
    # As the error map's own test (test_estimators): over about 4000 values the z-scores' standard
    # deviation and mean carry about 0.02-0.04 of noise; the mean squared error against the mean
    # squared stderr, about 0.05 each.
    assert 0.85 <= z.std() <= 1.15 and abs(z.mean()) < 0.1, (z.std(), z.mean())
    assert 0.8 < err2 / se2 < 1.25, err2 / se2


def test_adaptive_sampling_keeps_its_promise_on_the_high_poly_and_leaves_misses_out(near_truth):
    # Adaptive rounds (replicates' intervals) over the high plane under the near lid, which covers only
    # x < 0.75 of the low plane (on a texel boundary): at most 5% of the covered texels end farther
    # than the target from the exact AO, the open ones stop early, and the texels that missed take
    # no rounds after the first, no error and no samples.
    mean, _ = near_truth
    part = plane(-0.5, -0.5, 0.75, 1.5, z=GAP, uv=False, name="part")
    target, cap = 0.02, 4096
    far, counts = [], []
    for seed in range(2):
        r = bake_ao(plane(name="low"), [near_lid()], resolution=NEAR_W, samples=cap, min_samples=16,
                    target_error=target, margin=0, seed=seed, highpoly=[part], extrusion=0.1, threads=2)
        g = r.report["directions_per_point"]
        assert r.metadata["replicates"] == 2 and g == 8  # the first round: 8 samples per replicate
        covered = np.zeros((NEAR_W, NEAR_W), bool)
        covered[:, :24] = True
        assert np.array_equal(r.mask, covered) and np.array_equal(r.miss, ~covered)
        assert np.all(r.stderr[~covered] == 0) and np.all(r.samples[~covered] == 0) and np.all(r.ao[~covered] == 0)
        # The missed texels cast their first round's points only: 2 replicates x 1 point.
        assert r.missed == r.report["missed_matching_rays"] == (~covered).sum() * 2
        assert np.all(r.samples[covered] % g == 0) and np.all(r.samples[covered] >= 16)
        far.append(np.mean(np.abs(r.ao - mean)[covered] > target))
        counts.append(r.samples[covered])
    m = 2 * covered.sum()
    assert np.mean(far) <= 0.05 + 3 * math.sqrt(0.05 * 0.95 / m), far
    counts = np.concatenate(counts)
    assert np.mean(counts == 16) > 0.05 and counts.max() > 256 and np.mean(counts == cap) < 0.01


def test_a_texel_with_a_replicate_that_missed_borrows_its_error_and_lends_none():
    # A texel of which every point of one replicate missed the high-poly surface has no spread of its
    # own: it takes its neighbours' pooled variance and gives them nothing (were its zero counted with
    # a degree of freedom, its neighbours' error would shrink).
    from types import SimpleNamespace

    from core.engine.estimators import ErrorModel, TexelEstimates

    side = 16
    x, y = np.meshgrid(np.arange(side), np.arange(side))
    x, y = x.ravel(), y.ravel()
    est = TexelEstimates(side * side, 2)
    rows = np.arange(side * side)
    n = np.full(side * side, 8)
    est.add(rows, n, n * 0.4, n * 0.4, 0)   # replicate means 0.4 and 0.6: variance 0.01 everywhere
    lost = 5 * side + 7
    est.add(rows[rows != lost], n[:-1], n[:-1] * 0.6, n[:-1] * 0.6, 1)
    model = ErrorModel(SimpleNamespace(replicates=2, source="sobol", binary=False, bound=1.0), grouped=True)
    var, dof = model.variance(est, x, y)
    assert est.rn[1, lost] == 0 and dof[lost] == 24
    assert np.allclose(var[rows != lost], 0.01) and var[lost] > 0


def test_a_high_poly_over_a_small_part_of_the_low_poly_is_found():
    # The check before baking casts rays from PRECHECK_POINTS points spread by area; a high-poly
    # matching one texel of a 256 x 256 bake (1/65536 of the surface) is found by the scan of every
    # texel that follows when they all miss, and baked.
    tiny = plane(0.5 + 1 / 1024, 0.5 + 1 / 1024, 0.5 + 3 / 1024, 0.5 + 3 / 1024, z=GAP, uv=False, name="tiny")
    assert PRECHECK_POINTS / 512 ** 2 < 0.2  # the points expected on it
    r = bake_ao(plane(name="low"), resolution=256, samples=16, margin=0, highpoly=[tiny], extrusion=0.1)
    assert r.mask.sum() == 1 and r.mask[128, 128]


@pytest.mark.parametrize("case, message", [
    ("below", r"lies outside 'low', up to 0\.1 above it along its normals, farther than the extrusion \(0\) "
              r"pushes the rays out; raise the extrusion above 0\.1"),
    ("short", r"beyond the max ray distance 0\.01; raise the max ray distance above 0\.1"),
    ("elsewhere", r"no high-poly surface lies along 'low''s normals at all"),
    ("cage_on_low", r"the cage 'cage' lies on 'low' itself; move its vertices outwards"),
    ("cage_inside", r"lies outside the cage 'cage'.*enlarge the cage"),
])
def test_every_ray_missing_is_refused_before_baking_saying_what_to_change(case, message):
    low = plane(name="low")
    kw = dict(highpoly=[high_plane(z=0.1)], extrusion=0.0)
    if case == "short":
        kw.update(extrusion=0.2, max_ray_distance=0.01)
    elif case == "elsewhere":
        kw.update(highpoly=[plane(5, 5, 6, 6, z=0.0, uv=False, name="high")], extrusion=0.5)
    elif case == "cage_on_low":
        kw.update(cage=plane(name="cage"))
    elif case == "cage_inside":
        kw.update(cage=plane(z=0.05, name="cage"))
    rays = []
    with pytest.raises(MeshError, match=r"no matching ray from 'low' found the high-poly surface of 'high'.*" + message):
        bake_ao(low, resolution=16, samples=16, on_rays=rays.append, **kw)
    assert not rays  # not one AO ray was traced


# -- bad input ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("kw, error, message", [
    (dict(extrusion=-0.1), SettingsError, r"the extrusion must be a distance >= 0, got -0\.1"),
    (dict(extrusion=float("nan")), SettingsError, r"the extrusion must be a distance >= 0, got nan"),
    (dict(extrusion=float("inf")), SettingsError, r"the extrusion must be a finite distance"),
    (dict(extrusion="far"), SettingsError, r"the extrusion must be a number, got 'far'"),
    (dict(max_ray_distance=-1.0), SettingsError, r"the max ray distance \(0 = no limit\) must be a distance >= 0"),
    (dict(max_ray_distance=float("nan")), SettingsError, r"max ray distance .* got nan"),
    (dict(highpoly=[]), SettingsError, r"at least one high-poly mesh to bake onto 'low'"),
    (dict(highpoly="high"), SettingsError, r"high-poly meshes must be core.Mesh objects, got str"),
    (dict(highpoly=5), SettingsError, r"highpoly must be a core.Mesh or a list of them, got int"),
    (dict(cage="cage"), SettingsError, r"the cage must be a core.Mesh, got str"),
    (dict(bent_normals=True), SettingsError, r"bent normals are not baked with selected to active"),
])
def test_bad_settings_are_refused_by_name(kw, error, message):
    args = dict(highpoly=[high_plane()], extrusion=0.1)
    args.update(kw)
    with pytest.raises(error, match=message):
        bake_ao(plane(name="low"), resolution=8, samples=4, **args)


def test_a_high_poly_mesh_too_far_for_single_precision_is_refused_by_name():
    far = plane(1e16, 0, 1e16 + 1, 1, uv=False, name="far away")
    with pytest.raises(MeshError, match=r"high-poly mesh 'far away' reaches 1e\+16 times the size of 'low' away"):
        bake_ao(plane(name="low"), resolution=8, samples=4, highpoly=[high_plane(), far])


def test_the_target_cannot_be_its_own_high_poly_nor_its_own_cage():
    low = plane(name="low")
    with pytest.raises(SettingsError, match=r"'low' is the low-poly target and cannot also be a high-poly mesh"):
        bake_ao(low, resolution=8, samples=4, highpoly=[high_plane(), low])
    with pytest.raises(SettingsError, match=r"the cage 'low' is the low-poly target itself"):
        bake_ao(low, resolution=8, samples=4, highpoly=[high_plane()], cage=low)


def test_a_cage_of_another_topology_is_refused_naming_both():
    low = plane(name="Chair_low")
    four = Mesh(np.array([[0, 0, 0.1], [1, 0, 0.1], [1, 1, 0.1], [0, 1, 0.1], [0.5, 0.5, 0.1]], float),
                np.array([[0, 1, 4], [1, 2, 4], [2, 3, 4], [3, 0, 4]]), name="Chair_cage")
    other = Mesh(low.positions + [0, 0, 0.1], low.triangles[:, ::-1], name="Chair_cage")  # same counts, other triangles
    for cage, counts in ((four, "5 vertices and 4 triangles against 4 and 2"),
                         (other, "4 vertices and 2 triangles against 4 and 2")):
        with pytest.raises(MeshError, match=(r"the cage 'Chair_cage' does not have the topology of the low-poly "
                                             r"'Chair_low' \(" + counts + r", or other triangles\): a cage must be a "
                                             r"copy of 'Chair_low' with only its vertices moved")):
            bake_ao(low, resolution=8, samples=4, highpoly=[high_plane()], cage=cage)


# -- what is traced ------------------------------------------------------------------------------------------

def record(low, **kw):
    batches = []

    def keep(b):
        batches.append({k: np.array(getattr(b, k)) for k in ("origins", "directions", "tfar", "occluded",
                                                              "texels", "samples")})
        batches[-1]["replicate"] = np.full(len(b.texels), b.replicate)

    r = bake_ao(low, threads=1, margin=0, on_rays=keep, **kw)
    return {k: np.concatenate([b[k] for b in batches]) for k in batches[0]}, r


def test_every_sample_of_a_texel_is_traced_once_from_its_points_on_the_high_surface():
    samples = 256
    g = directions_per_point(samples, 16, False)
    assert g == DIRECTIONS_PER_POINT
    rays, r = record(plane(name="low"), resolution=16, samples=samples, highpoly=[high_plane()], extrusion=0.1)
    # Each replicate (two by default) traces its own half of the samples, indices 0 .. samples / 2 - 1.
    assert r.metadata["replicates"] == 2 and set(np.unique(rays["replicate"])) == {0, 1}
    assert rays["samples"].max() == samples // 2 - 1
    key = (rays["texels"] * 2 + rays["replicate"]) * samples + rays["samples"]
    assert np.unique(key).size == key.size == 16 * 16 * samples == r.rays - r.report["matching_rays"]
    # In the baker's frame (centred on the low plane, unit size) the high plane lies at z = GAP:
    # every AO ray leaves from it (pushed off by a hair), the points of a block share their origin,
    # and each texel's points lie inside its square.
    z = rays["origins"][:, 2]
    assert np.all(z > GAP) and np.all(z < GAP + 1e-5)
    org = rays["origins"].reshape(-1, g, 3)
    assert np.all(org == org[:, :1])
    x = (org[:, 0, 0] + 0.5) * 16
    col = rays["texels"].reshape(-1, g)[:, 0] % 16
    assert np.all((x >= col - 1e-4) & (x <= col + 1 + 1e-4))
    assert np.all(rays["samples"].reshape(-1, g) // g == rays["samples"].reshape(-1, g)[:, :1] // g)


CHI2_ALPHA = sidak(SUITE_ALPHA, 64)


@pytest.mark.parametrize("distribution", ["cosine", "uniform"])
def test_directions_follow_their_pdf_about_the_high_polys_normal(distribution):
    # A tilted high plane (normal 30 degrees from the low's +z): every AO direction, in the frame of
    # the high plane's normal, against cos(theta)/pi or 1/(2 pi); read about the low-poly's normal,
    # the same directions fail (the harness can tell).
    tilt = math.radians(30)
    n = np.array([0.0, -math.sin(tilt), math.cos(tilt)])
    h = high_plane()
    P = h.positions.copy()
    P[:, 2] = GAP + (P[:, 1] - 0.5) * math.tan(tilt)
    high = Mesh(P, h.triangles, name="tilted")
    assert np.allclose(high.face_normals, n)
    rays, r = record(plane(name="low"), resolution=32, samples=64, highpoly=[high], extrusion=0.5,
                     distribution=distribution, seed=9)
    assert r.missed == 0
    d = rays["directions"].astype(np.float64)
    d /= np.linalg.norm(d, axis=1, keepdims=True)

    def p_value(normal):
        nn = np.broadcast_to(normal, d.shape)
        local = np.stack([np.einsum("ij,ij->i", d, s) for s in warps.orthonormal_basis(nn)]
                         + [np.einsum("ij,ij->i", d, nn)], 1)
        keep = local[:, 2] > 0
        pdf = warps.cosine_hemisphere_pdf if distribution == "cosine" else warps.uniform_hemisphere_pdf

        class Drawn:
            domain, dim, points = "hemisphere", 3, local[keep]

            def __init__(self):
                self.pdf = pdf

            def draw(self, count, rng):
                return self.points[:count]

        return chi2_test(Drawn(), int(keep.sum()), None)[0]

    assert p_value(n) > CHI2_ALPHA
    assert p_value(np.array([0.0, 0.0, 1.0])) < CHI2_ALPHA


# -- determinism, cancellation, progress ---------------------------------------------------------------------

def bumpy_scene():
    """A low-poly whose triangles are smaller than texels (split texels everywhere) under two bumpy
    high-poly pieces that touch, a hovering occluder, and a block resting on the high-poly."""
    n = 6
    t = np.linspace(0.0, 1.0, n + 1)
    X, Y = np.meshgrid(t, t)
    P = np.stack([X.ravel(), Y.ravel(), 0.02 * np.sin(5 * X.ravel())], axis=1)
    i = np.arange(n)
    a = (i[None, :] + (n + 1) * i[:, None]).ravel()
    F = np.concatenate([np.stack([a, a + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + n + 1], 1)])
    rng = np.random.default_rng(1)
    vn = np.concatenate([rng.uniform(-0.2, 0.2, (len(P), 2)), np.ones((len(P), 1))], axis=1)
    low = Mesh(P, F, uvs=P[F][:, :, :2], normals=vn[F], name="low")
    m = 20
    s = np.linspace(-0.2, 1.2, m + 1)
    HX, HY = np.meshgrid(s, s)
    HZ = GAP + 0.04 * np.sin(9 * HX) * np.cos(7 * HY)
    HP = np.stack([HX.ravel(), HY.ravel(), HZ.ravel()], axis=1)
    j = np.arange(m)
    b = (j[None, :] + (m + 1) * j[:, None]).ravel()
    HF = np.concatenate([np.stack([b, b + 1, b + m + 2], 1), np.stack([b, b + m + 2, b + m + 1], 1)])
    left = HF[(HP[HF][:, :, 0].mean(axis=1) < 0.5)]
    right = HF[(HP[HF][:, :, 0].mean(axis=1) >= 0.5)]
    highs = [Mesh(HP, left, name="left"), Mesh(HP, right, name="right")]
    block = Mesh(np.array([[x, y, z] for z in (0.0, 0.25) for y in (0.3, 0.5) for x in (0.3, 0.45)], float),
                 np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
                           [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]]), name="block")
    return low, highs, [lid(), block]


@pytest.mark.parametrize("kw", [dict(), dict(distribution="uniform", source="halton"),
                                dict(falloff=1.0, ignore_backfaces=True, source="stratified"),
                                dict(samples=256, min_samples=32, target_error=0.05)])
def test_bakes_are_bit_identical_for_any_threads_tiles_and_chunks(kw):
    low, highs, occluders = bumpy_scene()
    args = dict(resolution=24, samples=64, max_distance=0.6, margin=0, seed=8, highpoly=highs, extrusion=0.12)
    args.update(kw)
    a = bake_ao(low, occluders, threads=1, **args)
    b = bake_ao(low, occluders, threads=2, tile_size=8, chunk_rays=333, **args)
    assert a.missed == b.missed
    for name in ("ao", "stderr", "samples", "mask", "miss"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    c = bake_ao(low, occluders, threads=2, **dict(args, seed=9))
    assert not np.array_equal(a.ao, c.ao)


def test_a_block_resting_on_the_high_poly_occludes_it_completely():
    # Contact (as core.tracing.tracer.Tracer for the target): a block standing on the high plane, taller
    # than the AO distance, darkens the points under it completely, in Cycles as here.
    block = Mesh(np.array([[x, y, z] for z in (GAP, GAP + 0.6) for y in (0.3, 0.7) for x in (0.3, 0.7)], float),
                 np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
                           [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]]), name="block")
    kw = dict(resolution=32, samples=64, max_distance=0.5, margin=0, extrusion=0.1)
    for highs, occluders in (([high_plane()], [block]), ([high_plane(), block], [])):
        r = bake_ao(plane(name="low"), occluders, highpoly=highs, **kw)
        assert np.all(r.ao[11:20, 11:20] == 0.0)
        assert r.ao[:8].mean() > 0.8


def test_cancel_raises_and_progress_runs_to_one():
    low, highs, occluders = bumpy_scene()
    ev = threading.Event()
    with pytest.raises(BakeCancelled):
        bake_ao(low, occluders, resolution=32, samples=64, highpoly=highs, extrusion=0.12,
                progress=lambda f: ev.set(), cancel=ev, chunk_rays=512)
    with pytest.raises(BakeCancelled):
        bake_ao(low, resolution=8, samples=4, highpoly=highs, extrusion=0.12, cancel=lambda: True)
    seen = []
    bake_ao(low, occluders, resolution=32, samples=64, highpoly=highs, extrusion=0.12, progress=seen.append,
            chunk_rays=512, tile_size=8)
    assert len(seen) > 8 and seen[-1] == 1.0 and all(b >= a for a, b in zip(seen, seen[1:]))


def test_directions_per_point():
    assert directions_per_point(64, 16, False) == DIRECTIONS_PER_POINT == 64
    assert directions_per_point(256, 16, True) == 16
    assert directions_per_point(100, 16, False) == 4
    assert directions_per_point(1, 1, False) == 1
    # Replicates: whole points in each replicate's share of the samples and of the first round.
    assert directions_per_point(64, 16, False, 2) == 32
    assert directions_per_point(256, 16, True, 2) == 8
    assert directions_per_point(65, 16, False, 2) == 1      # shares 33 and 32
    assert directions_per_point(1024, 48, True, 4) == 4     # first round 12 per replicate


def test_the_result_records_the_settings():
    r = bake_ao(plane(name="low"), resolution=8, samples=64, highpoly=[high_plane()], extrusion=0.1)
    assert r.metadata["selected_to_active"] is True and r.metadata["highpoly"] == "high"
    assert r.metadata["extrusion"] == 0.1 and r.metadata["max_ray_distance"] == 0.0
    assert r.metadata["replicates"] == 2 and r.report["directions_per_point"] == 32
    assert bake_ao(plane(name="low"), resolution=8, samples=64, highpoly=[high_plane()], extrusion=0.1,
                   replicates=1).report["directions_per_point"] == 64
    plain = bake_ao(plane(name="low"), resolution=8, samples=4)
    assert plain.miss is None and plain.missed == 0 and "selected_to_active" not in plain.metadata


def test_the_high_poly_bake_goes_through_the_scheduler_and_the_one_kernel(monkeypatch):
    """Every chunk of a selected-to-active tile is handed to the scheduler (so idle threads take
    chunks of the last tiles) and every AO ray is traced by the one kernel."""
    from core.engine import kernel, scheduler

    shared_out, kernel_rays = [], []
    run_chunks, run = scheduler.Scheduler.run_chunks, kernel.Kernel.run

    def counting_chunks(self, chunks, compute, commit):
        shared_out.append(len(chunks))
        return run_chunks(self, chunks, compute, commit)

    def counting_run(self, *args, **kw):
        out = run(self, *args, **kw)
        kernel_rays.append(out[2])
        return out

    monkeypatch.setattr(scheduler.Scheduler, "run_chunks", counting_chunks)
    monkeypatch.setattr(kernel.Kernel, "run", counting_run)
    low, highs, occluders = bumpy_scene()
    r = bake_ao(low, occluders, resolution=16, samples=64, max_distance=0.6, margin=0, highpoly=highs,
                extrusion=0.12, threads=2, chunk_rays=512, replicates=1)
    assert max(shared_out) > 1
    assert sum(kernel_rays) == r.rays - r.report["matching_rays"] and sum(kernel_rays) > 0
