"""Bent normals: the mean unoccluded direction per texel from the AO bake's own rays,
against the exact cosine-weighted means of the visible directions beside a wall, and Blender's
tangent-space encoding (the exact inverse of Cycles' Normal Map node)."""

import math

import numpy as np
import pytest

from core import Mesh, bake_ao
from core.post.bent import TangentFrames, barycentric, encode, texel_directions
from chi2 import sidak
from core.montecarlo.stats import normal_quantile
from scenes import box, plane

WALL_HEIGHT = 1000.0


def wall(x=0.0, height=WALL_HEIGHT, name="wall"):
    """A wall in the plane x = ``x``, from z = 0 up, 2000 long in y (infinite for a unit plane)."""
    P = np.array([[x, -1000, 0], [x, 1000, 0], [x, 1000, height], [x, -1000, height]], float)
    return Mesh(P, np.array([[0, 1, 2], [0, 2, 3]]), name=name)


def wall_moments(d, h=WALL_HEIGHT, reach=math.inf):
    """(m_x, m_z): the exact cosine-weighted mean of the visible directions times AO, at distance d
    from the wall (notes section 4.1, and 4.2 for an AO distance ``reach`` with an infinite wall)."""
    if math.isfinite(reach):
        c = min(d / reach, 1.0)
        return -(2 / (3 * math.pi)) * (1 - c * c) ** 1.5, 1 / 3 + c / 2 - c ** 3 / 6
    a = math.atan(h / d)
    return (-(2 / (3 * math.pi)) * math.sin(a) ** 2,
            (2 / (3 * math.pi)) * (math.pi - a) + math.sin(2 * a) / (3 * math.pi))


def texel_moments(W, x0, x1, reach=math.inf, order=8):
    """Per texel column of a plane x in [x0, x1] (wall at x = 0, d = -x): the texel means of m."""
    g, w = np.polynomial.legendre.leggauss(order)
    out = np.zeros((W, 2))
    for j in range(W):
        for gx, wx in zip((g + 1) / 2, w / 2):
            x = x0 + (x1 - x0) * (j + gx) / W
            out[j] += wx * np.array(wall_moments(-x, reach=reach))
    return out


@pytest.mark.parametrize("distribution", ["cosine", "uniform"])
def test_an_open_plane_bends_nowhere(distribution):
    """Open sky: the bent normal is the normal. Each texel's tilt from it is noise whose mean over
    the texels is zero (independent samples: m_x, m_y have variance 1/4 per sample under cosine
    directions, 1/3 under uniform ones, about m_z = 2/3)."""
    N = 256
    r = bake_ao(plane(), resolution=16, samples=N, margin=0, bent_normals=True, source="independent",
                distribution=distribution, seed=4)
    b = r.bent.reshape(-1, 3)
    np.testing.assert_allclose(np.linalg.norm(b, axis=1), 1.0, atol=1e-6)
    per_sample = 0.25 if distribution == "cosine" else 1 / 3
    sd = math.sqrt(per_sample / N) / (2 / 3) / math.sqrt(len(b))
    assert abs(b[:, 0].mean()) < 4 * sd and abs(b[:, 1].mean()) < 4 * sd
    assert b[:, 2].min() > 0.9
    # Sobol' points (the default) are closer still, texel by texel.
    r = bake_ao(plane(), resolution=16, samples=N, margin=0, bent_normals=True, distribution=distribution)
    assert np.abs(r.bent[..., :2]).max() < 0.05


