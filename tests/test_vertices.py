"""AO at mesh corners (colour attributes): sample units that are points, the texel
baker's estimator, sampling and errors, against Lambert's exact AO at each vertex."""

import math

import numpy as np
import pytest

from core import BakeCancelled, Mesh, MeshError
from core.montecarlo.analytic import polygon_form_factor
from core import bake_vertex_ao
from core.geometry.corners import all_corners, sample_points, vertex_means

LID = np.array([[-0.3, -0.3, 0.4], [0.3, -0.3, 0.4], [0.3, 0.3, 0.4], [-0.3, 0.3, 0.4]])


def lid():
    return Mesh(LID, np.array([[0, 2, 1], [0, 3, 2]]), name="lid")


def grid(n=9, size=1.0, smooth=False):
    """A flat grid (n x n vertices) on z = 0 over [-size, size]^2; corner normals +z when ``smooth``."""
    xs = np.linspace(-size, size, n)
    X, Y = np.meshgrid(xs, xs)
    P = np.stack([X.ravel(), Y.ravel(), np.zeros(n * n)], axis=1)
    F = []
    for i in range(n - 1):
        for j in range(n - 1):
            a = i * n + j
            F += [[a, a + 1, a + n + 1], [a, a + n + 1, a + n]]
    F = np.array(F)
    normals = np.tile([0.0, 0.0, 1.0], (len(F), 3, 1)) if smooth else None
    return Mesh(P, F, normals=normals, name="grid")


def test_an_open_plane_is_one_at_every_corner_with_zero_error():
    r = bake_vertex_ao(grid(), samples=64)
    assert r.ao.shape == (grid().triangle_count * 3,)
    assert np.all(r.ao == 1.0) and np.all(r.stderr == 0.0) and np.all(r.samples == 64)


def test_corner_values_match_lamberts_formula_at_each_vertex():
    """Under a square lid, each vertex's AO is 1 - F (Lambert's form factor at the vertex): corner
    estimates are unbiased with honest standard errors (independent samples, z-scores)."""
    g = grid(n=13, smooth=True)
    r = bake_vertex_ao(g, [lid()], samples=512, source="independent", seed=2)
    units = np.unique(r.unit)
    assert len(units) == len(g.positions)  # smooth: one sample point per vertex
    first = np.array([np.flatnonzero(r.unit == u)[0] for u in units])
    vert = g.triangles.reshape(-1)[first]
    truth = 1.0 - polygon_form_factor(g.positions[vert], LID)
    ao, se = r.ao[first].astype(float), r.stderr[first].astype(float)
    var = truth * (1 - truth) / 512
    total = (ao - truth).sum() / math.sqrt(var.sum())
    assert abs(total) < 4, total
    inner = se > 0
    z = (ao - truth)[inner] / se[inner]
    assert 0.7 < z.var() < 1.4, z.var()


@pytest.mark.parametrize("source", ["sobol", "halton"])
def test_replicates_give_quasi_monte_carlo_corners_their_real_error(source):
    """With replicates (the default) a corner's stderr is the error its estimate really makes for
    the quasi-Monte Carlo sources, as a texel's (pooled over the vertex's 1-ring); with one
    replicate it is the independent-sample bound, about 3 times too large (measured 2.6-3.0)."""
    g = grid(n=25, smooth=True)
    ratios = {}
    for replicates in (1, 2):
        r = bake_vertex_ao(g, [lid()], samples=256, source=source, seed=3, replicates=replicates)
        first = np.array([np.flatnonzero(r.unit == u)[0] for u in np.unique(r.unit)])
        truth = 1.0 - polygon_form_factor(g.positions[g.triangles.reshape(-1)[first]], LID)
        inner = truth < 0.999
        err = (r.ao[first].astype(float) - truth)[inner]
        se = r.stderr[first].astype(float)[inner]
        assert inner.sum() > 200
        ratios[replicates] = math.sqrt((se ** 2).mean() / (err ** 2).mean())
        if replicates == 2:
            # Pooled over the 1-ring (about 7 points, 1 degree of freedom each) the z-scores have
            # light tails: |z| > 4 about 0.5% of the time (measured 0.3-0.6%). A corner's own two
            # replicates alone (1 degree of freedom, Cauchy tails) give 16-17%.
            z = err / np.maximum(se, 1e-12)
            assert np.mean(np.abs(z) > 4) < 0.04, np.mean(np.abs(z) > 4)
    # About 300 corners: the RMSE itself is known to a few percent; 0.8-1.25 is several times that.
    assert 0.8 < ratios[2] < 1.25, ratios
    assert ratios[1] > 2.0, ratios


def test_flat_corners_have_their_faces_normals_and_points_average_their_corners():
    """A flat-shaded vertex has a sample point per face normal; the point domain is the plain mean
    of its corners' values (Cycles' rule), whatever the faces' sizes."""
    # A tent: two faces meeting at a ridge along y, each tilted 45 degrees.
    P = np.array([[-1, -1, 0], [0, -1, 1], [0, 1, 1], [-1, 1, 0], [1, -1, 0], [1, 1, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3], [1, 4, 5], [1, 5, 2]])
    slope = np.array([[-1.0, 0.0, 1.0], [1.0, 0.0, 1.0]]) / math.sqrt(2)
    tent = Mesh(P, F, normals=np.repeat(slope[[0, 0, 1, 1]][:, None, :], 3, axis=1), name="tent")
    r = bake_vertex_ao(tent, samples=256)
    # Ridge vertices (1, 2) have one sample point per face (two normals), the others one.
    assert len(np.unique(r.unit)) == 8
    np.testing.assert_array_equal(r.ao, 1.0)  # a convex tent is open everywhere
    values = np.arange(12, dtype=float)
    means = vertex_means(values, tent.triangles.reshape(-1), 7)
    ridge = np.flatnonzero(tent.triangles.reshape(-1) == 1)
    assert means[1] == values[ridge].mean() and means[6] == 0.0  # vertex 6 has no corners


