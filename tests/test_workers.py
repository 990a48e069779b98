"""Tiles baked in worker processes (core.execution.pool): the same bits as in this process for any workers x
threads x tiling, errors by the core's own classes, cancel, a worker that dies, and no worker that
outlives its parent. Driven by the bake's own events (progress), never by the clock."""

import dataclasses
import os
import signal
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest

from core import BakeCancelled, Mesh, MeshError, bake_ao, bake_udim
from core.base import machine
from core.execution import executor, messages, pool
from core.pipeline import run as pipeline_run
from core.post.bent import TangentFrames  # noqa: F401  (bent_space stays in the parent)
from scenes import QUAD, box, plane

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def without_memory(report):
    """A bake's report less ``worker_memory`` (each process's sizes differ from bake to bake), ``parallel``
    (where the tiles ran) and the warning of a worker count the machine's cores cut down (on this
    machine, not another)."""
    out = {k: v for k, v in report.items() if k not in ("worker_memory", "parallel")}
    warnings = [w for w in out.get("warnings") or [] if not w.startswith("asked for ")]
    out.pop("warnings", None)
    if warnings:
        out["warnings"] = warnings
    return out


def scene():
    """A bumpy plane (smooth normals: every kernel form) under a lid, with a box resting on it."""
    n = 12
    x, y = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1))
    z = 0.05 * np.sin(6 * x) * np.cos(5 * y)
    P = np.stack([x, y, z], -1).reshape(-1, 3)
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :]
    F = np.concatenate([np.stack([i, i + 1, i + n + 2], -1).reshape(-1, 3),
                        np.stack([i, i + n + 2, i + n + 1], -1).reshape(-1, 3)])
    UV = P[F][:, :, :2]
    target = Mesh(P, F, uvs=UV, name="bumps")
    lid = Mesh(np.array([[0.2, 0.2, 0.4], [0.8, 0.2, 0.4], [0.8, 0.8, 0.4], [0.2, 0.8, 0.4]]), QUAD, name="lid")
    return target, [lid, box((0.6, 0.1, -0.2), (0.8, 0.3, 0.2), name="block")]


FIELDS = ("ao", "stderr", "samples", "mask")


@pytest.mark.parametrize("kw", [dict(), dict(distribution="uniform", source="halton", falloff=1.0),
                                dict(samples=128, min_samples=16, target_error=0.03),
                                dict(bent_normals=True)])
def test_workers_give_the_bits_of_one_process_for_any_workers_threads_and_tiles(kw):
    target, occ = scene()
    args = dict(resolution=48, samples=32, max_distance=0.7, seed=3, margin=2)
    args.update(kw)
    ref = bake_ao(target, occ, threads=1, **args)
    for extra in (dict(workers=2), dict(workers=3, threads=2, tile_size=16), dict(workers=2, tile_size=(32, 16))):
        r = bake_ao(target, occ, **extra, **args)
        for name in FIELDS + (("bent",) if kw.get("bent_normals") else ()):
            assert np.array_equal(getattr(ref, name), getattr(r, name)), (extra, name)
        assert r.rays == ref.rays and without_memory(r.report) == without_memory(ref.report)


def test_selected_to_active_and_udim_in_workers_are_the_bits_of_one_process():
    high = plane(-0.5, -0.5, 1.5, 1.5, z=0.05, uv=False, name="high")
    low = plane(name="low")
    lid = Mesh(np.array([[0.25, 0.25, 0.3], [0.75, 0.25, 0.3], [0.75, 0.75, 0.3], [0.25, 0.75, 0.3]]), QUAD,
               name="lid")
    args = dict(resolution=32, samples=64, margin=0, highpoly=[high], extrusion=0.1)
    a = bake_ao(low, [lid], threads=1, **args)
    b = bake_ao(low, [lid], workers=2, **args)
    for name in FIELDS + ("miss",):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.report["matching_rays"] == b.report["matching_rays"] and a.missed == b.missed
    target, occ = scene()
    tiled = Mesh(target.positions, target.triangles, target.uvs + [1.0, 0.0], name="tile1002")
    u1 = bake_udim(tiled, occ, resolution=32, samples=16, threads=1)
    u2 = bake_udim(tiled, occ, resolution=32, samples=16, workers=2)
    assert list(u1.tiles) == list(u2.tiles) == [1002]
    assert np.array_equal(u1.ao, u2.ao) and np.array_equal(u1.stderr, u2.stderr)


