"""Selected to active on a smooth-shaded low-poly: the matching ray follows the low-poly's interpolated
normal (the normalised interpolation of its corner normals), not its face normal.

The scene has a closed form. The low-poly is a vertical wall at x = 0 (facing +x) from z0 to z0 + 1, its
corner normals tilted down at the bottom and up at the top, (1, 0, -s) and (1, 0, s): at height z the
interpolated normal is along (1, 0, s (2 (z - z0) - 1)). The high-poly is a flat wall at x = delta (inside
the extrusion) over the analytic ground z = 0. The ray from p + e n along -n meets x = delta at
q_z = z + delta n_z / n_x = z + delta s (2 (z - z0) - 1), and the AO there is the wall-over-the-ground's
circular segment, wall_ao(q_z) (tests/test_ground.py). A matching ray along the face normal (+x) would
find q_z = z instead, and one along the face normal from p + e n would find z + e n_z / |n|: rows
differ by up to 0.3 in height, 0.1-0.2 in AO.
"""


import numpy as np
import pytest

from core import Mesh, bake_ao
from core.montecarlo.stats import normal_quantile
from chi2 import SUITE_ALPHA, sidak
from scenes import QUAD
from test_ground import D, wall_ao

W, H = 4, 16
Z0, DELTA, S, E = 0.7, 0.15, 2.0, 0.6


def low_wall():
    P = np.array([[0.0, 0.0, Z0], [0.0, 1.0, Z0], [0.0, 1.0, Z0 + 1], [0.0, 0.0, Z0 + 1]])
    UV = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]])[QUAD]
    corner = np.where(P[:, 2:3] > Z0 + 0.5, [1.0, 0.0, S], [1.0, 0.0, -S])  # tilted down below, up above
    return Mesh(P, QUAD, UV, normals=corner[QUAD], name="low")


def high_wall():
    P = np.array([[DELTA, -1.0, 0.0], [DELTA, 2.0, 0.0], [DELTA, 2.0, 2.5], [DELTA, -1.0, 2.5]])
    return Mesh(P, QUAD, name="high")


def row_truth(matched_height, order=16):
    """Per texel row (row i covers z0 + [i, i + 1] / H), the mean of wall_ao(q(z)) and the spread of
    wall_ao over the row (for the variance of its points' positions)."""
    g, w = np.polynomial.legendre.leggauss(order)
    z = Z0 + (np.arange(H)[:, None] + (g[None, :] + 1) / 2) / H
    ao = wall_ao(matched_height(z))
    return (ao * w / 2).sum(axis=1), ao.max(axis=1) - ao.min(axis=1)


def interpolated(z):
    return z + DELTA * S * (2 * (z - Z0) - 1)


@pytest.mark.parametrize("seed", [0, 3])
def test_the_matching_ray_follows_the_interpolated_normal(seed):
    r = bake_ao(low_wall(), resolution=(W, H), samples=512, max_distance=D, source="independent", replicates=1,
                margin=0, seed=seed, highpoly=[high_wall()], extrusion=E, ground=0.0)
    assert r.mask.all()
    p, spread = row_truth(interpolated)
    face, _ = row_truth(lambda z: z)
    assert np.abs(p - face).max() > 0.08  # the two normals give other answers: the test can tell them apart
    # A texel's points each carry a block of directions: its mean's variance is at most the
    # directions' p (1 - p) / n plus its points' positions' (AO over the row, of range `spread`:
    # at most a quarter of its square) over the points. Each row's W texels together, Sidak over rows.
    points = r.samples / r.report["directions_per_point"]
    var = p[:, None] * (1 - p[:, None]) / r.samples + (spread[:, None] / 2) ** 2 / points
    open_rows = (p == 1.0) & (spread == 0.0)  # rows matched wholly at q_z >= d: open, exactly
    assert open_rows.any() and np.all(r.ao[open_rows] == 1.0)
    p, var, ao, face = p[~open_rows], var[~open_rows], r.ao[~open_rows], face[~open_rows]
    z = (ao.astype(float) - p[:, None]).sum(axis=1) / np.sqrt(var.sum(axis=1))
    crit = normal_quantile(1 - sidak(SUITE_ALPHA / 4, len(p)) / 2)
    assert np.abs(z).max() < crit, z
    z_face = (ao.astype(float) - face[:, None]).sum(axis=1) / np.sqrt(var.sum(axis=1))
    assert np.abs(z_face).max() > 2 * crit, z_face


def test_a_cage_of_the_extruded_smooth_low_poly_matches_the_same_points():
    """The cage: the low-poly pushed out along its interpolated normals by e gives the same matching
    rays (origin p + e n, direction -n), so the same bake within rounding."""
    low = low_wall()
    n = low.normals  # (T, 3, 3) unit corner normals
    cage_positions = low.positions.copy()
    for t, tri in enumerate(low.triangles):
        for c, v in enumerate(tri):
            cage_positions[v] = low.positions[v] + E * n[t, c]
    cage = Mesh(cage_positions, low.triangles, name="cage")
    kw = dict(resolution=(W, H), samples=64, max_distance=D, margin=0, seed=1, highpoly=[high_wall()], ground=0.0)
    a = bake_ao(low, extrusion=E, **kw)
    b = bake_ao(low, cage=cage, **kw)
    assert np.abs(a.ao - b.ao).max() < 0.05 and abs(float(a.ao.mean() - b.ao.mean())) < 0.01
