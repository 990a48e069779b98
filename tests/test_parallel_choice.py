"""Threads or worker processes: a bake with automatic workers and threads runs where the model predicts
it sooner (core.execution.cost.choose_parallel), from what the machine and the pool give (cores, a pool
running or not, the scene its workers keep), and says where and why in its report. Speed is never timed
here: the choice is held against the model's own predictions, and the bits against one thread."""

import numpy as np
import pytest

from core import Mesh, bake_ao
from core.base.request import BakeRequest
from core.engine.settings import BakeSettings
from core.execution import cost, executor, pool
from core.pipeline import run as run_mod


def grid(n):
    """An n x n grid over the unit square, its UVs the square: 2 n^2 triangles."""
    t = np.linspace(0.0, 1.0, n + 1)
    x, y = np.meshgrid(t, t)
    p = np.stack([x.ravel(), y.ravel(), 0.05 * np.sin(6 * x.ravel()) * np.cos(5 * y.ravel())], 1)
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    f = np.concatenate([np.stack([i, i + 1, i + n + 2], -1).reshape(-1, 3),
                        np.stack([i, i + n + 2, i + n + 1], -1).reshape(-1, 3)])
    return Mesh(p, f, uvs=p[f][:, :, :2], name="grid")


def lid():
    p = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float) * [0.6, 0.6, 0] + [0.2, 0.2, 0.3]
    return Mesh(p, np.array([[0, 1, 2], [0, 2, 3]]), name="lid")


WORKS = [cost.Work(128 * 128 * 0.6, 128, (4000, 26, 0), 128, 128, 600_000),
         cost.Work(512 * 512 * 0.5, 128, (4000, 26, 0), 512, 512, 600_000),
         cost.Work(1024 * 1024, 32, (524288, 0, 0), 1024, 1024, 82_000_000),
         cost.Work(4096 * 4096 * 0.5, 1, (4000, 0, 0), 4096, 4096, 600_000),
         cost.Work(2048 * 2048, 256, (10_000_000, 0, 0), 2048, 2048, 10**9)]


@pytest.mark.parametrize("work", WORKS)
@pytest.mark.parametrize("cores", [2, 4, 16])
@pytest.mark.parametrize("start, kept", [(0.0, True), (0.0, False), (0.7, False)])
def test_the_choice_is_the_option_the_model_predicts_sooner(work, cores, start, kept):
    c = cost.choose_parallel(work, cores, (cores, 1), start, kept, tiles=2 * cores)
    here = sum(cost.parallel_seconds(work, 1, cores).values())
    there = sum(cost.parallel_seconds(work, cores, 1, start, kept, 2 * cores).values())
    assert c.predicted == {"threads": pytest.approx(here), "processes": pytest.approx(there)}
    assert (c.processes, c.threads) == ((1, cores) if here <= there else (cores, 1))
    assert c.options == {"threads": (1, cores), "processes": (cores, 1)}
    r = c.report()
    assert r["processes"] == c.processes and r["threads"] == c.threads and r["options"]["processes"] == [cores, 1]
    # the sentence says where, and the two predictions, as the summary prints them
    assert r["why"].startswith(f"{cores} threads of this process" if c.processes == 1 else f"{cores} worker processes")
    assert f"{min(here, there):.2f} s against {max(here, there):.2f} s" in r["why"] or max(here, there) >= 10


def test_the_model_follows_what_each_option_costs():
    small, dense = WORKS[0], WORKS[2]
    # a pool not running costs its start; scenes kept cost no Embree build; the job goes to each worker
    cold = cost.parallel_seconds(small, 2, 1, pool_start=0.7)
    warm = cost.parallel_seconds(small, 2, 1, pool_start=0.0, scene_kept=True)
    assert cold["start"] == 0.7 and warm["start"] == 0.0 and warm["workers"] < cold["workers"]
    assert cost.parallel_seconds(dense, 4, 1)["send"] == pytest.approx(2 * cost.parallel_seconds(dense, 2, 1)["send"])
    # this process's threads pay no start, send or tail; their tiles wait for each other's Python
    here = cost.parallel_seconds(dense, 1, 2)
    assert set(here) == {"parent", "scene", "tiles"}
    assert here["tiles"] > cost.parallel_seconds(dense, 2, 1)["tiles"]
    assert cost.speedup(1, 1) == 1.0 and cost.speedup(2, 1) > cost.speedup(1, 2) > 1.0
    # on many cores the interpreter lock decides: a large bake goes to a running pool (one that must
    # start first pays its start), a tiny one with no pool running stays here
    assert cost.choose_parallel(WORKS[1], 16, (16, 1), 0.0, tiles=32).processes == 16
    assert cost.choose_parallel(WORKS[4], 16, (16, 1), 0.7, tiles=32).processes == 16
    tiny = cost.Work(32 * 32, 4, (200, 0, 0), 32, 32, 20_000)
    c = cost.choose_parallel(tiny, 16, (16, 1), 0.7, tiles=32)
    assert c.processes == 1 and "starting them" in c.why
    # one copy of the scene in memory, or one core: threads here, no weighing
    c = cost.choose_parallel(WORKS[4], 8, (1, 8))
    assert (c.processes, c.threads) == (1, 8) and "memory" in c.why and "options" not in c.report()


