"""Memory: what a bake holds per triangle, and that holding less changes no bit.

The mesh's face geometry and corner normals computed on demand, the UV triangles' corners and edges
per tile, the surface table and the UV layout built in slices of triangles: each gives the same
bits as the whole-array forms (checked here by slices of a few triangles against the usual ones).
``report['worker_memory']`` says what every process held, and ``'auto'`` starts no more workers than
the memory holds. No figure here depends on the machine: the bench measures them
(bench/sections/memory.py).
"""

import os
import sys

import numpy as np
import pytest

from core import Mesh, bake_ao, bake_udim, cost
from core.geometry import mesh as mesh_mod
from core.geometry import raster, surface
from core.execution import executor, memory, messages
from core.geometry.mesh import corner_positions, face_geometry
from core import bake_vertex_ao


def wavy(n=12, normals=True, seed=0):
    """An n x n grid with bumps, its UVs over [0, 1]^2, corner normals tilted at random (one zero-length,
    falling back to the face normal) and a degenerate triangle."""
    t = np.linspace(0.0, 1.0, n + 1)
    U, V = np.meshgrid(t, t)
    P = np.stack([U, V, 0.1 * np.sin(6 * U) * np.cos(5 * V)], -1).reshape(-1, 3)
    a = (np.arange(n)[None, :] + (n + 1) * np.arange(n)[:, None]).ravel()
    F = np.concatenate([np.stack([a, a + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + n + 1], 1)])
    UV = P[F][:, :, :2].copy()
    P[n + 2] = P[n + 3]  # triangles with no area in space (their UVs keep theirs)
    N = None
    if normals:
        rng = np.random.default_rng(seed)
        N = np.repeat(np.array([[[0.0, 0.0, 1.0]]]), len(F), 0).repeat(3, 1) + rng.normal(0, 0.2, (len(F), 3, 3))
        N[5, 1] = 0.0
    return P * 2.0 + 10.0, F, UV, N


def lid():
    P = np.array([[10.5, 10.5, 10.6], [11.5, 10.5, 10.6], [11.5, 11.5, 10.6], [10.5, 11.5, 10.6]])
    return Mesh(P, np.array([[0, 1, 2], [0, 2, 3]]), name="lid")


def small_slices(monkeypatch, n=7):
    for mod in (mesh_mod, raster, surface):
        monkeypatch.setattr(mod, "SLICE", n)


FIELDS = ("ao", "stderr", "samples", "mask")


def same(a, b, *extra):
    for name in FIELDS + extra:
        x, y = getattr(a, name), getattr(b, name)
        assert np.array_equal(x, y), name


def test_the_lazy_face_geometry_gives_the_bits_of_the_whole_arrays():
    P, F, UV, N = wavy()
    m = Mesh(P, F, uvs=UV, normals=N, name="m")
    areas, fn = face_geometry(corner_positions(m.positions, m.triangles))
    tri = np.array([5, 0, 17, 5, 3])
    a, f = m.face_geometry_of(tri)  # nothing computed for all triangles yet
    assert np.array_equal(a, areas[tri]) and np.array_equal(f, fn[tri])
    assert m._face_normals is None and m._normals is None
    part = m.corner_normals(tri)
    assert np.array_equal(m.areas, areas) and np.array_equal(m.face_normals, fn)
    whole = m.normals
    assert np.array_equal(part, whole[tri])
    # A zero corner normal falls back to its face normal; unit length elsewhere.
    assert np.array_equal(whole[5, 1], fn[5])
    assert np.allclose(np.linalg.norm(whole, axis=2)[np.any(fn != 0, axis=1)], 1.0)
    m.drop_face_geometry()
    assert m._face_normals is None and m._normals is None
    assert np.array_equal(m.normals, whole) and np.array_equal(m.face_normals, fn)
    flat = Mesh(P, F, name="flat")
    assert np.array_equal(flat.normals, np.repeat(fn[:, None], 3, axis=1))


