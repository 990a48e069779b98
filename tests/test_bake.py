"""The AO baker against analytic truth: open and closed scenes, Lambert's polygon form factor,
truncated distances, estimator agreement, determinism, adaptive sampling, margin, files."""

import math
import threading

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from core import BakeCancelled, Mesh, bake_ao
from core.geometry.raster import prepare, rasterize_tile
from core.montecarlo.stats import normal_quantile
from scenes import box, plane, polygon_form_factor, texel_mean

LID = np.array([[0.25, 0.25, 0.3], [0.75, 0.25, 0.3], [0.75, 0.75, 0.3], [0.25, 0.75, 0.3]])


def lid_mesh(verts=LID):
    return Mesh(verts, np.array([[0, 1, 2], [0, 2, 3]]), name="lid")


@pytest.mark.parametrize("source", ["sobol", "stratified", "independent", "halton"])
def test_open_plane_is_exactly_one_with_zero_error(source):
    r = bake_ao(plane(), resolution=16, samples=32, source=source, margin=0)
    assert r.mask.all()
    assert np.all(r.ao == 1.0) and np.all(r.stderr == 0.0) and np.all(r.samples == 32)


def test_open_plane_uniform_is_unbiased_but_noisy():
    r = bake_ao(plane(), resolution=16, samples=256, distribution="uniform", margin=0, source="independent")
    # 2 cos(theta) under uniform directions: mean 1, variance 1/3 per sample.
    assert np.all(r.stderr > 0)
    z = (r.ao.astype(float) - 1.0)
    # ao is clipped to [0, 1], so compare the unclipped mean through texels below and above 1 symmetrically
    assert abs(np.mean(np.minimum(z, 0))) < 4 * math.sqrt(1 / 3 / 256)


@pytest.fixture(scope="module")
def lid_truth():
    W = H = 24
    truth = texel_mean(lambda p: 1.0 - polygon_form_factor(p, LID), W, H)
    return W, H, truth


@pytest.mark.parametrize("distribution", ["cosine", "uniform"])
def test_plane_under_polygon_matches_lamberts_formula(lid_truth, distribution):
    W, H, truth = lid_truth
    r = bake_ao(plane(), [lid_mesh()], resolution=(W, H), samples=256, source="independent",
                distribution=distribution, margin=0, seed=3)
    # Compare before the [0, 1] clip only where clipping cannot act: the truth is well inside (0, 1).
    err = r.ao - truth
    z = err / r.stderr
    m = z.size
    assert abs(z.mean()) < 4 / math.sqrt(m), z.mean()            # no systematic bias
    assert 0.8 < z.var() < 1.25, z.var()                         # the stderr is honest
    assert np.abs(z).max() < normal_quantile(1 - 0.01 / (2 * m)) + 0.5  # no texel far off (Sidak, t tails)


def test_sobol_is_unbiased_and_more_accurate_than_independent(lid_truth):
    W, H, truth = lid_truth
    errs = {}
    for source in ("sobol", "independent"):
        r = bake_ao(plane(), [lid_mesh()], resolution=(W, H), samples=256, source=source, margin=0, seed=5)
        errs[source] = r.ao - truth
        se = r.stderr
    # Sobol's mean error is within the (conservative) combined standard error of zero.
    assert abs(errs["sobol"].mean()) < 4 * math.sqrt((se ** 2).mean() / se.size)
    rmse = {k: math.sqrt((v ** 2).mean()) for k, v in errs.items()}
    assert rmse["sobol"] < 0.7 * rmse["independent"], rmse


def test_cosine_has_lower_variance_than_uniform(lid_truth):
    W, H, _ = lid_truth
    se = {d: bake_ao(plane(), [lid_mesh()], resolution=(W, H), samples=128, distribution=d, margin=0,
                     source="independent").stderr.mean() for d in ("cosine", "uniform")}
    assert se["cosine"] < 0.8 * se["uniform"], se


BIG_LID = np.array([[-1.0, -1.0, 0.3], [2.0, -1.0, 0.3], [2.0, 2.0, 0.3], [-1.0, 2.0, 0.3]])


def test_max_distance_below_the_lid_height_sees_nothing():
    r = bake_ao(plane(), [lid_mesh(BIG_LID)], resolution=16, samples=64, max_distance=0.25, margin=0)
    assert np.all(r.ao == 1.0) and np.all(r.stderr == 0)


def test_max_distance_between_gives_the_truncated_cone():
    # Hits count only for cos(theta) >= h / d; the lid covers that whole cone, so the occluded
    # cosine-weighted fraction is sin^2(theta_c) and AO = (h / d)^2 = 0.36 everywhere.
    r = bake_ao(plane(), [lid_mesh(BIG_LID)], resolution=16, samples=256, max_distance=0.5, margin=0,
                source="independent", seed=2)
    z = (r.ao - 0.36) / r.stderr
    assert abs(z.mean()) < 4 / math.sqrt(z.size) and 0.75 < z.var() < 1.3


def test_point_inside_a_closed_box_is_fully_occluded():
    r = bake_ao(plane(), [box((-0.5, -0.5, -0.5), (1.5, 1.5, 1.0))], resolution=16, samples=64, margin=0)
    assert np.all(r.ao == 0.0) and np.all(r.stderr == 0)


