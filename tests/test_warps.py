"""Every sampler of core.montecarlo.warps.REGISTRY against its pdf: chi-square fit, normalisation, inversion,
acceptance rates of the rejection samplers, and the frames that orient hemispheres."""

import math

import numpy as np
import pytest

from core import warps
from core.montecarlo.stats import normal_quantile
from chi2 import SUITE_ALPHA, chi2_test, expected_fractions, sidak

NAMES = sorted(warps.REGISTRY)
REJECTION = [n for n in NAMES if warps.REGISTRY[n].rejection is not None]
INVERTIBLE = [n for n in NAMES if warps.REGISTRY[n].inverse is not None]
# The suite's statistical tests of samplers: one chi-square per sampler, one binomial per rejection sampler.
ALPHA = sidak(SUITE_ALPHA, len(NAMES) + len(REJECTION))


def test_registry_holds_every_sampler_of_the_lecture_and_issue():
    expected = {"linear_ramp", "piecewise_constant_1d", "piecewise_constant_2d", "disk_polar",
                "disk_concentric", "disk_rejection", "sphere_uniform", "sphere_rejection",
                "hemisphere_uniform", "hemisphere_cosine", "hemisphere_rejection_z",
                "hemisphere_rejection_normal", "hemisphere_rejection_flip", "triangle_heitz",
                "hemisphere_cosine_polar", "hemisphere_cosine_sphere", "hemisphere_uniform_flip"}
    assert expected <= set(NAMES)
    for s in warps.REGISTRY.values():
        assert s.domain in {"interval", "square", "disk", "sphere", "hemisphere", "triangle"}


@pytest.mark.slow
@pytest.mark.parametrize("name", NAMES)
def test_chi_square_goodness_of_fit(name):
    sampler = warps.REGISTRY[name]
    rng = np.random.default_rng([NAMES.index(name), 20261123])
    p, msg = chi2_test(sampler, 1_000_000, rng)
    assert p > ALPHA, f"{name}: p = {p:.3g} <= {ALPHA:.3g} ({msg})"


class _Perturbed:
    """A sampler whose draws are subtly wrong, to show the harness can fail."""

    def __init__(self, base, fn):
        self.__dict__.update(base.__dict__)
        self._base, self._fn = base, fn
        self.pdf = base.pdf

    def draw(self, n, rng):
        return self._fn(self._base.draw(n, rng))


@pytest.mark.parametrize("case", ["ramp_squared_bias", "disk_uniform_radius", "cosine_as_uniform"])
def test_chi_square_rejects_wrong_samplers(case):
    rng = np.random.default_rng(7)
    if case == "ramp_squared_bias":
        s = _Perturbed(warps.REGISTRY["linear_ramp"], lambda y: y ** 1.02)
    elif case == "disk_uniform_radius":  # the classic mistake: r = u instead of sqrt(u)
        s = _Perturbed(warps.REGISTRY["disk_polar"],
                       lambda p: p * np.linalg.norm(p, axis=1, keepdims=True))
    else:
        s = _Perturbed(warps.REGISTRY["hemisphere_uniform"], lambda w: w)
        s.pdf = warps.cosine_hemisphere_pdf
    p, msg = chi2_test(s, 200_000, rng)
    assert p < ALPHA, msg  # the suite would reject it


@pytest.mark.parametrize("name", NAMES)
def test_pdf_integrates_to_one(name):
    sampler = warps.REGISTRY[name]
    from chi2 import default_resolution

    total = expected_fractions(sampler, default_resolution(sampler)).sum()
    assert total == pytest.approx(1.0, abs=1e-9)


@pytest.mark.parametrize("name", NAMES)
def test_pdf_is_zero_outside_the_domain(name):
    s = warps.REGISTRY[name]
    outside = {"interval": np.array([[-0.1], [1.1]]), "square": np.array([[-0.1, 0.5], [0.5, 1.2]]),
               "disk": np.array([[0.9, 0.9], [-1.1, 0.0]])}.get(s.domain)
    if s.domain == "triangle":
        outside = np.array([[-0.1, 0.5], [0.6, 0.6], [0.5, -0.01]])
    if s.domain == "hemisphere":
        n = getattr(s, "normal", np.array([0.0, 0.0, 1.0]))
        outside = np.array([-n, -(n + 0.3 * warps.orthonormal_basis(n)[0]) / np.linalg.norm(n + 0.3)])
    if outside is None:
        pytest.skip("the sphere has no outside among unit directions")
    assert np.all(s.pdf(outside) == 0)


