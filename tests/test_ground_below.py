"""The ground seen from below it: surfaces under the ground plane get the plane's back face (occluding,
as a huge plane mesh's back would) or nothing with Ignore Backfaces, never black everywhere.

Closed forms (cosine directions project to the unit disk uniformly; see tests/test_ground.py):
- a wall facing +x crossing the ground: a point at height z < 0 is the mirror image of one at -z, whose
  rays up meet the plane's back within d in a circular segment: AO(z) = wall_ao(|z|); with Ignore
  Backfaces those rays pass: AO = 1 below, the same segment above;
- a floor at depth a under the ground facing up: rays up meet it within d where cos(theta) >= a / d:
  AO = (a / d)^2 (1 with Ignore Backfaces); facing down: nothing to meet, AO = 1.
"""

import math

import numpy as np
import pytest

from core import bake_ao
from core.montecarlo.stats import normal_quantile
from chi2 import SUITE_ALPHA
from scenes import plane
from test_ground import D, H, N, W, check_binomial, row_means, wall, wall_ao


@pytest.mark.parametrize("seed", [0, 5])
def test_a_wall_through_the_ground_sees_the_planes_back_below_it(seed):
    r = bake_ao(wall(-1.0, 1.0), resolution=(W, H), samples=N, max_distance=D, source="independent", replicates=1,
                margin=0, seed=seed, ground=0.0)
    truth = row_means(lambda z: wall_ao(abs(z)), z0=-1.0, height=2.0)
    check_binomial(r, truth, SUITE_ALPHA / 4)
    below = r.ao[: H // 2]
    assert below.mean() > 0.6  # not black


def test_with_ignore_backfaces_a_wall_below_the_ground_is_open():
    r = bake_ao(wall(-1.0, 1.0), resolution=(W, H), samples=N, max_distance=D, source="independent", replicates=1,
                margin=0, seed=2, ground=0.0, ignore_backfaces=True)
    truth = row_means(lambda z: 1.0 if z < 0 else wall_ao(z), z0=-1.0, height=2.0)
    # rows below the ground are exactly open; rows above, the circular segment
    assert np.all(r.ao[: H // 2 - 1] == 1.0)
    check_binomial(r, truth, SUITE_ALPHA / 4)


def _total_z(r, p):
    n = r.samples[r.mask].astype(float)
    k = np.rint(r.ao[r.mask].astype(float) * n)
    return (k.sum() - p * n.sum()) / math.sqrt(max(p * (1 - p), 1e-12) * n.sum())


@pytest.mark.parametrize("depth", [0.25, 0.5, 0.8])
def test_a_floor_under_the_ground_facing_up_has_the_truncated_cone(depth):
    kw = dict(resolution=16, samples=256, max_distance=D, source="independent", replicates=1, margin=0, seed=1)
    r = bake_ao(plane(z=-depth), ground=0.0, **kw)
    assert r.mask.all()
    assert abs(_total_z(r, (depth / D) ** 2)) < normal_quantile(1 - SUITE_ALPHA / 8)
    assert np.all(bake_ao(plane(z=-depth), ground=0.0, ignore_backfaces=True, **kw).ao == 1.0)
    assert np.all(bake_ao(plane(z=-depth, flip=True), ground=0.0, **kw).ao == 1.0)  # facing down: nothing below


@pytest.mark.parametrize("height", [1e30, 1e39, 1e300])
@pytest.mark.parametrize("ignore_backfaces", [False, True])
def test_a_ground_at_any_finite_height_occludes_as_an_endless_floor(height, ignore_backfaces):
    """Without a maximum distance the ground is an endless plane at any height: below a floor facing down,
    every ray meets its front; above a floor facing up, every ray meets its back (passes with Ignore
    Backfaces). Embree's rays stop at a float32 length; the ground did not occlude beyond it (a far
    height baked as without a ground)."""
    kw = dict(resolution=8, samples=16, margin=0, ignore_backfaces=ignore_backfaces)
    assert np.all(bake_ao(plane(flip=True), ground=-height, **kw).ao == 0.0)
    assert np.all(bake_ao(plane(), ground=-height, **kw).ao == 1.0)
    assert np.all(bake_ao(plane(), ground=height, **kw).ao == (1.0 if ignore_backfaces else 0.0))
    # The same in a bake that needs hit distances (a back face passed through: the visibility path).
    kw["ignore_backfaces"] = True
    assert np.all(bake_ao(plane(flip=True), ground=-height, **kw).ao == 0.0)
    # With a maximum distance it is out of reach.
    assert np.all(bake_ao(plane(flip=True), ground=-height, max_distance=10.0, **kw).ao == 1.0)