def test_same_seed_is_bit_identical_for_any_thread_count():
    kw = dict(resolution=40, samples=64, margin=2, tile_size=8)
    a = bake_ao(plane(), [lid_mesh()], threads=1, seed=11, **kw)
    b = bake_ao(plane(), [lid_mesh()], threads=2, seed=11, **kw)
    c = bake_ao(plane(), [lid_mesh()], threads=2, seed=12, **kw)
    for name in ("ao", "stderr", "samples", "mask"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert not np.array_equal(a.ao, c.ao)


class _OneTileOnTwoThreads:
    """on_rays for a bake of a single tile on two threads. The first thread to trace waits in that
    call until the other thread has made ``wait_for`` calls, so the second thread must be tracing
    that same tile's chunks (the timeout is reached only when it never does); ``helper`` runs on
    every call of the second thread."""

    def __init__(self, wait_for=1, helper=None):
        self.cond = threading.Condition()
        self.names, self.others, self.wait_for, self.helper = [], 0, wait_for, helper

    def __call__(self, batch):
        me = threading.current_thread().name
        with self.cond:
            self.names.append(me)
            first = self.names[0] == me
            if first and len(self.names) == 1:
                self.cond.wait_for(lambda: self.others >= self.wait_for, timeout=60)
            elif not first:
                self.others += 1
                self.cond.notify_all()
        if not first and self.helper is not None:
            self.helper()


def test_threads_with_no_tile_left_trace_another_tile_chunks_bit_for_bit():
    # One replicate of 56 = 32 + 16 + 8 samples a texel, so every texel's sums add three pieces from
    # three calls, and terms that are not whole numbers (uniform directions, falloff): their sums
    # depend on the order the pieces are added in, as do the bent normals' sums.
    kw = dict(resolution=8, samples=56, replicates=1, tile_size=16, chunk_rays=256, margin=0,
              distribution="uniform", max_distance=0.6, falloff=1.0, bent_normals=True)
    calls = []
    a = bake_ao(plane(), [lid_mesh()], threads=1, on_rays=calls.append, **kw)
    # The first call's thread waits until the other has traced every other chunk: it finishes last.
    spy = _OneTileOnTwoThreads(wait_for=len(calls) - 1)
    b = bake_ao(plane(), [lid_mesh()], threads=2, on_rays=spy, **kw)
    assert len(set(spy.names)) == 2 and spy.others == len(calls) - 1
    for name in ("ao", "stderr", "samples", "mask", "bent"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert not np.all(a.ao == np.round(a.ao * 56) / 56)  # the terms are not whole numbers


def test_chunks_traced_by_another_thread_are_committed_in_their_order():
    from core.engine.scheduler import Scheduler as _Shared, run_all as _run_all

    chunks = list(range(12))
    shared = _Shared(1, None, None)
    cond, computed, by, committed = threading.Condition(), [], {}, []

    def compute(c):
        with cond:
            by[c] = threading.current_thread().name
            if c == chunks[0]:  # the first chunk finishes last (the timeout: only if no thread helps)
                cond.wait_for(lambda: len(computed) == len(chunks) - 1, timeout=60)
            computed.append(c)
            cond.notify_all()
        return c * 10

    _run_all(lambda item: shared.run_chunks(chunks, compute, lambda c, r: committed.append((c, r))),
             ["one tile"], 2, shared, None)
    assert computed[-1] == chunks[0] and len(set(by.values())) == 2
    assert committed == [(c, c * 10) for c in chunks]


def test_an_error_or_a_cancel_in_a_helping_thread_stops_the_bake():
    kw = dict(resolution=16, samples=48, tile_size=16, chunk_rays=256, margin=0, threads=2)

    def fail():
        raise ValueError("raised while helping")

    with pytest.raises(ValueError, match="raised while helping"):
        bake_ao(plane(), [lid_mesh()], on_rays=_OneTileOnTwoThreads(helper=fail), **kw)
    cancel = threading.Event()
    with pytest.raises(BakeCancelled):
        bake_ao(plane(), [lid_mesh()], on_rays=_OneTileOnTwoThreads(helper=cancel.set), cancel=cancel, **kw)


def test_result_does_not_depend_on_tiling_or_chunking():
    a = bake_ao(plane(), [lid_mesh()], resolution=20, samples=32, tile_size=8, chunk_rays=100, margin=0)
    b = bake_ao(plane(), [lid_mesh()], resolution=20, samples=32, tile_size=32, chunk_rays=1 << 16, margin=0)
    assert np.array_equal(a.ao, b.ao) and np.array_equal(a.stderr, b.stderr)


@given(st.integers(1, 8192), st.integers(1, 8192), st.integers(1, 64), st.one_of(st.none(), st.integers(1, 4096)))
@example(4096, 4096, 2, 4).via("large tiles")
@example(4096, 4096, 2, 17).via("too many samples")
@example(4096, 4096, 2, None).via("samples unknown")
@example(4096, 4096, 16, 1).via("too few large tiles per thread")
@example(2048, 2048, 2, 16).via("just enough large tiles per thread")
@example(1024, 1024, 2, 1).via("too few large tiles per thread")
@example(128, 128, 2, 128).via("a small image, halved for the threads")
@settings(max_examples=300, deadline=None)
def test_auto_tiles_cover_the_image_with_a_tile_per_thread(width, height, threads, samples):
    """The automatic tile shape: sides multiples of TILE_MULTIPLE, at most TILE_SIDE, or
    LARGE_TILE_SIDE only for few samples on an image with LARGE_TILES_PER_THREAD such tiles per
    thread; at least one tile per thread whenever the image has room for that many."""
    from core.engine.settings import (LARGE_TILE_SAMPLES, LARGE_TILE_SIDE, LARGE_TILES_PER_THREAD, TILE_MULTIPLE,
                               TILE_SIDE, auto_tile_shape)

    def side(v):
        """The image's side rounded up to a multiple of TILE_MULTIPLE."""
        return max(TILE_MULTIPLE, -(-v // TILE_MULTIPLE) * TILE_MULTIPLE)

    tw, th = auto_tile_shape(width, height, threads, samples)
    assert tw % TILE_MULTIPLE == 0 and th % TILE_MULTIPLE == 0
    large = -(-width // LARGE_TILE_SIDE) * -(-height // LARGE_TILE_SIDE)
    few = samples is not None and samples <= LARGE_TILE_SAMPLES and large >= LARGE_TILES_PER_THREAD * threads
    assert max(tw, th) <= (LARGE_TILE_SIDE if few else TILE_SIDE)
    assert tw <= side(width) and th <= side(height)
    tiles = -(-width // tw) * -(-height // th)
    if max(tw, th) > TILE_MULTIPLE:
        assert tiles >= threads
    if few:
        assert (tw, th) == (min(LARGE_TILE_SIDE, side(width)), min(LARGE_TILE_SIDE, side(height)))


def _grid(n):
    """An n x n quad grid over the unit square (2 n^2 triangles), its UVs the same square."""
    i = np.arange(n + 1)
    X, Y = np.meshgrid(i / n, i / n)
    P = np.stack([X.ravel(), Y.ravel(), np.zeros(X.size)], axis=1)
    v = (np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]).ravel()
    F = np.concatenate([np.stack([v, v + 1, v + n + 2], 1), np.stack([v, v + n + 2, v + n + 1], 1)])
    return Mesh(P, F, uvs=P[F][:, :, :2], name="grid")


def test_automatic_tiles_of_a_dense_mesh_hold_at_most_tile_triangles():
    """72200 triangles over a 64^2 image, one thread: the automatic tile (the whole image) would hold
    them all; it is halved until each holds at most TILE_TRIANGLES (by UV centre), here 64 x 32. A
    tile the caller chose is kept, and the result is the same bits either way."""
    from core.engine.settings import TILE_TRIANGLES

    grid = _grid(190)
    assert grid.triangle_count > TILE_TRIANGLES >= grid.triangle_count // 2
    blocks, chosen = [], []
    auto = bake_ao(grid, [], resolution=64, samples=2, threads=1, margin=0,
                   on_tile=lambda r, c, a: blocks.append((r.stop - r.start, c.stop - c.start)))
    fixed = bake_ao(grid, [], resolution=64, samples=2, threads=1, margin=0, tile_size=64,
                    on_tile=lambda r, c, a: chosen.append((r.stop - r.start, c.stop - c.start)))
    assert sorted(blocks) == [(32, 64), (32, 64)] and chosen == [(64, 64)]
    assert np.array_equal(auto.ao, fixed.ao) and np.array_equal(auto.samples, fixed.samples)


def test_fit_tiles_halves_the_longer_side_until_no_tile_holds_too_many_triangles():
    from core.base.request import BakeRequest
    from core.engine.settings import TILE_MULTIPLE, TILE_TRIANGLES, BakeSettings

    def settings(tile_size=None, threads=1):
        return BakeSettings.of(BakeRequest(resolution=512, samples=16, margin=0, threads=threads, tile_size=tile_size))

    rng = np.random.default_rng(0)
    # Uniform over the image: a 256^2 tile holds 1/4 of them, 256 x 128 1/8, 128^2 1/16.
    spread = rng.random((2, 12 * TILE_TRIANGLES)) * 512
    s = settings()
    assert s.tile_shape == (256, 256)
    assert s.fit_tiles(spread).tile_shape == (128, 128)           # 3, then 1.5, then 0.75 x TILE_TRIANGLES
    assert s.fit_tiles(spread[:, ::2]).tile_shape == (256, 128)   # 1.5, then 0.75
    assert s.fit_tiles(spread[:, :TILE_TRIANGLES]) is s           # few enough triangles: unchanged
    assert settings(tile_size=256).fit_tiles(spread).tile_shape == (256, 256)  # the caller's tiles
    heap = np.full((2, TILE_TRIANGLES + 1), 3.5)          # all in one texel: down to the smallest tile
    assert s.fit_tiles(heap).tile_shape == (TILE_MULTIPLE, TILE_MULTIPLE)
    fitted = s.fit_tiles(spread)
    x, y = spread.astype(np.int64)
    counts = np.bincount((y // fitted.tile_shape[1]) * (512 // fitted.tile_shape[0]) + x // fitted.tile_shape[0])
    assert counts.max() <= TILE_TRIANGLES


def test_mesh_arrays_in_any_memory_layout_make_the_same_mesh_and_bake():
    """Fortran-ordered, reversed and fancy-indexed inputs (what an add-on's corner reordering for a
    mirrored object gives: numpy's advanced indexing picks its own layout) make the same Mesh, bit
    for bit, as C-ordered copies, and the same bake."""
    rng = np.random.default_rng(3)
    ground = plane()
    P, F, UV = ground.positions, ground.triangles, ground.uvs
    N = rng.normal(size=(len(F), 3, 3)) * 0.1 + [0.0, 0.0, 1.0]
    N[0, 1] = 0.0  # a zero corner normal falls back to the face normal
    order = [0, 2, 1]
    ref = Mesh(P, F[:, order].copy(), UV[:, order].copy(), normals=N[:, order].copy(), name="c")
    layouts = {
        "fancy": (P, F[:, order], UV[:, order], N[:, order]),
        "fortran": (np.asfortranarray(P), np.asfortranarray(F[:, order]), np.asfortranarray(UV[:, order]),
                    np.asfortranarray(N[:, order])),
        "transposed": (P.T.copy().T, F[:, order].T.copy().T, UV[:, order].transpose(2, 1, 0).copy().transpose(2, 1, 0),
                       N[:, order].transpose(2, 0, 1).copy().transpose(1, 2, 0)),
    }
    want = bake_ao(ref, [lid_mesh()], resolution=16, samples=16, margin=2)
    for name, (p, f, uv, n) in layouts.items():
        m = Mesh(p, f, uv, normals=n, name=name)
        for attr in ("positions", "triangles", "uvs", "normals", "face_normals", "areas"):
            assert np.array_equal(getattr(m, attr), getattr(ref, attr)), (name, attr)
        got = bake_ao(m, [lid_mesh()], resolution=16, samples=16, margin=2)
        assert np.array_equal(got.ao, want.ao) and np.array_equal(got.mask, want.mask), name


def test_adaptive_sampling_stops_open_texels_early_and_converges_the_rest():
    big = plane(-1.0, -1.0, 2.0, 2.0)
    target = 0.05
    # Texels whose whole window sees no variance (the open plane around the lid's shadow, limited
    # by the distance) stop at the minimum; the shadow's texels go on until their interval is
    # within the target.
    r = bake_ao(big, [lid_mesh()], resolution=32, samples=1024, min_samples=16, target_error=target,
                max_distance=0.5, margin=0)
    open_ = r.ao == 1.0
    assert open_.sum() > 100 and np.median(r.samples[open_]) == 16
    under = r.ao < 0.9
    assert under.any() and np.all(r.samples[under] > 16)
    assert r.rays < 0.25 * 1024 * 32 * 32
    # Texels stop on their interval at the time (pooled over neighbours that may go on sampling, so
    # the final error map can differ a little): nearly every texel reached the cap or the target.
    assert np.mean((r.samples == 1024) | (1.96 * r.stderr <= target)) > 0.97


@pytest.mark.parametrize("source", ["independent", "sobol"])
def test_agreeing_samples_beside_varying_ones_do_not_stop_a_texel_early(source):
    # A plane under a large lid at h = 0.3 with the AO distance d = 0.3077: AO = (h / d)^2 = 0.95
    # everywhere. With 16 independent samples, 44% of the texels see no hit at all; such a texel is
    # 0.05 off, more than the target 0.03. It must not stop on its own agreeing samples: it takes
    # the variance of its neighbours, whose samples vary, and keeps sampling.
    h, d, target = 0.3, 0.3077, 0.03
    r = bake_ao(plane(), [lid_mesh(BIG_LID)], resolution=32, samples=4096, min_samples=16, target_error=target,
                max_distance=d, margin=0, seed=9, source=source)
    assert r.samples.min() > 16
    miss = np.mean(np.abs(r.ao - (h / d) ** 2) > target)
    assert miss <= 0.05 + 3 * math.sqrt(0.05 * 0.95 / r.ao.size), miss


def test_without_replicates_agreeing_samples_do_not_stop_a_texel_early():
    # One randomisation per texel: the interval is Agresti and Coull's, 16 open rays of 16 do not
    # prove AO = 1 to +-0.05: the texel keeps sampling (to 64).
    r = bake_ao(plane(), resolution=8, samples=1024, min_samples=16, target_error=0.05, margin=0, replicates=1)
    assert np.all(r.samples == 64) and np.all(r.ao == 1.0)


def test_adaptive_sampling_keeps_its_promise_against_the_exact_answer(lid_truth):
    # The target is the half-width of a 95% interval: at most about 5% of texels may miss the exact
    # AO by more than the target (the intervals are conservative, so usually far fewer do).
    W, H, truth = lid_truth
    target = 0.03
    for source in ("independent", "sobol"):
        r = bake_ao(plane(), [lid_mesh()], resolution=(W, H), samples=4096, min_samples=16, target_error=target,
                    source=source, margin=0, seed=7)
        miss = np.mean(np.abs(r.ao - truth) > target)
        m = truth.size
        assert miss <= 0.05 + 3 * math.sqrt(0.05 * 0.95 / m), (source, miss)
        assert r.samples.max() < 4096  # nothing needed the cap


def test_margin_keeps_covered_texels_and_fills_the_border():
    half = Mesh(np.array([[0, 0, 0], [0.5, 0, 0], [0.5, 1, 0], [0, 1, 0]], float), np.array([[0, 1, 2], [0, 2, 3]]),
                uvs=np.array([[[0, 0], [0.5, 0], [0.5, 1]], [[0, 0], [0.5, 1], [0, 1]]]), name="half")
    a = bake_ao(half, [lid_mesh()], resolution=32, samples=32, margin=0)
    b = bake_ao(half, [lid_mesh()], resolution=32, samples=32, margin=4)
    assert np.array_equal(a.ao[a.mask], b.ao[b.mask]) and np.array_equal(a.mask, b.mask)
    cols = np.flatnonzero(a.mask.any(axis=0))
    last = cols.max()
    assert last == 15
    ring = b.ao[:, last + 1:last + 5]
    # Each ring averages already-filled neighbours, so it stays within the covered values' range.
    assert np.all(ring >= a.ao[a.mask].min()) and np.all(ring <= a.ao[a.mask].max())
    # The first ring takes the mean of its covered 8-neighbours: the edge column's rows i-1, i, i+1.
    edge = np.pad(a.ao[:, last].astype(float), 1)
    cnt = np.pad(np.ones(32), 1)
    want = (edge[:-2] + edge[1:-1] + edge[2:]) / (cnt[:-2] + cnt[1:-1] + cnt[2:])
    np.testing.assert_allclose(ring[:, 0], want, rtol=1e-6)
    assert np.all(b.ao[:, last + 5:] == 0)


def test_cancel_raises_and_returns_nothing():
    ev = threading.Event()
    calls = []

    def progress(f):
        calls.append(f)
        ev.set()

    with pytest.raises(BakeCancelled):
        bake_ao(plane(), [lid_mesh()], resolution=64, samples=64, progress=progress, cancel=ev, chunk_rays=1024)
    with pytest.raises(BakeCancelled):
        bake_ao(plane(), resolution=8, samples=4, cancel=lambda: True)


def test_progress_is_monotone_and_ends_at_one():
    seen = []
    bake_ao(plane(), [lid_mesh()], resolution=32, samples=16, progress=seen.append, chunk_rays=256, tile_size=8)
    assert seen[-1] == 1.0 and all(b >= a for a, b in zip(seen, seen[1:]))


def test_on_tile_reports_final_blocks():
    blocks = []
    # Tiles are multiples of 16 texels (the blocks error estimates are pooled in): 8 becomes 16.
    r = bake_ao(plane(), [lid_mesh()], resolution=40, samples=8, tile_size=8, margin=0,
                on_tile=lambda rows, cols, block: blocks.append((rows, cols, block)))
    assert len(blocks) == 9
    for rows, cols, block in blocks:
        assert np.array_equal(block, r.ao[rows, cols])


def test_rasteriser_covers_exactly_the_uv_area():
    rng = np.random.default_rng(4)
    uv = rng.random((40, 3, 2))
    P = rng.random((120, 3))
    m = Mesh(P, np.arange(120).reshape(40, 3), uvs=uv, name="soup")
    W = H = 16
    tris = prepare(m, W, H)
    frag = rasterize_tile(tris, np.flatnonzero(tris.valid), W, H, 0, 0, W, H)
    # The area of the corners the UV triangles keep (float32, as Blender's UVs are), in texels.
    xy = tris.corners
    e1, e2 = xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0]
    uv_area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    assert frag.coverage.sum() == pytest.approx(uv_area, rel=1e-9)
    assert uv_area == pytest.approx(0.5 * np.abs((uv[:, 1, 0] - uv[:, 0, 0]) * (uv[:, 2, 1] - uv[:, 0, 1])
                                                 - (uv[:, 1, 1] - uv[:, 0, 1]) * (uv[:, 2, 0] - uv[:, 0, 0])).sum()
                                    * W * H, rel=1e-6)
    # Every sub-triangle lies inside its texel square.
    tex = frag.texels[frag.sub_texel]
    x0, y0 = tex % W, tex // W
    assert np.all(frag.sub_xy[..., 0] >= x0[:, None] - 1e-9) and np.all(frag.sub_xy[..., 0] <= x0[:, None] + 1 + 1e-9)
    assert np.all(frag.sub_xy[..., 1] >= y0[:, None] - 1e-9) and np.all(frag.sub_xy[..., 1] <= y0[:, None] + 1 + 1e-9)


def test_texels_cut_by_an_edge_are_covered_and_sampled_on_the_surface():
    # One triangle whose hypotenuse cuts texels diagonally: every texel it touches is covered, and
    # the AO of a surface point is 1 anywhere on this open triangle.
    m = Mesh(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2]]),
             uvs=np.array([[[0.01, 0.01], [0.93, 0.01], [0.01, 0.93]]]), name="tri")
    r = bake_ao(m, resolution=16, samples=8, margin=0)
    x = (np.arange(16) + 0.5) / 16
    U, V = np.meshgrid(x, x)
    centre_inside = (U > 0.01) & (V > 0.01) & (U + V < 0.94)
    assert np.all(r.mask[centre_inside])
    assert r.mask.sum() > centre_inside.sum()  # edge texels whose centres are outside count too
    assert np.all(r.ao[r.mask] == 1.0)


def test_report_counts_degenerate_outside_and_overlapping_uvs():
    P = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3], [0, 1, 2], [0, 1, 3]])
    uv = np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]], [[0, 0], [1, 0], [1, 1]],
                   [[0.2, 0.2], [0.2, 0.2], [0.2, 0.2]]], float)
    uv[1] += [0.0, 0.0]
    r = bake_ao(Mesh(P, F, uv, name="m"), resolution=8, samples=4, margin=0)
    assert r.report["degenerate_uv_triangles"] == 1
    assert r.report["overlapping_texels"] > 0
    uv2 = np.array([[[0, 0], [1.5, 0], [1.5, 1]], [[0, 0], [1, 1], [0, 1]]], float)
    r2 = bake_ao(Mesh(P, F[:2], uv2, name="m2"), resolution=8, samples=4, margin=0)
    assert r2.report["uv_outside_triangles"] == 1


