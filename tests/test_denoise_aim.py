"""Adaptive sampling aimed at the denoised map's error (core.post.denoise.aim, the two passes of
core.pipeline.run): the counts against the formula written out, and bakes of the exact scenes that
meet the target with fewer rays than the raw estimate's adaptive sampling, the same bits on threads,
worker processes and a Dask cluster. Small scenes, nothing timed."""

import math

import numpy as np
import pytest

from core import bake_ao, bake_maps
from core.post.denoise import aim
from test_denoise import scene

TARGET = 0.03
AIMED = dict(resolution=64, samples=256, min_samples=16, target_error=TARGET, margin=0, denoise=True)


def test_each_texel_takes_the_count_its_denoised_error_asks():
    h, w = 16, 24
    s2 = (TARGET / 1.959963984540054) ** 2
    variance = np.full((h, w), s2 / 2)  # within the target already
    bias = np.zeros((h, w))
    raw = np.full((h, w), s2 * 3)
    variance[4, 4] = s2 * 4  # needs 4^(1 / (2 rate)) times the samples
    variance[12, 20], bias[12, 20], raw[12, 20] = s2 / 8, math.sqrt(s2), s2 * 64  # bias-limited: its raw error
    mask = np.ones((h, w), bool)
    mask[0, :] = False
    first, cap = 8, 512
    for rate in (0.5, 0.75):
        goal = aim.goal_counts(variance, bias, raw, mask, first, TARGET, cap, rate)
        want = np.zeros((h, w), np.int64)
        for (i, j), ratio in (((4, 4), 4.0), ((12, 20), 64.0)):
            need = first * ratio ** (1 / (2 * rate))
            n = min(max(2 ** math.ceil(math.log2(need)), 2 * first), cap)
            # the texel's count for every texel of its window (the filter's), on the covered ones
            r = aim.SPREAD
            win = want[max(i - r, 0):i + r + 1, max(j - r, 0):j + r + 1]
            np.maximum(win, n, out=win)
        want[~mask] = 0
        np.testing.assert_array_equal(goal, want)


def truth_and_gradient(name):
    _, _, truth = scene(name)
    gy, gx = np.gradient(truth)
    return truth, np.hypot(gx, gy)


@pytest.mark.parametrize("name", ["box on plane", "polygon"])
def test_the_denoised_map_meets_the_target_with_fewer_rays(name):
    target, occ, _ = scene(name)
    truth, grad = truth_and_gradient(name)
    r = bake_ao(target, occ, seed=2, **AIMED)
    plain = bake_ao(target, occ, seed=2, **dict(AIMED, denoise=False))
    m = r.mask
    # The denoised map's error is within the target at 95% of the texels (its interval's confidence:
    # each texel's predicted half-width is at most the target; measured 99.4-100% over seeds 0-27).
    assert np.mean(np.abs(r.ao - truth)[m] <= TARGET) >= 0.95
    # Fewer rays than the raw estimate's adaptive sampling for the same target (measured: 0.35-0.38x on
    # the box, 0.15-0.20x on the polygon, seeds 0-7).
    assert r.rays < 0.75 * plain.rays, (r.rays, plain.rays)
    # Every texel took the first round.
    assert r.samples[m].min() >= 16
    if name == "box on plane":
        # Beside the box's contact edge (the steepest AO), where the filter can average nothing across
        # the edge, the texels took more than the smooth ones (about 6x over seeds 0-27). Not asserted
        # for the polygon: its penumbra is smooth at 64^2, the filter averages it, and whether its
        # steepest texels take more than the open plane depends on the first round's noise (0.96-3.7x
        # over seeds 0-27).
        steep = m & (grad >= np.quantile(grad[m], 0.9))
        smooth = m & (grad <= np.quantile(grad[m], 0.5))
        assert r.samples[steep].mean() > 1.5 * r.samples[smooth].mean()
    # The raw estimate kept beside it is the bake of those counts, its error honest.
    sel = m & (r.raw_stderr > 0)
    z = (r.raw_ao - truth)[sel] / r.raw_stderr[sel]
    assert 0.85 <= z.std() <= 1.15


FIELDS = ("ao", "stderr", "samples", "mask", "raw_ao", "raw_stderr")


def test_the_aimed_bake_is_the_same_bits_on_threads_and_worker_processes():
    target, occ, _ = scene("box on plane")
    kw = dict(AIMED, resolution=48, seed=5, tile_size=16)
    ref = bake_ao(target, occ, threads=1, **kw)
    for other in (dict(threads=2), dict(workers=2, threads=1)):
        r = bake_ao(target, occ, **kw, **other)
        for name in FIELDS:
            assert np.array_equal(getattr(ref, name), getattr(r, name)), (other, name)
        assert r.rays == ref.rays


def test_the_aimed_bake_is_the_same_bits_on_a_dask_cluster():
    distributed = pytest.importorskip("distributed")
    import os

    target, occ, _ = scene("box on plane")
    kw = dict(AIMED, resolution=48, seed=5, tile_size=16)
    ref = bake_ao(target, occ, threads=1, **kw)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None, silence_logs=40) as cluster, \
            distributed.Client(cluster) as client:
        root = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        client.run(lambda: __import__("sys").path.insert(0, root))
        r = bake_ao(target, occ, workers=client, **kw)
    for name in FIELDS:
        assert np.array_equal(getattr(ref, name), getattr(r, name)), name


def test_maps_of_several_quantities_take_the_same_counts():
    target, occ, _ = scene("box on plane")
    out = bake_maps(target, occ, quantities=("ao", "thickness"), **dict(AIMED, resolution=32))
    ao, thick = out["ao"], out["thickness"]
    assert ao.samples[ao.mask].max() > 16
    np.testing.assert_array_equal(ao.samples, thick.samples)
