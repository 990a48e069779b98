"""bench.sections.oracle's allocation (the bound the adaptive targets are read against): on errors
whose best allocation is known by hand, it finds it."""

import numpy as np

from bench.sections.oracle import allocate, model_errors, replay

COUNTS = (16, 32, 64, 128)


def test_an_open_texel_never_takes_more_than_the_first_count():
    # Texel 0 errs as 1/n (an occluded texel), texel 1 never (an open one): reaching the fixed
    # count's mean error takes texel 0 to that count and leaves texel 1 at 16.
    n = np.array(COUNTS, float)
    err = np.stack([16.0 / n, np.zeros(4)])
    curve = replay(allocate(err, COUNTS), err, COUNTS)
    for j, fixed_n in enumerate(COUNTS):
        fixed = err[:, j].mean()
        first = np.flatnonzero(curve[:, 1] <= fixed + 1e-15)[0]
        assert curve[first, 0] == (fixed_n + 16) / 2


def test_samples_go_where_they_buy_most_error_per_sample():
    # Two varying texels, one with four times the error of the other at every count: the greedy
    # allocation moves the noisy one first, and each step it takes lowers the mean error.
    n = np.array(COUNTS, float)
    err = np.stack([4.0 / n, 1.0 / n])
    moves = allocate(err, COUNTS)
    assert moves[0] == (0, 1) and sorted(moves) == [(0, 1), (0, 2), (0, 3), (1, 1), (1, 2), (1, 3)]
    curve = replay(moves, err, COUNTS)
    assert np.all(np.diff(curve[:, 1]) < 0) and np.all(np.diff(curve[:, 0]) > 0)
    assert curve[-1, 0] == 128 and np.isclose(curve[-1, 1], err[:, -1].mean())


def test_the_error_model_recovers_each_texels_constant_and_the_rate():
    rng = np.random.default_rng(3)
    n = np.array(COUNTS, float)
    c = np.array([0.5, 2.0, 8.0])
    sq = c[None, :, None] * n ** -1.5 * rng.exponential(size=(400, 3, 4))  # squared errors, mean c n^-1.5
    model, a = model_errors(sq, COUNTS)
    assert abs(a - 1.5) < 0.05
    np.testing.assert_allclose(model[:, 0] * 16 ** 1.5, c, rtol=0.1)