def test_written_file_has_the_right_orientation_and_metadata(tmp_path):
    from core.files.imageio import read_image, write_ao

    half = Mesh(np.array([[0, 0, 0], [1, 0, 0], [1, 0.5, 0], [0, 0.5, 0]], float), np.array([[0, 1, 2], [0, 2, 3]]),
                uvs=np.array([[[0, 0], [1, 0], [1, 0.5]], [[0, 0], [1, 0.5], [0, 0.5]]]), name="bottom")
    r = bake_ao(half, resolution=8, samples=8, margin=0, seed=9)
    assert r.mask[0].all() and not r.mask[-1].any()  # row 0 is v = 0
    write_ao(tmp_path / "ao.exr", r, bits="float")
    img, meta = read_image(tmp_path / "ao.exr")
    assert np.array_equal(img, r.ao)
    assert int(meta["samples"]) == 8 and int(meta["seed"]) == 9 and meta["sample_source"] == "sobol"
    import OpenImageIO as oiio

    raw = oiio.ImageBuf(str(tmp_path / "ao.exr")).get_pixels(oiio.FLOAT)
    assert raw[-1].min() == 1.0 and raw[0].max() == 0.0  # the file's first scanline is the top row


@pytest.mark.parametrize("samples", [4, 64])
def test_a_block_resting_on_the_surface_occludes_it_completely(samples):
    # The block's bottom face lies in the plane: the plane under it is in contact, AO 0, as in Cycles,
    # even though the block is taller than max_distance (rays pushed off the surface would start
    # inside it and find nothing within reach). Found by comparing with Cycles (bench/agreement.py).
    r = bake_ao(plane(), [box((0.3, 0.3, 0.0), (0.7, 0.7, 0.6))], resolution=32, samples=samples,
                max_distance=0.5, margin=0)
    assert np.all(r.ao[11:20, 11:20] == 0.0)
    assert r.ao[:8].mean() > 0.8  # away from the block the plane stays open
    # A block floating 0.002 above, with rays reaching 0.001: not in contact, nothing within reach.
    g = bake_ao(plane(), [box((0.3, 0.3, 0.002), (0.7, 0.7, 0.6))], resolution=32, samples=samples,
                max_distance=0.001, margin=0)
    assert np.all(g.ao == 1.0)