def test_a_transformed_copy_keeps_the_corner_normals_of_its_source():
    P, F, UV, N = wavy()
    # So tiny that no face normal survives in world units (the cross products underflow), and a zero
    # corner normal has nothing to fall back to there; in the bake's frame it takes the face normal.
    P = (P - 10.0) * 1e-170
    N[7] = 0.0
    m = Mesh(P, F, uvs=UV, normals=N, name="m")
    assert not m.face_normals.any()
    out = m.transformed(np.zeros(3), 1e-170)
    # What the copy's normals were when they were computed with it, whole.
    nz = (m.normals != 0).reshape(-1, 3)
    lost = ~(nz[:, 0] | nz[:, 1] | nz[:, 2]).reshape(len(m.normals), 3)
    want = np.where(lost[..., None], out.face_normals[:, None, :], m.normals)
    assert lost.any() and out.normals[7].any() and np.array_equal(out.normals, want)
    assert np.array_equal(out.corner_normals(np.array([3, 1])), want[[3, 1]])


def test_a_mesh_shares_the_callers_float64_arrays_and_copies_others():
    P, F, UV, N = wavy(normals=False)
    m = Mesh(P, F, uvs=UV, name="m")
    assert m.positions is P and m.triangles is F and m.uvs is UV
    m32 = Mesh(P.astype(np.float32), F.astype(np.int32), uvs=UV[:, ::-1], name="m32")
    assert m32.positions.dtype == np.float64 and m32.triangles.dtype == np.int64
    assert m32.uvs.flags.c_contiguous and np.array_equal(m32.uvs, UV[:, ::-1])


def test_slices_of_triangles_change_no_pixel(monkeypatch):
    P, F, UV, N = wavy()
    target = Mesh(P, F, uvs=UV, normals=N, name="wavy")
    args = dict(resolution=40, samples=16, max_distance=1.0, margin=2, threads=1, tile_size=16)
    ref = bake_ao(target, [lid()], bent_normals=True, **args)
    vref = bake_vertex_ao(target, [lid()], samples=16, threads=1)
    small_slices(monkeypatch)
    r = bake_ao(Mesh(P, F, uvs=UV, normals=N, name="wavy"), [lid()], bent_normals=True, **args)
    same(ref, r, "bent")
    v = bake_vertex_ao(Mesh(P, F, uvs=UV, normals=N, name="wavy"), [lid()], samples=16, threads=1)
    assert np.array_equal(vref.ao, v.ao) and np.array_equal(vref.stderr, v.stderr)
    assert ref.report["degenerate_triangles"] == r.report["degenerate_triangles"] > 0


def test_slices_change_no_pixel_of_a_selected_to_active_or_udim_bake(monkeypatch):
    P, F, UV, N = wavy(16)
    high = Mesh(P, F, normals=N, name="high")
    lowp = np.array([[10, 10, 9.8], [12, 10, 9.8], [12, 12, 9.8], [10, 12, 9.8]], float)
    low = Mesh(lowp, np.array([[0, 1, 2], [0, 2, 3]]), uvs=(lowp[[[0, 1, 2], [0, 2, 3]]][:, :, :2] - 10) / 2,
               name="low")
    args = dict(resolution=24, samples=64, max_distance=1.0, margin=0, threads=1)
    a = bake_ao(low, [], highpoly=[high], extrusion=0.5, **args)
    u = bake_udim(Mesh(P, F, uvs=UV + [1.0, 0.0], normals=N, name="u"), [lid()], resolution=24, samples=8, threads=1)
    small_slices(monkeypatch, 5)
    b = bake_ao(low, [], highpoly=[Mesh(P, F, normals=N, name="high")], extrusion=0.5, **args)
    same(a, b, "miss")
    v = bake_udim(Mesh(P, F, uvs=UV + [1.0, 0.0], normals=N, name="u"), [lid()], resolution=24, samples=8, threads=1)
    assert np.array_equal(u.ao, v.ao) and np.array_equal(u.stderr, v.stderr)