@pytest.mark.parametrize("reach, distribution", [(math.inf, "cosine"), (0.5, "cosine"), (math.inf, "uniform")])
def test_beside_a_wall_the_bent_normal_leans_away_by_the_exact_mean(reach, distribution):
    """A plane x in [-1, 0] at the foot of an infinite wall x = 0: each texel's bent normal leans away
    from the wall (-x) by atan(-m_x / m_z) of the texel's mean m (atan(2 / pi) = 32.48 degrees at
    any distance without an AO distance; with one, the lean fades to 0 at the reach). The ratio
    b_x / b_z estimates m_x / m_z; its texel errors are tested against their own spread."""
    W, H, N = 32, 8, 2048
    r = bake_ao(plane(-1, -0.5, 0, 0.5), [wall()], resolution=(W, H), samples=N, margin=0, bent_normals=True,
                source="independent", max_distance=reach, seed=11, distribution=distribution)
    m = texel_moments(W, -1.0, 0.0, reach)
    want = m[:, 0] / m[:, 1]
    b = r.bent.astype(float)
    assert np.all(np.abs(b[..., 1]) < 0.1)
    ratio = b[..., 0] / b[..., 2]
    err = (ratio - want[None, :]).ravel()
    spread = err.std(ddof=1) / math.sqrt(err.size)
    assert abs(err.mean()) < 4 * spread + 0.3 / N, (err.mean(), spread)  # + the ratio's O(1/N) bias
    if not math.isfinite(reach) and distribution == "cosine":
        # The delta method's variance of the ratio at the infinite wall: N Var = 0.6045 (notes 4.1).
        assert 0.7 < err.var() / (0.6045 / N) < 1.3, err.var() * N
    if not math.isfinite(reach):
        lean = np.degrees(np.arctan2(-b[..., 0], b[..., 2])).mean()
        assert abs(lean - math.degrees(math.atan(2 / math.pi))) < 0.3, lean
    else:
        # Texels beyond the reach: no lean. Open texels' b_x / b_z has mean 0 and, for N independent
        # cosine directions, sd sqrt(E[x^2] / N) / E[z] = sqrt(1 / (4 N)) / (2 / 3) (0.0166 at 2048);
        # every one of them within the Sidak bound for a family-wise 1e-3, whatever the seed.
        far = ratio[:, : W // 2 - 2]
        sd = math.sqrt(1.0 / (4 * N)) / (2.0 / 3.0)
        z = normal_quantile(1 - sidak(1e-3, far.size) / 2)
        assert np.all(np.abs(far) < z * sd), (np.abs(far).max(), z * sd)
    # The AO of the same bake is the wall's: (1 + cos(alpha)) / 2 = 1/2 at an infinite wall, and
    # 1 - (acos c - c sqrt(1 - c^2)) / pi, c = d / reach, with a reach (notes 4.2).
    d = -(-1.0 + (np.arange(W) + 0.5) / W)
    c = np.minimum(d / reach, 1.0)
    exact = 1 - (np.arccos(c) - c * np.sqrt(1 - c * c)) / math.pi if math.isfinite(reach) else np.full(W, 0.5)
    assert abs((r.ao - exact[None, :]).mean()) < 0.01 or distribution == "uniform"  # uniform AO is clipped


def test_bent_normals_cost_no_ray_and_leave_the_ao_as_it_was():
    seen = {}
    for bent in (False, True):
        rays = []
        r = bake_ao(plane(-1, -0.5, 0, 0.5), [wall()], resolution=16, samples=64, bent_normals=bent,
                    on_rays=lambda batch: rays.append(len(batch.origins)))
        seen[bent] = (sum(rays), r)
    assert seen[True][0] == seen[False][0] == seen[True][1].rays
    np.testing.assert_array_equal(seen[True][1].ao, seen[False][1].ao)
    assert seen[False][1].bent is None


def test_a_fully_occluded_texel_takes_its_shading_normal():
    """Inside a closed box nothing is visible: m = 0, and the texel gets the normal (flat in tangent space)."""
    r = bake_ao(plane(0.25, 0.25, 0.75, 0.75, z=0.5), [box((0, 0, 0), (1, 1, 1))], resolution=8, samples=16,
                margin=0, bent_normals=True)
    assert np.all(r.ao == 0)
    np.testing.assert_allclose(r.bent, np.broadcast_to([0, 0, 1], r.bent.shape), atol=1e-6)


def _random_frames(rng, n):
    T = rng.normal(size=(n, 3))
    N = rng.normal(size=(n, 3))
    N += 3 * np.cross(T, rng.normal(size=(n, 3)))  # far from parallel to T
    return T, N, np.where(rng.random(n) < 0.5, -1.0, 1.0)


@pytest.mark.parametrize("unit_normal", [False, True])
def test_tangent_space_is_the_exact_inverse_of_the_normal_map_node(unit_normal):
    """Random non-orthonormal frames, unnormalised interpolants, either bitangent sign: decoding the
    encoded texel value as Cycles' Normal Map node does (normalize(c.x T + c.y B + c.z N) with
    B = sign (N x T); N normalised first with ``unit_normal``, as Blender 5.1 and later do) gives back
    the bent normal's direction in the frame's space, exactly; the other convention does not."""
    rng = np.random.default_rng(3)
    n = 200
    tangents = rng.normal(size=(n, 3, 3))
    normals = rng.normal(size=(n, 3, 3)) + np.array([0, 0, 3.0])
    signs = np.where(rng.random((n, 3)) < 0.5, -1.0, 1.0)
    matrix = rng.normal(size=(3, 3)) + 2 * np.eye(3)
    frames = TangentFrames(tangents, signs, normals, matrix, unit_normal=unit_normal)
    weights = rng.dirichlet([1, 1, 1], size=n)
    sums = rng.normal(size=(n, 3))
    tri = np.arange(n)
    got = texel_directions(sums, tri, weights, None, frames).astype(float)
    want = sums @ matrix.T
    want /= np.linalg.norm(want, axis=1, keepdims=True)

    def decode(unit):
        T = np.einsum("nk,nkc->nc", weights, tangents)
        N = np.einsum("nk,nkc->nc", weights, normals)
        if unit:
            N /= np.linalg.norm(N, axis=1, keepdims=True)
        s = np.where(np.einsum("nk,nk->n", weights, signs) < 0, -1.0, 1.0)
        B = s[:, None] * np.cross(N, T)
        d = got[:, :1] * T + got[:, 1:2] * B + got[:, 2:] * N
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    np.testing.assert_allclose(decode(unit_normal), want, atol=2e-6)
    assert np.abs(decode(not unit_normal) - want).max() > 1e-3
    np.testing.assert_allclose(np.linalg.norm(got, axis=1), 1.0, atol=1e-6)


def test_tangent_space_bake_of_a_plane_with_turned_uvs():
    """A plane whose u runs along +y and v along -x: tangent +y, bitangent -x. The wall at x = 0 makes
    the world bent normal lean to -x, which is +B: in tangent space (0, +sin, cos), RGB G > 1/2."""
    P = np.array([[-1, -0.5, 0], [0, -0.5, 0], [0, 0.5, 0], [-1, 0.5, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.stack([P[:, 1] + 0.5, -P[:, 0]], axis=1)  # u = y + 1/2, v = -x
    target = Mesh(P, F, uvs=uv[F], name="turned")
    t = np.tile([0.0, 1.0, 0.0], (2, 3, 1))
    nrm = np.tile([0.0, 0.0, 1.0], (2, 3, 1))
    frames = TangentFrames(t, np.ones((2, 3)), nrm, np.eye(3))
    world = bake_ao(target, [wall()], resolution=16, samples=256, margin=0, bent_normals=True)
    tangent = bake_ao(target, [wall()], resolution=16, samples=256, margin=0, bent_normals=True, bent_space=frames)
    np.testing.assert_allclose(tangent.bent[..., 0], world.bent[..., 1], atol=1e-6)
    np.testing.assert_allclose(tangent.bent[..., 1], -world.bent[..., 0], atol=1e-6)
    np.testing.assert_allclose(tangent.bent[..., 2], world.bent[..., 2], atol=1e-6)
    rgb = encode(tangent.bent, np.ones((16, 16), bool), tangent=True)
    assert rgb[..., 1].mean() > 0.7 and abs(rgb[..., 0].mean() - 0.5) < 0.05
    # Object space: a matrix applied to the world vector, normalised.
    turn = np.array([[0.0, 1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, 2.0]])
    obj = bake_ao(target, [wall()], resolution=16, samples=256, margin=0, bent_normals=True, bent_space=turn)
    want = world.bent.astype(float) @ turn.T
    want /= np.linalg.norm(want, axis=-1, keepdims=True)
    np.testing.assert_allclose(obj.bent, want, atol=1e-6)


def test_barycentric_weights_reproduce_the_point():
    rng = np.random.default_rng(0)
    corners = rng.random((5, 3, 2)) * 10
    tri = np.arange(5)
    x, y = rng.random(5) * 10, rng.random(5) * 10
    w = barycentric(corners, tri, x, y)
    np.testing.assert_allclose(w.sum(axis=1), 1.0)
    np.testing.assert_allclose(np.einsum("nk,nkc->nc", w, corners), np.stack([x, y], 1), atol=1e-9)


def test_margin_texels_hold_unit_vectors_and_the_rest_the_unbaked_fill():
    r = bake_ao(plane(), resolution=16, samples=16, margin=0, bent_normals=True)
    half = Mesh(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0]], float), np.array([[0, 1, 2]]),
                uvs=np.array([[[0.1, 0.1], [0.6, 0.1], [0.6, 0.6]]]), name="half")
    r = bake_ao(half, resolution=16, samples=16, margin=2, bent_normals=True)
    size = np.linalg.norm(r.bent, axis=-1)
    filled = size > 0
    assert np.all(filled[r.mask]) and (filled & ~r.mask).any() and (~filled).any()
    np.testing.assert_allclose(size[filled], 1.0, atol=1e-6)
    rgb = encode(r.bent, filled, tangent=True)
    np.testing.assert_array_equal(rgb[~filled], np.broadcast_to([0.5, 0.5, 1.0], rgb[~filled].shape))
    assert np.all(encode(r.bent, filled, tangent=False)[~filled] == 0)


@pytest.mark.parametrize("threads", [1, 2])
def test_dilated_directions_are_the_componentwise_margin_normalised(threads):
    """dilate_directions against its definition: each component through the margin's dilate alone,
    then every vector normalised where it is not zero (covered texels too); texels beyond the
    margin hold 0 and are not filled."""
    from core.post.bent import dilate_directions
    from core.geometry.margin import dilate

    rng = np.random.default_rng(5)
    h, w, margin = 300, 80, 4
    mask = np.zeros((h, w), bool)
    for _ in range(12):
        y, x = rng.integers(0, h), rng.integers(0, w)
        mask[y:y + rng.integers(2, 30), x:x + rng.integers(2, 30)] = True
    v = rng.standard_normal((h, w, 3))  # of any length: the covered vectors are normalised too
    bent = np.where(mask[..., None], v, 0).astype(np.float32)
    bent[np.flatnonzero(mask)[:3] // w, np.flatnonzero(mask)[:3] % w] = 0.0  # covered zero vectors stay 0
    out, filled = dilate_directions(bent, mask, margin, threads)
    ref = np.stack([dilate(np.ascontiguousarray(bent[..., c]), mask, margin) for c in range(3)], axis=-1)
    reach = dilate(mask.astype(np.float32), mask, margin) > 0
    size = np.linalg.norm(ref, axis=-1)
    want = np.where((reach & (size > 0))[..., None], ref / np.where(size > 0, size, 1)[..., None], 0)
    np.testing.assert_allclose(out, want, rtol=3e-7, atol=0)
    assert np.array_equal(filled, mask | (reach & (size > 0)))
    assert (filled & ~mask).any() and (~filled).any() and not out[~filled].any()
    np.testing.assert_allclose(np.linalg.norm(out[filled & (size > 0)], axis=-1), 1.0, atol=1e-6)


def test_every_ray_of_every_replicate_and_round_counts_in_the_bent_normal():
    """With replicates and adaptive rounds (texels stopping at different counts), a texel's bent
    normal is the normalised sum of the unit directions of all its unoccluded rays, over every
    replicate and every round: rebuilt here from the rays the bake reports (world space, a flat
    plane, so no interpolation of normals). Fails if a replicate's or a round's sums are dropped."""
    rays = []

    def on_rays(b):
        rays.append((b.texels.copy(), b.directions.astype(np.float64), ~b.occluded & (b.tfar > 0), b.replicate))

    W = 16
    r = bake_ao(plane(-1, -0.5, 0, 0.5), [wall(x=0.05)], resolution=W, samples=512, min_samples=32,
                target_error=0.02, replicates=2, margin=0, bent_normals=True, threads=2, on_rays=on_rays)
    counts = np.unique(r.samples[r.mask])
    assert len(counts) >= 2 and counts.min() > 32 and counts.max() < 512  # two rounds or more, stopped early
    assert {rep for *_, rep in rays} == {0, 1}
    sums = np.zeros((W * W, 3))
    for texels, d, open_, _ in rays:
        d = d / np.linalg.norm(d, axis=1)[:, None]
        np.add.at(sums, texels, d * open_[:, None])
    want = sums / np.linalg.norm(sums, axis=1)[:, None]
    got = r.bent.reshape(-1, 3)
    np.testing.assert_allclose(got, want, atol=2e-6)