def test_the_reason_names_the_largest_part_of_the_difference():
    dense = WORKS[2]
    c = cost.choose_parallel(dense, 2, (2, 1), 0.0, False, tiles=16)
    there = cost.parallel_seconds(dense, 2, 1, 0.0, False, 16)
    if c.processes == 1:
        extra = {k: there[k] for k in ("start", "send", "workers", "tail")}
        words = {"start": "starting them", "send": "sending each the meshes", "workers": "each one's own set-up",
                 "tail": "the last tiles"}
        assert words[max(extra, key=extra.get)] in c.why
    c = cost.choose_parallel(dense, 2, (2, 1), 5.0, False, tiles=16)
    assert c.processes == 1 and "starting them (5.00 s)" in c.why


def settings(**kw):
    return BakeSettings.of(BakeRequest(**dict(dict(resolution=64, samples=16, max_distance=1.0), **kw)))


def test_auto_weighs_the_pool_it_would_run_on(monkeypatch):
    work = WORKS[1]
    s = settings(resolution=512, samples=128)
    monkeypatch.setattr(executor, "cpu_count", lambda: 16)
    monkeypatch.setattr(executor, "auto_workers", lambda triangles: (16, 1))
    seen = []

    def state(workers, threads, remote):
        seen.append((workers, threads, remote))
        return states.pop(0)

    monkeypatch.setattr(executor, "pool_state", state)
    remote = run_mod.REMOTE
    tiles = executor._tile_count(work, 16, s)
    # running, with this bake's scene kept: no start, no Embree build in the workers
    states = [("running", "abc")]
    c = executor.parallel_of("auto", None, s, work.triangles, work, remote, lambda: "abc")
    assert seen == [(16, 1, remote)]
    assert c.predicted["processes"] == pytest.approx(sum(cost.parallel_seconds(work, 16, 1, 0.0, True, tiles).values()))
    # running another scene: the workers build theirs
    states = [("running", "other")]
    c = executor.parallel_of("auto", None, s, work.triangles, work, remote, lambda: "abc")
    assert c.predicted["processes"] == pytest.approx(sum(cost.parallel_seconds(work, 16, 1, 0.0, False, tiles).values()))
    # none running: the start measured in this process, else the model's
    states = [("none", 2.5), ("none", None)]
    c = executor.parallel_of("auto", None, s, work.triangles, work, remote, None)
    assert c.predicted["processes"] == pytest.approx(sum(cost.parallel_seconds(work, 16, 1, 2.5, False, tiles).values()))
    c = executor.parallel_of("auto", None, s, work.triangles, work, remote, None)
    start = cost.WORKER_START_SECONDS
    assert c.predicted["processes"] == pytest.approx(sum(cost.parallel_seconds(work, 16, 1, start, False, tiles).values()))
    # a pool whose self-test failed: this process's threads, saying why
    states = [("failed", "worker process 0 baked the self-test differently")]
    c = executor.parallel_of("auto", None, s, work.triangles, work, remote, None)
    assert (c.processes, c.threads) == (1, 16) and "self-test differently" in c.why


def test_workers_or_threads_given_are_taken_as_asked(monkeypatch):
    monkeypatch.setattr(executor, "pool_state", lambda *a: pytest.fail("a given count weighs nothing"))
    work = WORKS[0]
    s = settings(threads=2)
    assert executor.parallel_of(1, 2, s, 100, work, run_mod.REMOTE).report() == {
        "processes": 1, "threads": 2, "why": "2 threads of this process, as asked"}
    monkeypatch.setattr(executor, "cpu_count", lambda: 4)
    c = executor.parallel_of(3, None, s, 100, work, run_mod.REMOTE)
    assert (c.processes, c.threads) == (3, 1) and c.why == "3 worker processes of 1 thread each, as asked"
    c = executor.parallel_of(6, None, s, 100, work, run_mod.REMOTE)  # more than the cores: as many as they hold
    assert (c.processes, c.threads) == (4, 1) and c.why.startswith("4 worker processes of 1 thread each, not the 6 asked")
    c = executor.parallel_of("auto", 2, s, 100, work, run_mod.REMOTE)
    assert c.threads == 2 and "options" not in c.report()
    # no work given (callers that price a bake before it is set up): auto_workers' processes
    assert executor.processes_of("auto", None, s, 100) == executor.auto_workers(100)