def test_contact_probes_take_each_triangle_own_normal():
    # One mesh, a wall (normal +x, its triangles first) and a floor (normal +z), each half of the UV
    # square. The block resting on the floor puts the floor under it in contact: AO 0 there. Each
    # sample's probe crosses the surface along its own triangle's normal; along the wall's normal
    # it would run within the floor's plane and find nothing.
    P = np.array([[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 0, 1],  # wall x = 0
                  [0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)  # floor z = 0
    F = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7]])
    uv = np.array([[0, 0], [0.5, 0], [0.5, 1], [0, 1], [0.5, 0], [1, 0], [1, 1], [0.5, 1]], float)
    corner = Mesh(P, F, uv[F], name="corner")
    assert corner.face_normals[0] @ [1, 0, 0] > 0.99 and corner.face_normals[2] @ [0, 0, 1] > 0.99
    r = bake_ao(corner, [box((0.4, 0.3, 0.0), (0.8, 0.7, 0.6))], resolution=32, samples=64, max_distance=0.1,
                margin=0)
    # Floor texels wholly under the block: u = 0.5 + x / 2 in [0.7, 0.9], v = y in [0.3, 0.7].
    under = r.ao[11:21, 23:28]
    assert np.all(under == 0.0), under
    assert r.ao[2:8, 18:30].mean() > 0.8  # the floor in front of the block stays open