def test_a_vertex_at_the_foot_of_a_wall_is_nudged_into_its_face():
    """A floor vertex on the bottom edge of a wall: Cycles moves the sample a hair into the face, so
    it sees half the sky (AO = 1/2 beside an infinite wall) rather than lying in the wall's plane."""
    floor = Mesh(np.array([[-1, -1, 0], [0, -1, 0], [0, 1, 0], [-1, 1, 0]], float),
                 np.array([[0, 1, 2], [0, 2, 3]]), name="floor")
    wall = Mesh(np.array([[0, -100, 0], [0, 100, 0], [0, 100, 100], [0, -100, 100]], float),
                np.array([[0, 1, 2], [0, 2, 3]]), name="wall")
    corners = np.array([[0, 1], [0, 2]])  # the corners at vertices 1 and 2, on the wall's foot
    r = bake_vertex_ao(floor, [wall], corners=corners, samples=4096, source="independent")
    z = (r.ao - 0.5) / math.sqrt(0.25 / 4096)
    assert np.all(np.abs(z) < 4), r.ao


def test_adaptive_sampling_and_errors_are_the_texels():
    """target_error stops open corners at the minimum and samples occluded ones further, with the
    texel rule (replicates, errors pooled over each vertex's 1-ring); the same seed gives the same
    values on any number of threads."""
    g = grid(n=9, size=2.0, smooth=True)
    kw = dict(samples=1024, min_samples=128, target_error=0.01, max_distance=0.6)
    r = bake_vertex_ao(g, [lid()], threads=2, **kw)
    open_ = r.ao == 1.0
    assert open_.any() and (~open_).any()
    # Rays reach the lid (0.3 wide at height 0.4, max distance 0.6) from within 0.75 of the centre
    # in x or y; vertices 1.5 out and beyond have only open neighbours (grid step 0.5): they stop at
    # the minimum. Open corners beside occluded ones may go on (their neighbours' errors count).
    far = np.abs(g.positions[g.triangles.reshape(-1)][:, :2]).max(axis=1) >= 1.5
    assert np.all(open_[far]) and np.all(r.samples[far] == 128) and r.samples[~open_].max() > 256
    # Corners that stopped before the cap did so with a 95% interval within the target.
    early = r.samples < 1024
    assert np.all(2.0 * r.stderr[early] <= 0.01)
    again = bake_vertex_ao(g, [lid()], threads=1, **kw)
    np.testing.assert_array_equal(r.ao, again.ao)
    np.testing.assert_array_equal(r.stderr, again.stderr)


def test_every_sample_is_traced_once_from_its_corner():
    g = grid(n=5, smooth=True)
    seen = []

    def on_rays(batch):
        seen.append((batch.texels.copy(), batch.samples.copy(), batch.origins.copy(),
                     np.full(len(batch.texels), batch.replicate)))

    r = bake_vertex_ao(g, [lid()], samples=32, on_rays=on_rays, threads=1)
    texels = np.concatenate([s[0] for s in seen])
    samples = np.concatenate([s[1] for s in seen])
    origins = np.concatenate([s[2] for s in seen])
    replicate = np.concatenate([s[3] for s in seen])
    m = len(np.unique(r.unit))
    # Two replicates (the default) of 16 samples each: samples 0..15 of each, every one once.
    assert set(np.unique(replicate)) == {0, 1} and samples.max() == 15
    pairs = (texels * 2 + replicate) * 16 + samples
    assert len(pairs) == m * 32 and len(np.unique(pairs)) == m * 32
    # Every ray of a sample point starts at the same place (a point has no extent), off the surface.
    for u in range(m):
        o = origins[texels == u]
        assert np.ptp(o, axis=0).max() == 0.0 and o[0, 2] > 0


def test_bad_corners_are_refused_with_the_mesh_name():
    g = grid(n=3)
    with pytest.raises(MeshError, match="'grid'.*corners"):
        bake_vertex_ao(g, corners=np.array([[0, 3]]))
    with pytest.raises(MeshError, match="'grid'"):
        bake_vertex_ao(g, corners=np.array([[99, 0]]))


def test_cancel_raises():
    with pytest.raises(BakeCancelled):
        bake_vertex_ao(grid(), [lid()], samples=64, cancel=lambda: True)


def test_sample_points_sit_on_their_vertices_nudged_towards_the_triangle():
    g = grid(n=3)
    unit, p, n, gn, corners3, flat = sample_points(g, all_corners(g))
    assert flat == 0 and np.all(gn == [0, 0, 1])
    first = np.array([np.flatnonzero(unit == u)[0] for u in range(len(p))])
    vert = g.triangles.reshape(-1)[first]
    step = np.linalg.norm(p - g.positions[vert], axis=1)
    assert np.all(step > 0) and np.all(step <= 1e-4 * 2.0 * (1 + 1e-12))