def test_a_workers_error_is_raised_as_the_cores_own_class():
    high = plane(-0.5, -0.5, 1.5, 1.5, z=3.0, uv=False, name="far_high")
    with pytest.raises(MeshError, match="far_high"):
        bake_ao(plane(name="low"), resolution=16, samples=16, workers=2, highpoly=[high], extrusion=0.1,
                max_ray_distance=0.5)
    target, occ = scene()
    assert bake_ao(target, occ, resolution=16, samples=8, workers=2).mask.any()  # the pool still bakes


def test_cancel_from_progress_stops_the_workers_and_the_next_bake_runs():
    target, occ = scene()
    stop = threading.Event()
    seen = []

    def progress(f):
        seen.append(f)
        if f > 0.0:
            stop.set()

    with pytest.raises(BakeCancelled):
        bake_ao(target, occ, resolution=64, samples=256, workers=2, progress=progress, cancel=stop)
    assert seen and max(seen) < 1.0
    ref = bake_ao(target, occ, resolution=32, samples=8, threads=1)
    r = bake_ao(target, occ, resolution=32, samples=8, workers=2)
    assert np.array_equal(ref.ao, r.ao)


def test_a_worker_that_dies_fails_the_bake_and_the_next_bake_gets_a_fresh_pool():
    target, occ = scene()
    killed = []

    def progress(f):
        if not killed and f > 0.0:
            victim = pool._POOL.workers[0].process
            victim.kill()
            killed.append(victim.pid)

    with pytest.raises(messages.BakeWorkerError, match="ended before the bake did"):
        bake_ao(target, occ, resolution=64, samples=256, workers=2, progress=progress)
    assert killed
    r = bake_ao(target, occ, resolution=32, samples=8, workers=2)
    assert r.mask.any()
    assert all(w.process.pid != killed[0] for w in pool._POOL.workers)


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie is gone too
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split(") ")[1][0] != "Z"
    except OSError:
        return False


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc")
def test_no_worker_outlives_its_parent_killed():
    """A parent that bakes with workers is killed; its workers end by themselves (the lifeline)."""
    code = textwrap.dedent(f"""
        import sys; sys.path[:0] = [{ROOT!r}, {os.path.join(ROOT, 'tests')!r}]
        from test_workers import scene
        from core import bake_ao
        from core.execution import pool as workers
        t, o = scene()
        bake_ao(t, o, resolution=16, samples=4, workers=2)
        print(" ".join(str(w.process.pid) for w in workers._POOL.workers), flush=True)
        sys.stdin.read()
    """)
    parent = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    pids = [int(p) for p in parent.stdout.readline().split()]
    assert len(pids) == 2 and all(_alive(p) for p in pids)
    parent.send_signal(signal.SIGKILL)
    parent.wait()
    deadline = time.monotonic() + 60  # a bound for a slow machine, not a measurement
    while any(_alive(p) for p in pids) and time.monotonic() < deadline:
        time.sleep(0.05)
    assert not any(_alive(p) for p in pids)