def _rotated_box(centre, half, height, angle):
    c, s_ = math.cos(angle), math.sin(angle)
    b = box((-half, -half, 0.0), (half, half, height))
    P = b.positions @ np.array([[c, s_, 0], [-s_, c, 0], [0, 0, 1]]) + [centre[0], centre[1], 0.0]
    return Mesh(P, b.triangles, name="turned box")


@pytest.mark.parametrize("resolution", [32, 96])
def test_every_texel_in_contact_is_found_split_texels_too(resolution):
    # Contact probes (core.geometry.surface.contact_texels) go to the corners and centre of texels inside
    # one triangle and to the corners and centroid of every sub-triangle of split texels. The
    # plane's two triangles are separate UV islands, so split texels run along their diagonal,
    # under a turned box. Every texel under a resting box (or one hovering within the probes'
    # reach), split or not, is in contact: AO exactly 0, though the boxes are taller than the rays
    # reach; the box hovering 0.05 above is not.
    halves = plane()
    uvs = halves.uvs.copy()
    uvs[1] = uvs[1] * 0.98 + 0.01  # the second triangle's island a little apart
    halves = Mesh(halves.positions, halves.triangles, uvs, name="halves")
    turned = ((0.55, 0.45), 0.12, 0.5)
    # Boxes in contact: one resting, one 1e-6 above (within the probes' reach); and one hovering.
    touching = [((0.2, 0.55, 0.0), (0.45, 0.8, 0.3)), ((0.7, 0.1, 1e-6), (0.9, 0.3, 0.3))]
    occluders = [box(lo, hi) for lo, hi in touching] + [_rotated_box(turned[0], turned[1], 0.3, turned[2]),
                                                         box((0.1, 0.05, 0.05), (0.3, 0.25, 0.3))]
    # The bake's own estimates (Fix Seams, after it, may move texels along the diagonal seam).
    kw = dict(resolution=resolution, samples=32, max_distance=0.2, margin=0, threads=2, tile_size=32, fix_seams=False)
    r = bake_ao(halves, occluders, **kw)

    def under(p):
        """Whether points (..., 2) of the plane lie under a box in contact (1e-3 inside its edges)."""
        x, y = p[..., 0], p[..., 1]
        c, s_ = math.cos(turned[2]), math.sin(turned[2])
        dx, dy = x - turned[0][0], y - turned[0][1]
        u, v = c * dx + s_ * dy, -s_ * dx + c * dy  # the turned box's own axes
        e = 1e-3
        out = (np.abs(u) < turned[1] - e) & (np.abs(v) < turned[1] - e)
        for lo, hi in touching:
            out |= (x > lo[0] + e) & (x < hi[0] - e) & (y > lo[1] + e) & (y < hi[1] - e)
        return out

    i, j = np.mgrid[0:resolution, 0:resolution]
    corners = np.stack([np.stack([(j + a) / resolution, (i + b) / resolution], -1) for a in (0, 1) for b in (0, 1)])
    # Texel corners as points of either triangle (the second island's map undone).
    inside = np.all(under(corners) & under((corners - 0.01) / 0.98), axis=0)
    assert inside.sum() > 0.1 * resolution ** 2
    np.testing.assert_array_equal(r.ao[inside], 0.0)
    split = np.zeros(resolution * resolution, bool)
    uvt = prepare(halves, resolution, resolution)
    frag = rasterize_tile(uvt, np.arange(2), resolution, resolution, 0, 0, resolution, resolution)
    split[frag.texels[frag.full_tri == -1]] = True
    assert (split.reshape(inside.shape) & inside).sum() >= resolution // 16  # split texels among them
    assert r.ao[(r.mask & ~inside)].mean() > 0.5  # elsewhere the plane is mostly open