def test_uv_triangles_per_tile_are_the_whole_arrays_rows(monkeypatch):
    P, F, UV, N = wavy()
    UV[::3] = UV[::3, ::-1]  # some triangles clockwise in the UV map
    m = Mesh(P, F, uvs=UV, name="m")
    whole = raster.prepare(m, 33, 17)
    xy, edges = whole.xy, whole.edges
    tri = np.array([4, 0, 9, 4])
    fresh = raster.prepare(m, 33, 17)
    assert np.array_equal(fresh.xy_of(tri), xy[tri]) and np.array_equal(fresh.edges_of(tri), edges[tri])
    assert fresh.cw.any() and not fresh.cw.all()
    small_slices(monkeypatch, 3)
    sliced = raster.prepare(m, 33, 17)
    assert np.array_equal(sliced.xy, xy) and np.array_equal(sliced.edges, edges)
    assert (sliced.degenerate, sliced.degenerate_space, sliced.outside) == (whole.degenerate, whole.degenerate_space,
                                                                            whole.outside)
    assert np.array_equal(sliced.valid, whole.valid)
    bins = raster.bin_triangles(whole, 33, 17, 8)
    monkeypatch.setattr(raster, "SLICE", 3)
    sliced_bins = raster.bin_triangles(whole, 33, 17, 8)
    assert list(sliced_bins) == list(bins) and len(bins) > 4
    assert all(np.array_equal(sliced_bins[k], bins[k]) for k in bins)


def test_messages_carry_arrays_out_of_band_unchanged():
    import io

    a = np.arange(24.0).reshape(4, 6)
    msg = ("setup", 3, dict(p=a, t=a[:, ::2], i=np.arange(5, dtype=np.int32), empty=np.zeros((0, 3)), s="x"))
    buf = io.BytesIO()
    messages.send(buf, msg)
    messages.send(buf, ("finish", 4))
    buf.seek(0)
    kind, n, job = messages.receive(buf)
    assert (kind, n, job["s"]) == ("setup", 3, "x")
    for k in ("p", "t", "i", "empty"):
        assert np.array_equal(job[k], msg[2][k]) and job[k].dtype == msg[2][k].dtype
    job["p"][0, 0] = -1.0  # the received arrays are the message's own, writable
    assert messages.receive(buf) == ("finish", 4) and messages.receive(buf) is None


def test_held_bytes_counts_each_block_once():
    a = np.zeros(1000)
    holder = type("H", (), {})()
    holder.a, holder.view, holder.more = a, a[10:20], [a, {"b": np.zeros(10, np.int32)}]
    assert memory.held_bytes(holder) == a.nbytes + 40
    assert memory.held_bytes(None) == 0


LINUX = os.path.exists("/proc/self/status")


@pytest.mark.parametrize("workers", [1, 2])
def test_the_report_says_what_each_process_held(workers):
    P, F, UV, N = wavy(24)
    target = Mesh(P, F, uvs=UV, normals=N, name="wavy")
    r = bake_ao(target, [lid()], resolution=32, samples=8, workers=workers)
    mem = r.report["worker_memory"]
    assert [e["process"] for e in mem] == ["parent"] + [f"worker {i}" for i in range(workers if workers > 1 else 0)]
    assert mem[0]["pid"] == os.getpid()
    for e in mem[1:] if workers > 1 else mem:  # the processes that baked hold the scene's arrays
        assert e["held"] >= P.nbytes + F.nbytes + (UV.nbytes if workers == 1 else 0)  # a worker lets UVs go
    if LINUX:
        for e in mem:
            assert 0 < e["rss"] <= e["peak"] < 1 << 40
        for e in mem[1:]:
            # Sizes when the set-up began and when the scene was ready, both within the bake's peak (the
            # set-up may free as much as it builds: a worker drops its last scene before building another).
            assert e["pid"] != os.getpid() and 0 < e["start"] <= e["peak"] and 0 < e["ready"] <= e["peak"]