def test_an_automatic_bake_reports_its_choice_and_bakes_the_same_bits():
    target, occ = grid(24), [lid()]
    kw = dict(resolution=48, samples=16, max_distance=1.0, margin=2)
    ref = bake_ao(target, occ, threads=1, **kw)
    for _ in range(2):  # the second with the pool running if the first started it
        r = bake_ao(target, occ, workers="auto", **kw)
        assert np.array_equal(r.ao, ref.ao) and np.array_equal(r.stderr, ref.stderr)
        p = r.report.parallel
        assert set(p["predicted_seconds"]) == {"threads", "processes"}
        chosen = "threads" if p["processes"] == 1 else "processes"
        assert p["predicted_seconds"][chosen] <= min(p["predicted_seconds"].values())
        assert [p["processes"], p["threads"]] == p["options"][chosen]
        assert r.threads == p["threads"] * p["processes"] or p["processes"] > 1
    assert ref.report.parallel == {"processes": 1, "threads": 1, "why": "1 thread of this process, as asked"}
    r = bake_ao(target, occ, workers=2, **kw)
    assert r.report.parallel["processes"] == 2 and r.report.parallel["why"].endswith("as asked")
    # with the pool running and the same meshes, its workers keep their scene: the prediction has no
    # Embree build in them (the scene token the pool holds is this bake's)
    state, token = pool.pool_state(2, 1, run_mod.REMOTE)
    assert state == "running" and token == run_mod._scene_token(
        run_mod.check(BakeRequest(**kw), target, occ))()


def test_udim_and_corner_bakes_report_where_they_ran():
    target, occ = grid(8), [lid()]
    from core import bake_udim, bake_vertex_ao

    r = bake_udim(target, occ, resolution=16, samples=4, max_distance=1.0, workers="auto")
    assert r.report.parallel["processes"] >= 1 and "predicted_seconds" in r.report.parallel

    v = bake_vertex_ao(target, occ, samples=4, max_distance=1.0, workers="auto")
    assert v.report.parallel["processes"] >= 1 and "predicted_seconds" in v.report.parallel


def test_a_workers_set_up_repeats_the_checks_not_the_layout_that_comes_in_its_job():
    work = WORKS[2]
    target, every = work.triangles[0], sum(work.triangles)
    kept = cost.parallel_seconds(work, 2, 1, 0.0, True)
    built = cost.parallel_seconds(work, 2, 1, 0.0, False)
    own = cost.NS_WORKER_SETUP_PER_TRIANGLE + cost.NS_TABLE_PER_TRIANGLE
    assert kept["workers"] == pytest.approx(cost.WORKER_BAKE_SECONDS
                                            + 1e-9 * (cost.NS_RECEIVE_PER_BYTE * work.job_bytes + own * target))
    assert built["workers"] - kept["workers"] == pytest.approx(1e-9 * cost.NS_EMBREE_PER_TRIANGLE * every)
    # the parent lays the UVs out (UV triangles, bins); a worker repeats only its checks and prologue
    assert 0 < cost.NS_WORKER_SETUP_PER_TRIANGLE < cost.NS_SETUP_PER_TRIANGLE
    assert kept["parent"] == cost.parallel_seconds(work, 1, 2)["parent"]


def test_the_job_bytes_weighed_are_the_arrays_a_worker_is_sent(monkeypatch):
    target, occ = grid(40), [lid()]
    seen = {}
    parallel_of, bake_tiles = run_mod.parallel_of, run_mod.bake_tiles

    def weigh(*a, **kw):
        seen["work"] = a[4]
        return parallel_of(*a, **kw)

    def sent(remote, bake, keys, processes, threads, job, *a, **kw):
        seen["job"] = job()
        return bake_tiles(remote, bake, keys, processes, threads, job, *a, **kw)

    monkeypatch.setattr(run_mod, "parallel_of", weigh)
    monkeypatch.setattr(run_mod, "bake_tiles", sent)
    bake_ao(target, occ, resolution=256, samples=1, max_distance=1.0, workers="auto")

    def arrays(x):
        if isinstance(x, np.ndarray):
            return x.nbytes
        if isinstance(x, dict):
            return sum(arrays(v) for v in x.values())
        if isinstance(x, (list, tuple)):
            return sum(arrays(v) for v in x)
        return 0

    job = seen["job"]
    assert job["target"]["uvs"] is None and len(job["layout"]["bins"]) > 1
    assert 0.95 < seen["work"].job_bytes / arrays(job) < 1.05