def test_contact_is_found_on_triangles_that_no_texel_lies_inside():
    # Every texel of this 2 x 2 image is split (the UV island [0.05, 0.95]^2 leaves a border in each):
    # the plane's triangles reach the contact probes through split texels alone. A block rests on
    # the middle of the plane; within the rays' reach of 0.01 only contact can occlude the part of
    # each texel under it, 0.0324 / 0.2025 = 16% of its covered area: AO about 0.84 (without the
    # probes, about 0.99). Tolerance: 4 binomial standard deviations of 1024 samples (an upper bound
    # for the stratified positions), plus 0.02 for rays that meet the block's walls.
    p = plane()
    halves = Mesh(p.positions, p.triangles, p.uvs * 0.9 + 0.05, name="bordered")
    frag = rasterize_tile(prepare(halves, 2, 2), np.arange(2), 2, 2, 0, 0, 2, 2)
    assert len(frag.texels) == 4 and np.all(frag.full_tri == -1)
    r = bake_ao(halves, [box((0.3, 0.3, 0.0), (0.7, 0.7, 0.6))], resolution=2, samples=1024, max_distance=0.01,
                margin=0)
    under = 0.0324 / 0.2025
    tol = 4 * math.sqrt(under * (1 - under) / 1024)
    assert np.all(r.ao > 1 - under - tol - 0.02) and np.all(r.ao < 1 - under + tol), r.ao