def test_a_vertex_bake_reports_its_processes_memory_too():
    P, F, UV, N = wavy(8)
    r = bake_vertex_ao(Mesh(P, F, normals=N, name="wavy"), [lid()], samples=8, workers=2)
    assert [e["process"] for e in r.report["worker_memory"]] == ["parent", "worker 0", "worker 1"]


def test_auto_starts_no_more_workers_than_the_memory_holds():
    T = 2_000_000
    one = cost.process_bytes(T)
    parent = cost.parent_bytes(T)
    for room in (1, 2, 3):
        memory = (parent + room * one + one // 2) / 0.8
        w, t = executor.auto_workers(T, cores=8, memory=memory)
        assert w == room and w * t <= 8 and t == 8 // room
        assert w * one + parent <= 0.8 * memory
    # Too little for even one: still one, with every core's threads.
    assert executor.auto_workers(T, cores=8, memory=one // 10) == (1, 8)
    # High-poly triangles cost a worker less than a target's: more workers fit.
    memory = (cost.parent_bytes(2, T) + 2 * cost.process_bytes(2, 0, T)) / 0.8
    assert executor.auto_workers((2, 0, T), cores=8, memory=memory)[0] == 2
    assert executor.auto_workers(T, cores=8, memory=memory)[0] < 2


def test_the_memory_estimate_prices_the_parent_and_each_worker():
    one = cost.estimate(1000, 16, 10_000, image_texels=1 << 20, threads=1, processes=1)
    two = cost.estimate(1000, 16, 10_000, image_texels=1 << 20, threads=1, processes=2)
    assert two.bytes - one.bytes == cost.process_bytes(10_000) + cost.parent_bytes(10_000) + 1000 * 16 * \
        cost.BYTES_PER_CHUNK_RAY
    high = cost.estimate(1000, 16, 2, highpoly_triangles=10_000)
    assert high.bytes < cost.estimate(1000, 16, 10_002).bytes


def test_a_large_high_poly_alone_is_one_embree_scene_that_matches_and_occludes(monkeypatch):
    from core.highpoly import scene as highpoly

    P, F, UV, N = wavy(16)
    lowp = np.array([[10, 10, 9.8], [12, 10, 9.8], [12, 12, 9.8], [10, 12, 9.8]], float)
    low = Mesh(lowp, np.array([[0, 1, 2], [0, 2, 3]]), uvs=(lowp[[[0, 1, 2], [0, 2, 3]]][:, :, :2] - 10) / 2,
               name="low")
    args = dict(resolution=24, samples=64, max_distance=1.0, margin=0, threads=1, extrusion=0.5)
    scenes = []
    real = highpoly.HighPolyScene.__init__

    def spy(self, *a, **k):
        real(self, *a, **k)
        scenes.append(self.tracer.scene is self.match_scene)

    monkeypatch.setattr(highpoly.HighPolyScene, "__init__", spy)
    two = bake_ao(low, [], highpoly=[Mesh(P, F, normals=N, name="high")], **args)
    monkeypatch.setattr(highpoly, "ONE_SCENE_TRIANGLES", len(F))
    one = bake_ao(low, [], highpoly=[Mesh(P, F, normals=N, name="high")], **args)
    with_lid = bake_ao(low, [lid()], highpoly=[Mesh(P, F, normals=N, name="high")], **args)
    assert scenes == [False, True, False]  # another occluder: the occlusion scene holds both
    # The same rays; the robust scene may answer a ray grazing an edge differently, nothing more.
    assert np.array_equal(one.mask, two.mask) and np.mean(one.ao == two.ao) > 0.95
    assert np.abs(one.ao - two.ao).max() <= 2.0 / 64
    assert with_lid.mask.any()