@pytest.mark.parametrize("name", INVERTIBLE)
def test_inverse_of_sample_is_identity_on_a_grid(name):
    s = warps.REGISTRY[name]
    k = 97 if s.u_dim == 1 else 64
    g = (np.arange(k) + 0.5) / k
    u = g[:, None] if s.u_dim == 1 else np.stack(np.meshgrid(g, g, indexing="ij"), -1).reshape(-1, 2)
    np.testing.assert_allclose(s.inverse(s.sample(u)), u, atol=1e-9, rtol=0)


@pytest.mark.parametrize("name", INVERTIBLE)
def test_sample_of_inverse_is_identity_on_samples(name):
    s = warps.REGISTRY[name]
    pts = s.draw(2000, np.random.default_rng(3))
    np.testing.assert_allclose(s.sample(s.inverse(pts)), pts, atol=1e-9, rtol=0)


@pytest.mark.parametrize("name", REJECTION)
def test_rejection_acceptance_rate_matches_the_volume_ratio(name):
    s = warps.REGISTRY[name]
    r = s.rejection
    r.trials = r.accepted = 0
    s.draw(200_000, np.random.default_rng(11))
    p = r.expected_acceptance
    z = normal_quantile(1 - ALPHA / 2)
    tol = z * math.sqrt(p * (1 - p) / r.trials)
    assert r.accepted == 200_000
    assert abs(r.acceptance_rate - p) < tol, (r.acceptance_rate, p, tol)


def test_rejection_acceptance_values_are_the_lecture_shapes():
    rates = {n: warps.REGISTRY[n].rejection.expected_acceptance for n in REJECTION}
    assert rates["disk_rejection"] == pytest.approx(math.pi / 4)
    assert rates["sphere_rejection"] == pytest.approx(math.pi / 6)
    assert rates["hemisphere_rejection_z"] == pytest.approx(math.pi / 12)
    assert rates["hemisphere_rejection_normal"] == pytest.approx(math.pi / 12)
    assert rates["hemisphere_rejection_flip"] == pytest.approx(math.pi / 6)


def _axis_normals():
    eye = np.eye(3)
    return np.concatenate([eye, -eye])


@pytest.mark.parametrize("kind", ["random", "axes", "near_minus_z", "near_equator"])
def test_frames_are_orthonormal_and_right_handed(kind):
    rng = np.random.default_rng(5)
    if kind == "random":
        n = rng.normal(size=(10_000, 3))
    elif kind == "axes":
        n = _axis_normals()
    elif kind == "near_minus_z":
        e = 10.0 ** -np.arange(1, 16)
        n = np.stack([e, e * 0.5, -np.ones_like(e)], axis=1)
    else:
        e = 10.0 ** -np.arange(1, 16)
        n = np.concatenate([np.stack([np.ones_like(e), e, s * e], 1) for s in (1.0, -1.0)])
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    s, t = warps.orthonormal_basis(n)
    dots = lambda a, b: np.einsum("ij,ij->i", a, b)  # noqa: E731
    for a, b, want in [(s, s, 1), (t, t, 1), (s, t, 0), (s, n, 0), (t, n, 0)]:
        np.testing.assert_allclose(dots(a, b), want, atol=1e-12)
    np.testing.assert_allclose(np.cross(s, t), n, atol=1e-12)


def test_frame_is_continuous_around_the_poles():
    # Tilting the normal by 1e-7 off +z or -z moves the tangents by O(1e-7): no singularity there.
    for pole in (1.0, -1.0):
        n0 = np.array([[0.0, 0.0, pole]])
        n1 = np.array([[1e-7, -2e-7, pole]])
        n1 /= np.linalg.norm(n1)
        s0, t0 = warps.orthonormal_basis(n0)
        s1, t1 = warps.orthonormal_basis(n1)
        assert np.abs(s1 - s0).max() < 1e-6 and np.abs(t1 - t0).max() < 1e-6