@pytest.mark.parametrize("moved", ["occluder", "target"])
def test_a_worker_keeps_the_last_scene_and_a_changed_mesh_is_built_anew(moved):
    target, occ = scene()
    args = dict(resolution=32, samples=16, max_distance=0.7, margin=2, workers=2)

    def reused(r):
        return [e["scene_reused"] for e in r.report["worker_memory"][1:]]

    pool.shutdown()
    first = bake_ao(target, occ, **args)
    assert reused(first) == [False, False]
    # Baked again with other samples and resolution: the workers trace in the scene they kept.
    again = bake_ao(target, occ, **dict(args, samples=24, resolution=40))
    assert reused(again) == [True, True]
    # One vertex moved (of the lid, or of the bumpy plane): the scene is built anew.
    if moved == "occluder":
        P = occ[0].positions.copy()
        P[0, 2] = 0.1
        occ = [Mesh(P, occ[0].triangles, name="lid")] + occ[1:]
    else:
        P = target.positions.copy()
        P[len(P) // 2, 2] += 0.2
        target = Mesh(P, target.triangles, uvs=target.uvs, name="bumps")
    changed = bake_ao(target, occ, **args)
    assert reused(changed) == [False, False]
    assert not np.array_equal(changed.ao, first.ao)  # the vertex changes the bake
    pool.shutdown()  # a fresh pool's workers build every scene
    fresh = bake_ao(target, occ, **args)
    for name in FIELDS:
        assert np.array_equal(getattr(changed, name), getattr(fresh, name)), name
    assert changed.rays == fresh.rays
    # And the re-bake in the kept scene is the bits of a fresh pool's.
    pool.shutdown()
    target, occ = scene()
    fresh = bake_ao(target, occ, **dict(args, samples=24, resolution=40))
    for name in FIELDS:
        assert np.array_equal(getattr(again, name), getattr(fresh, name)), name


def test_as_many_tiles_as_workers_give_each_worker_one():
    target, occ = scene()
    r = bake_ao(target, occ, resolution=32, samples=8, tile_size=(32, 16), workers=2)
    assert [e["tiles"] for e in r.report["worker_memory"][1:]] == [1, 1]
    r = bake_ao(target, occ, resolution=32, samples=8, tile_size=16, workers=2)
    assert sum(e["tiles"] for e in r.report["worker_memory"][1:]) == 4


def test_shutdown_ends_the_pool():
    target, occ = scene()
    bake_ao(target, occ, resolution=16, samples=4, workers=2)
    procs = [w.process for w in pool._POOL.workers]
    pool.shutdown()
    assert pool._POOL is None and all(p.poll() is not None for p in procs)


def test_auto_workers_follow_cores_and_memory():
    assert executor.auto_workers(10_000, cores=16, memory=64 << 30) == (16, 1)
    # 10M triangles: each worker holds gigabytes; 16 GB holds a few copies, whose threads use every core.
    w, t = executor.auto_workers(10_000_000, cores=16, memory=16 << 30)
    from core import cost

    assert w * cost.process_bytes(10_000_000) + cost.parent_bytes(10_000_000) \
        <= 0.8 * (16 << 30) and w * t <= 16 and t >= 16 // max(w, 1) and w < 16
    assert executor.auto_workers(10, cores=4, memory=None) == (4, 1)


@pytest.mark.parametrize("bad", [0, -1, 1.5, "two", True])
def test_bad_worker_counts_are_refused(bad):
    from core import SettingsError

    target, occ = scene()
    with pytest.raises(SettingsError, match="workers"):
        bake_ao(target, occ, resolution=8, samples=4, workers=bad)


def test_on_rays_needs_this_process():
    from core import SettingsError

    target, occ = scene()
    with pytest.raises(SettingsError, match="on_rays"):
        bake_ao(target, occ, resolution=8, samples=4, workers=2, on_rays=lambda batch: None)


def test_vertex_bakes_in_workers_are_the_bits_of_one_process(monkeypatch):
    from core import bake_vertex_ao
    from core.targets import corners as vertices

    monkeypatch.setattr(vertices, "BLOCK", 40)  # several blocks for the workers to share
    target, occ = scene()
    args = dict(samples=32, max_distance=0.7, seed=5, bent_normals=True)
    a = bake_vertex_ao(target, occ, threads=1, **args)
    b = bake_vertex_ao(target, occ, workers=2, **args)
    for name in ("ao", "stderr", "samples", "unit", "bent"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.rays == b.rays


@pytest.fixture(scope="module")
def dask_client():
    distributed = pytest.importorskip("distributed")
    cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                       dashboard_address=None, silence_logs=40)
    client = distributed.Client(cluster)
    client.run(lambda: __import__("sys").path.insert(0, ROOT))
    yield client
    client.close()
    cluster.close()


def test_a_bake_on_a_dask_cluster_is_the_bits_of_one_process_and_survives_a_lost_worker(dask_client):
    target, occ = scene()
    args = dict(resolution=48, samples=32, max_distance=0.7, seed=3, margin=2, tile_size=16)
    ref = bake_ao(target, occ, threads=1, **args)
    r = bake_ao(target, occ, workers=dask_client, **args)
    for name in FIELDS:
        assert np.array_equal(getattr(ref, name), getattr(r, name)), name
    assert r.rays == ref.rays
    # A worker killed after the first tile came back: its tiles are redone elsewhere, the same bits.
    killed = []

    def progress(f):
        if not killed and f > 0:
            pids = dask_client.run(os.getpid)
            pid = sorted(pids.values())[0]
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

    r = bake_ao(target, occ, workers=dask_client, progress=progress, **args)
    assert killed
    for name in FIELDS:
        assert np.array_equal(getattr(ref, name), getattr(r, name)), name


def test_a_dask_bake_whose_every_worker_ends_sends_its_job_again(dask_client):
    """Dask keeps one copy of a scattered job once the tiles are under way, and cannot compute it again:
    with every worker that held it killed after the first tile, the tiles come back cancelled and the
    bake sends the job again to the workers that replace them; the same bits and rays."""
    dask_client.wait_for_workers(2, timeout=120)  # the test before this one killed a worker
    target, occ = scene()
    args = dict(resolution=48, samples=32, max_distance=0.7, seed=3, margin=2, tile_size=16)
    ref = bake_ao(target, occ, threads=1, **args)
    killed = []

    def progress(f):
        if not killed and f > 0:
            killed.extend(dask_client.run(os.getpid).values())
            for pid in killed:
                os.kill(pid, signal.SIGKILL)

    r = bake_ao(target, occ, workers=dask_client, progress=progress, **args)
    assert len(killed) == 2
    for name in FIELDS:
        assert np.array_equal(getattr(ref, name), getattr(r, name)), name
    assert r.rays == ref.rays
    dask_client.wait_for_workers(2, timeout=120)
    dask_client.run(lambda: None if ROOT in __import__("sys").path else __import__("sys").path.insert(0, ROOT))


def test_a_script_without_a_main_guard_runs_once(tmp_path):
    """Workers are not multiprocessing's spawn children: the script that bakes (Blender's --python
    file, a user's script without ``if __name__ == '__main__'``) is never run again in a worker."""
    marker = tmp_path / "runs.txt"
    script = tmp_path / "bake_script.py"
    script.write_text(textwrap.dedent(f"""
        import sys; sys.path[:0] = [{ROOT!r}, {os.path.join(ROOT, 'tests')!r}]
        with open({str(marker)!r}, "a") as f:
            f.write("ran\\n")
        from test_workers import scene
        from core import bake_ao
        t, o = scene()
        r = bake_ao(t, o, resolution=16, samples=4, workers=2)
        print("covered", int(r.mask.sum()))
    """))
    out = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    assert "covered" in out.stdout and marker.read_text() == "ran\n"


def test_a_pool_whose_self_test_fails_falls_back_to_threads_and_says_why(monkeypatch):
    """Where worker processes bake differently (another platform's numpy or Embree) or cannot start,
    the bake runs on threads, with the same bits, and a warning that says why."""
    pool.shutdown()
    # The workers' digests differ from this process's.
    monkeypatch.setattr(pipeline_run, "REMOTE", dataclasses.replace(pipeline_run.REMOTE,
                                                                    self_test=lambda: "this process's digest"))
    target, occ = scene()
    ref = bake_ao(target, occ, resolution=16, samples=8, threads=1)
    r = bake_ao(target, occ, resolution=16, samples=8, workers=2)
    assert np.array_equal(ref.ao, r.ao)
    (warning,) = r.report["warnings"]
    assert "not in worker processes" in warning and "self-test differently" in warning
    assert "warnings" not in ref.report
    pool.shutdown()


def test_auto_workers_with_threads_given_keep_within_the_cores():
    from core.base.request import BakeRequest
    from core.engine.settings import BakeSettings

    s = BakeSettings.of(BakeRequest(resolution=8, samples=4, min_samples=4, max_distance=1.0, margin=0, threads=2))
    processes, threads = executor.processes_of("auto", 2, s, 1000)
    assert threads == 2 and processes * threads <= max(2, machine.cpu_count())


def test_a_cancel_from_a_tile_ends_the_bake_whatever_each_worker_is_doing():
    """Cancelled as the first tile is stored, with tiles still dealt and results on their way back: the
    bake raises BakeCancelled and does not wait for a worker it stopped. (A cancel while the parent
    is held in on_tile, every worker idle with its results queued, hung the bake before: that is
    tests/blender/test_blender_bad_input.py::test_esc_during_a_bake_puts_the_images_back with the
    operator's default processes.)"""
    target, occ = scene()
    for seed in range(8):
        stop = threading.Event()
        out = []

        def bake():
            try:
                bake_ao(target, occ, resolution=64, samples=4, tile_size=16, workers=2, seed=seed, cancel=stop,
                        on_tile=lambda *a: stop.set())
            except BakeCancelled:
                out.append("cancelled")

        t = threading.Thread(target=bake, daemon=True)
        t.start()
        t.join(120)  # a bound for a slow machine: a bake left waiting for a stopped worker never ends
        assert out == ["cancelled"], seed


def test_a_workers_job_carries_the_parents_layout_not_the_uvs_and_the_worker_lays_out_nothing(monkeypatch):
    from core.geometry.raster import bin_triangles, prepare
    from core.pipeline import remote
    from core.targets import texels

    target, occ = scene()
    args = dict(resolution=48, samples=16, max_distance=0.7, seed=5, margin=2, tile_size=16, denoise=True)
    sent = []
    real_send = pool.send

    def spy(stream, msg):
        if msg[0] == "setup":
            sent.append(msg[2])
        real_send(stream, msg)

    monkeypatch.setattr(pool, "send", spy)
    r = bake_ao(target, occ, workers=2, threads=1, **args)
    ref = bake_ao(target, occ, workers=1, threads=1, **args)
    for name in FIELDS + ("raw_ao",):
        assert np.array_equal(getattr(ref, name), getattr(r, name)), name
    assert len(sent) == 2 and all(job is sent[0] for job in sent)  # one job, to each worker
    job = sent[0]
    # The target travels without its UVs; its UV triangles and tiles as this process laid them out.
    assert job["target"]["uvs"] is None and set(job["target"]) == {"positions", "triangles", "uvs", "normals", "name"}
    tris = prepare(target, 48, 48)
    lay = job["layout"]
    assert np.array_equal(lay["corners32"], tris.corners32) and lay["corners32"].dtype == np.float32
    assert np.array_equal(lay["valid"], tris.valid) and np.array_equal(lay["cw"], tris.cw)
    assert lay["counts"] == [tris.degenerate, tris.degenerate_space, tris.outside]
    bins = bin_triangles(tris, 48, 48, 16)
    assert sorted(lay["bins"]) == sorted(bins) and all(np.array_equal(lay["bins"][k], bins[k]) for k in bins)
    # The worker's side of that job, here: it never lays out the UVs (no UV triangles, no fitting of the
    # tiles, no bins), and bakes the tiles of this process's bake.
    calls = []

    def counted(name, f):
        def wrapper(*a, **kw):
            calls.append(name)
            return f(*a, **kw)
        return wrapper

    monkeypatch.setattr(texels, "prepare", counted("prepare", texels.prepare))
    monkeypatch.setattr(texels, "bin_triangles", counted("bin_triangles", texels.bin_triangles))
    import core.engine.settings as settings_mod
    monkeypatch.setattr(settings_mod.BakeSettings, "fit_tiles", counted("fit_tiles", settings_mod.BakeSettings.fit_tiles))
    bake, shared, _ = remote.build(dict(job), threading.Event(), lambda work: None)
    assert calls == []
    assert bake.uvtris.corners32 is lay["corners32"] and bake.bins is lay["bins"] and bake.pro.target.uvs is None
    out = bake.tile((1, 2))
    rows, cols = out.texels // 48, out.texels % 48
    assert len(out.texels) and np.array_equal(out.ao, ref.raw_ao[rows, cols])
    # The same job through the path of a job with UVs (a bake laid out in the worker) lays out once, the same.
    old = dict(job, target=dict(job["target"], uvs=target.uvs))
    old.pop("layout")
    again, _, _ = remote.build(old, threading.Event(), lambda work: None)
    assert calls.count("prepare") == 1 and calls.count("bin_triangles") == 1
    assert np.array_equal(again.uvtris.corners32, tris.corners32) and sorted(again.bins) == sorted(bins)