def _dilate_by_hand(values, mask, margin):
    """Ring by ring, texel by texel: each empty texel touching filled ones (8-neighbourhood) takes the
    mean of those filled before this ring. Returns (values, filled)."""
    v = np.where(mask, values, 0.0).astype(np.float64)
    filled = mask.copy()
    h, w = mask.shape
    for _ in range(margin):
        ring = {}
        for i in range(h):
            for j in range(w):
                if filled[i, j]:
                    continue
                nb = [v[i + di, j + dj] for di in (-1, 0, 1) for dj in (-1, 0, 1)
                      if (di or dj) and 0 <= i + di < h and 0 <= j + dj < w and filled[i + di, j + dj]]
                if nb:
                    ring[i, j] = sum(nb) / len(nb)
        for p, x in ring.items():
            v[p] = x
            filled[p] = True
    return v, filled


@pytest.mark.parametrize("margin", [1, 2, 5, 30])
def test_margin_is_the_ring_by_ring_mean_of_filled_neighbours(margin):
    """dilate against a texel-by-texel reference, on islands touching the image's edges, holes and
    single texels; texels beyond the margin keep their values."""
    from core.geometry.margin import dilate

    rng = np.random.default_rng(7 + margin)
    mask = np.zeros((37, 29), bool)
    for _ in range(6):
        y, x = rng.integers(-3, 37), rng.integers(-3, 29)
        mask[max(y, 0):y + rng.integers(1, 9), max(x, 0):x + rng.integers(1, 9)] = True
    mask[20, 3] = mask[0, 28] = True
    mask[5:9, 10:14] = True
    mask[6:8, 11:13] = False  # a hole
    values = rng.random((37, 29)).astype(np.float32)  # under the empty texels too: kept beyond the margin
    want, filled = _dilate_by_hand(values, mask, margin)
    for threads in (1, 2):
        got = dilate(values, mask, margin, threads=threads)
        np.testing.assert_allclose(got[filled], want[filled], rtol=2e-6)
        assert np.array_equal(got[~filled], values[~filled])
    if margin == 1:
        assert (~filled).any()  # some texels lie beyond the margin
    if margin == 30:
        assert filled.all()