def test_to_world_and_to_local_are_inverse_rotations():
    rng = np.random.default_rng(9)
    n = rng.normal(size=(500, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    v = rng.normal(size=(500, 3))
    np.testing.assert_allclose(warps.to_local(warps.to_world(v, n), n), v, atol=1e-12)
    np.testing.assert_allclose(warps.to_world(np.array([0.0, 0.0, 1.0]), n), n, atol=1e-15)


def test_piecewise_constant_never_samples_zero_bins():
    pc = warps.PiecewiseConstant1D([0.0, 1.0, 0.0, 3.0])
    x = pc.sample(np.random.default_rng(1).random(100_000))[:, 0]
    bins = np.floor(x * 4).astype(int)
    assert set(np.unique(bins)) == {1, 3}
    assert abs((bins == 3).mean() - 0.75) < 5 * math.sqrt(0.75 * 0.25 / 1e5)


@pytest.mark.parametrize("bad", [[], [1.0, -1.0], [0.0, 0.0], [1.0, np.nan]])
def test_piecewise_constant_rejects_bad_tables(bad):
    with pytest.raises(ValueError):
        warps.PiecewiseConstant1D(bad)


def test_chi_square_rejects_a_triangle_map_that_folds():
    # The naive fold (u0 + u1 > 1 -> 1 - u) is uniform too; a map that squeezes towards corner 0 is not.
    s = _Perturbed(warps.REGISTRY["triangle_heitz"], lambda b: b * (0.9 + 0.1 * (b[:, :1] + b[:, 1:])))
    p, msg = chi2_test(s, 200_000, np.random.default_rng(8))
    assert p < ALPHA, msg


def test_heitz_map_is_the_one_the_baker_uses():
    # square_to_triangle (component form, any scale) against pbrt-v4's branchy form.
    rng = np.random.default_rng(12)
    u = rng.random((10_000, 2))
    first = u[:, 0] < u[:, 1]
    b0 = np.where(first, u[:, 0] / 2, u[:, 0] - u[:, 1] / 2)
    b1 = np.where(first, u[:, 1] - u[:, 0] / 2, u[:, 1] / 2)
    got = warps.square_to_triangle(u[:, 0], u[:, 1])
    np.testing.assert_allclose(got[0], b0, atol=1e-15)
    np.testing.assert_allclose(got[1], b1, atol=1e-15)
    scaled = warps.square_to_triangle(u[:, 0] * 2.0**32, u[:, 1] * 2.0**32)
    np.testing.assert_allclose(scaled[0] * 2.0**-32, b0, atol=1e-12)


def test_cosine_by_the_sphere_equals_the_polar_map():
    # normalize(n + v), v the uniform sphere point of u with its pole along n, is Malley's polar
    # map of the same u: the form the baker uses with per-sample normals gives the same directions.
    rng = np.random.default_rng(13)
    u = rng.random((5000, 2))
    d = warps.sample_cosine_hemisphere_polar(u)
    v = np.stack(warps.cosine_sphere_point(d[:, 0], d[:, 1], d[:, 2]), axis=1)
    np.testing.assert_allclose(v, warps.sample_uniform_sphere(np.stack([u[:, 0], u[:, 1]], 1)), atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(v, axis=1), 1.0, atol=1e-12)
    w = v + np.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(w / np.linalg.norm(w, axis=1, keepdims=True), d, atol=1e-9)


def test_turning_the_frame_shifts_the_azimuth():
    rng = np.random.default_rng(14)
    n = rng.normal(size=(200, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    s, t = warps.orthonormal_basis(n)
    a = rng.random(200) * 2 * np.pi
    s2, t2 = warps.rotate_tangents(s, t, np.cos(a)[:, None], np.sin(a)[:, None])
    u = rng.random((200, 2))
    local = warps.sample_cosine_hemisphere_polar(u)
    d = local[:, :1] * s2 + local[:, 1:2] * t2 + local[:, 2:] * n
    shifted = warps.sample_cosine_hemisphere_polar(np.stack([u[:, 0], (u[:, 1] + a / (2 * np.pi)) % 1.0], 1))
    np.testing.assert_allclose(d, shifted[:, :1] * s + shifted[:, 1:2] * t + shifted[:, 2:] * n, atol=1e-12)