@pytest.mark.parametrize("margin", [3, 16])
def test_margin_does_not_depend_on_the_number_of_threads(margin):
    # The margin is computed in bands of rows (each with `margin` rows of its neighbours) when
    # threads allow: any number of bands gives the same texels as one, and the first ring is the
    # mean of its covered 8-neighbours.
    from core.geometry.margin import dilate

    rng = np.random.default_rng(margin)
    mask = np.zeros((400, 300), bool)
    for _ in range(40):
        y, x = rng.integers(0, 400), rng.integers(0, 300)
        mask[y:y + rng.integers(1, 40), x:x + rng.integers(1, 40)] = True
    values = np.where(mask, rng.random((400, 300)), 0).astype(np.float32)
    one = dilate(values, mask, margin, threads=1)
    for threads in (2, 3, 5):
        assert np.array_equal(dilate(values, mask, margin, threads=threads), one), threads
    assert np.array_equal(one[mask], values[mask])
    ring = ~mask & (np.pad(mask, 1)[:-2, :-2] | np.pad(mask, 1)[:-2, 1:-1] | np.pad(mask, 1)[:-2, 2:]
                    | np.pad(mask, 1)[1:-1, :-2] | np.pad(mask, 1)[1:-1, 2:]
                    | np.pad(mask, 1)[2:, :-2] | np.pad(mask, 1)[2:, 1:-1] | np.pad(mask, 1)[2:, 2:])
    pv, pm = np.pad(values.astype(float), 1), np.pad(mask, 1).astype(float)
    s = sum(pv[1 + dy:401 + dy, 1 + dx:301 + dx] * pm[1 + dy:401 + dy, 1 + dx:301 + dx]
            for dy in (-1, 0, 1) for dx in (-1, 0, 1))
    c = sum(pm[1 + dy:401 + dy, 1 + dx:301 + dx] for dy in (-1, 0, 1) for dx in (-1, 0, 1))
    np.testing.assert_allclose(one[ring], (s / np.maximum(c, 1))[ring], rtol=1e-6)
    reach = mask.copy()
    for _ in range(margin):  # texels within `margin` (8-neighbour steps) of a covered one
        p = np.pad(reach, 1)
        reach = reach | p[:-2, :-2] | p[:-2, 1:-1] | p[:-2, 2:] | p[1:-1, :-2] | p[1:-1, 2:] | p[2:, :-2] | p[2:, 1:-1] | p[2:, 2:]
    assert np.all(one[~reach] == 0) and np.all(one[reach & ~mask] > 0)


@pytest.mark.parametrize("margin", [2, 16])
def test_margin_bands_of_any_height_give_the_same_texels(monkeypatch, margin):
    """An image cut into many bands of rows (BAND_TEXELS small, one thread or three) gives the bits
    of one band, with values under the empty texels beyond the margin kept; the result written into
    the values themselves (``out=values``, as the bake does) or into another array is the same."""
    from core.geometry import margin as M

    rng = np.random.default_rng(40 + margin)
    h, w = 1300, 90
    mask = np.zeros((h, w), bool)
    for _ in range(60):
        y, x = rng.integers(0, h), rng.integers(0, w)
        mask[y:y + rng.integers(1, 30), x:x + rng.integers(1, 30)] = True
    values = rng.random((h, w)).astype(np.float32)
    monkeypatch.setattr(M, "BAND_TEXELS", h * w)
    one = M.dilate(values, mask, margin, threads=1)
    want, filled = _dilate_by_hand(values, mask, margin)
    np.testing.assert_allclose(one[filled], want[filled], rtol=2e-6)
    for rows in (64, 97, 300):
        monkeypatch.setattr(M, "BAND_TEXELS", rows * w)
        for threads in (1, 3):
            assert np.array_equal(M.dilate(values, mask, margin, threads=threads), one), (rows, threads)
        into = np.full_like(values, np.nan)
        assert M.dilate(values, mask, margin, out=into) is into and np.array_equal(into, one)
        same = values.copy()
        assert M.dilate(same, mask, margin, out=same) is same and np.array_equal(same, one)
    # Islands of exact zeros (fully occluded) give a margin of exact zeros: nothing the rings keep
    # as bookkeeping leaks into the values.
    zeros = np.zeros_like(values)
    assert not M.dilate(zeros, mask, margin, threads=1).any()


def test_channels_share_the_margin_rings_and_get_each_the_one_channel_bits(monkeypatch):
    """dilate of (H, W, C) values equals dilate of each channel alone, bit for bit, in any bands and
    threads; margin_texels lists exactly the texels dilate fills, with their values."""
    from core.geometry import margin as M

    rng = np.random.default_rng(11)
    h, w = 700, 60
    mask = np.zeros((h, w), bool)
    for _ in range(30):
        y, x = rng.integers(0, h), rng.integers(0, w)
        mask[y:y + rng.integers(1, 25), x:x + rng.integers(1, 25)] = True
    values = np.where(mask[..., None], rng.standard_normal((h, w, 3)), 0).astype(np.float32)
    for rows, threads in ((h, 1), (64, 1), (90, 2)):
        monkeypatch.setattr(M, "BAND_TEXELS", rows * w)
        got = M.dilate(values, mask, 5, threads=threads)
        for c in range(3):
            assert np.array_equal(got[..., c], M.dilate(np.ascontiguousarray(values[..., c]), mask, 5, threads=threads))
        idx, vals = M.margin_texels(values, mask, 5, threads=threads)
        assert len(np.unique(idx)) == len(idx) and not mask.reshape(-1)[idx].any()
        assert np.array_equal(got.reshape(-1, 3)[idx], vals)
        changed = np.flatnonzero(np.any(got != values, axis=-1))
        assert set(changed) <= set(idx) and len(idx) > 0
    with pytest.raises(ValueError):
        M.dilate(values, mask, 5, out=np.zeros((h, w, 3), np.float32)[:, ::-1])
