"""Bad input to the core: each case raises its documented exception, naming the mesh and the problem,
before any heavy work; random meshes and settings never raise anything else and give sane results."""

import threading

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from core import (BakeCancelled, BakeMemoryError, McAoError, Mesh, MeshError, MeshTypeError, SettingsError,
                  bake_ao)
from scenes import plane

P = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
F = np.array([[0, 1, 2], [0, 2, 3]])
UV = P[F][:, :, :2]


@pytest.mark.parametrize("bad, exc, words", [
    (dict(positions=np.where(np.arange(12).reshape(4, 3) == 4, np.nan, P)), MeshError, ["'crate'", "NaN"]),
    (dict(positions=np.where(np.arange(12).reshape(4, 3) == 7, np.inf, P)), MeshError, ["'crate'", "infinity"]),
    (dict(normals=np.full((2, 3, 3), np.nan)), MeshError, ["'crate'", "normals", "NaN"]),
    (dict(uvs=np.full((2, 3, 2), np.inf)), MeshError, ["'crate'", "uvs"]),
    (dict(triangles=F + 2), MeshError, ["'crate'", "out of range", "4 vertices"]),
    (dict(triangles=-F), MeshError, ["out of range"]),
    (dict(positions=P[:, :2]), MeshError, ["positions", "shape (N, 3)"]),
    (dict(triangles=F.astype(float)), MeshTypeError, ["triangles", "integer"]),
    (dict(positions=P.astype(complex)), MeshTypeError, ["positions", "complex"]),
    (dict(positions=P.astype(object)), MeshTypeError, ["positions"]),
    (dict(uvs=UV[:1]), MeshError, ["uvs", "(2, 3, 2)"]),
    (dict(normals=np.ones((2, 3))), MeshError, ["normals", "(2, 3, 3)"]),
    (dict(triangles=np.zeros((0, 3), int)), MeshError, ["'crate'", "empty"]),
    (dict(positions=np.zeros((0, 3)), triangles=np.zeros((0, 3), int)), MeshError, ["empty"]),
])
def test_bad_meshes_are_refused_with_a_clear_message(bad, exc, words):
    args = dict(positions=P, triangles=F, uvs=UV, normals=None, name="crate")
    args.update(bad)
    with pytest.raises(exc) as info:
        Mesh(**args)
    for w in words:
        assert w in str(info.value), (w, str(info.value))
    assert isinstance(info.value, McAoError)


def test_target_without_uvs_is_refused():
    with pytest.raises(MeshError, match=r"'ground' has no UVs"):
        bake_ao(Mesh(P, F, name="ground"))


@pytest.mark.parametrize("kw, words", [
    (dict(resolution=0), "at least 1"), (dict(resolution=-5), "at least 1"),
    (dict(resolution=(16, 0)), "height"), (dict(resolution=(16,)), "pair"),
    (dict(resolution=1.5), "pair"), (dict(resolution=100_000), "exceeds"),
    (dict(samples=0), "samples"), (dict(samples=2.5), "samples"), (dict(min_samples=0), "min_samples"),
    (dict(max_distance=0.0), "max_distance"), (dict(max_distance=-1.0), "max_distance"),
    (dict(max_distance=float("nan")), "max_distance"), (dict(target_error=-0.1), "target_error"),
    (dict(distribution="gaussian"), "cosine, uniform"), (dict(source="random"), "sobol"),
    (dict(margin=-1), "margin"), (dict(seed=-3), "seed"), (dict(threads=0), "threads"),
    (dict(falloff=1.0), "finite max_distance"), (dict(occluders=[object()]), "core.Mesh"),
])
def test_bad_settings_are_refused(kw, words):
    kw = dict(kw)
    occ = kw.pop("occluders", ())
    with pytest.raises(SettingsError, match=words):
        bake_ao(plane(), occ, **{"resolution": 8, "samples": 4, **kw})


def test_a_bake_too_large_for_memory_is_refused_with_the_estimate_before_allocating():
    with pytest.raises(BakeMemoryError, match=r"needs about [0-9.]+ GiB.*available"):
        bake_ao(plane(), resolution=65536, samples=1)


@pytest.mark.parametrize("after", [0, 1, 3, 10])
def test_cancel_at_any_point_leaves_no_result(after):
    calls = []

    def cancel():
        calls.append(1)
        return len(calls) > after

    with pytest.raises(BakeCancelled):
        bake_ao(plane(), [plane(z=0.3, uv=False, name="lid")], resolution=64, samples=16, chunk_rays=512,
                cancel=cancel, threads=2)


def test_cancel_from_another_thread_mid_bake():
    """Cancelled from the progress callback, at 30%: the bake stops there, on any machine."""
    ev = threading.Event()
    seen = []

    def progress(f):
        seen.append(f)
        if f > 0.3:
            ev.set()

    with pytest.raises(BakeCancelled):
        bake_ao(plane(), [plane(z=0.3, uv=False, name="lid")], resolution=64, samples=64, chunk_rays=2048,
                progress=progress, cancel=ev, threads=2)
    assert 0.3 < max(seen) < 1.0


def test_degenerate_triangles_are_skipped_and_counted():
    Pd = np.concatenate([P, [[2, 2, 0]]])
    Fd = np.concatenate([F, [[1, 1, 4]]])  # zero area in space, but UVs with area
    uv = np.concatenate([UV, [[[0.1, 0.1], [0.2, 0.1], [0.1, 0.2]]]])
    r = bake_ao(Mesh(Pd, Fd, uv, name="m"), resolution=8, samples=4, margin=0)
    assert r.report["degenerate_triangles"] == 1
    assert np.all(r.ao[r.mask] == 1.0)


# --- property-based: random meshes and settings --------------------------------------------------

coords = st.floats(-4, 4, allow_nan=False, width=32)


@st.composite
def meshes(draw):
    nv = draw(st.integers(3, 9))
    nt = draw(st.integers(1, 6))
    pos = np.array(draw(st.lists(st.tuples(coords, coords, coords), min_size=nv, max_size=nv)), float)
    tri = np.array(draw(st.lists(st.tuples(*[st.integers(0, nv - 1)] * 3), min_size=nt, max_size=nt)))
    uv = np.array(draw(st.lists(st.floats(-0.5, 1.5, width=32), min_size=nt * 6, max_size=nt * 6)),
                  float).reshape(nt, 3, 2)
    normals = None
    if draw(st.booleans()):
        normals = np.array(draw(st.lists(st.floats(-1, 1, width=32), min_size=nt * 9, max_size=nt * 9)),
                           float).reshape(nt, 3, 3)
    return Mesh(pos, tri, uv, normals, name="random")


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(mesh=meshes(), res=st.integers(1, 12), samples=st.integers(1, 8),
       max_distance=st.one_of(st.just(float("inf")), st.floats(1e-3, 10)),
       distribution=st.sampled_from(["cosine", "uniform"]),
       source=st.sampled_from(["sobol", "stratified", "independent", "halton"]),
       margin=st.integers(0, 3), target_error=st.sampled_from([0.0, 0.05]),
       ignore_backfaces=st.booleans(), seed=st.integers(0, 2 ** 40))
def test_random_meshes_and_settings(mesh, res, samples, max_distance, distribution, source, margin,
                                    target_error, ignore_backfaces, seed):
    kw = dict(resolution=res, samples=samples, max_distance=max_distance, distribution=distribution, source=source,
              margin=margin, target_error=target_error, min_samples=min(2, samples),
              ignore_backfaces=ignore_backfaces, seed=seed, threads=1)
    try:
        r = bake_ao(mesh, [mesh], **kw)
    except MeshError as e:
        # A bake that covers no texel is refused, naming the mesh; the same bake allowed to be empty
        # covers nothing indeed.
        assert "the bake covered no texel" in str(e) and repr(mesh.name) in str(e)
        r = bake_ao(mesh, [mesh], empty_ok=True, **kw)
        assert not r.mask.any() and not r.ao.any()
    else:
        assert r.mask.any()
    for a in (r.ao, r.stderr):
        assert a.shape == (res, res) and a.dtype == np.float32 and np.all(np.isfinite(a))
    assert np.all((r.ao >= 0) & (r.ao <= 1))
    assert np.all(r.stderr >= 0)
    assert np.all(r.samples[r.mask] >= 1) and np.all(r.samples[~r.mask] == 0)
    assert np.all(r.stderr[~r.mask] == 0)
    if margin == 0:
        assert np.all(r.ao[~r.mask] == 0)
    assert r.report["covered_texels"] == r.mask.sum()


@settings(max_examples=40, deadline=None)
@given(mesh=meshes(), which=st.sampled_from(["positions", "uvs", "normals"]), idx=st.integers(0, 10 ** 6),
       value=st.sampled_from([np.nan, np.inf, -np.inf]))
def test_any_non_finite_value_is_refused_by_name(mesh, which, idx, value):
    arrays = dict(positions=mesh.positions.copy(), uvs=mesh.uvs.copy(), normals=mesh.normals.copy())
    a = arrays[which]
    a.flat[idx % a.size] = value
    with pytest.raises(MeshError, match=which):
        Mesh(arrays["positions"], mesh.triangles, arrays["uvs"], arrays["normals"], name="random")


# --- trust: scale, duplicated occluders, broken UVs, memory, events -------------------------------

LID_Q = np.array([[0.25, 0.25, 0.3], [0.75, 0.25, 0.3], [0.75, 0.75, 0.3], [0.25, 0.75, 0.3]])


@pytest.mark.parametrize("scale", [1e13, 1e-14, 1e20, 1e-20, 1e6])
@pytest.mark.parametrize("max_distance", [float("inf"), 0.5])
def test_the_unit_of_the_scene_does_not_change_the_ao(scale, max_distance):
    """A scene modelled at 1e13 or 1e-14 bakes the AO of the same scene at 1 (offsets follow the size)."""
    def bake(s, offset):
        p = plane()
        target = Mesh((p.positions + offset) * s, p.triangles, p.uvs, name="t")
        lid = Mesh((LID_Q + offset) * s, F, name="lid")
        return bake_ao(target, [lid], resolution=8, samples=64, margin=0, max_distance=max_distance * s,
                       seed=2, threads=1)
    ref = bake(1.0, 0.0)
    assert 0.3 < ref.ao.mean() < 0.95
    got = bake(scale, 3.0)
    # The same rays up to rounding: at most a ray or two of 64 per texel may flip at an edge.
    assert np.abs(got.ao - ref.ao).max() <= 2 / 64
    assert abs(float(got.ao.mean() - ref.ao.mean())) < 1e-3


def test_the_target_among_its_own_occluders_is_ignored():
    p = plane()
    lid = Mesh(LID_Q, F, name="lid")
    ref = bake_ao(p, [lid], resolution=8, samples=32, seed=1, threads=1)
    twin = Mesh(p.positions.copy(), p.triangles.copy(), name="twin")  # the same surface, another object
    for occ in ([p, lid], [lid, p, p], [twin, lid, twin]):
        r = bake_ao(p, occ, resolution=8, samples=32, seed=1, threads=1)
        assert np.array_equal(r.ao, ref.ao)


@pytest.mark.parametrize("value", [1e17, -1e17, 1e9])
def test_uvs_far_outside_any_uv_map_are_refused_by_name(value):
    uv = UV.copy()
    uv[1, 2, 0] = value
    with pytest.raises(MeshError, match=r"'crate': 1 triangles have UV coordinates beyond"):
        Mesh(P, F, uv, name="crate")


def test_udim_range_uvs_are_accepted():
    Mesh(P, F, UV + [9, 99], name="crate")


@pytest.mark.parametrize("samples", [2 ** 20 + 1, 2 ** 31])
def test_too_many_samples_are_refused_before_any_work(samples):
    with pytest.raises(SettingsError, match="samples must be at most"):
        bake_ao(plane(), resolution=1, samples=samples)


def test_the_memory_estimate_counts_samples_and_chunks():
    from core.execution.cost import bake_bytes

    small = bake_bytes(1, 1, 2, 1, 1 << 16, samples=16)
    big = bake_bytes(1, 1, 2, 1, 1 << 16, samples=1 << 20)
    assert big - small > (1 << 20) * 40  # the sample tables


def test_a_texel_with_many_samples_is_traced_in_bounded_pieces():
    """2^17 samples of one texel: chunks of at most 2^16 rays, and the same numbers as in one piece."""
    from core.engine.settings import SAMPLE_PIECE

    sizes = []
    r = bake_ao(plane(), [Mesh(LID_Q, F, name="lid")], resolution=1, samples=1 << 17, margin=0, threads=1,
                on_rays=lambda batch: sizes.append(len(batch.origins)))
    assert max(sizes) <= SAMPLE_PIECE and sum(sizes) == 1 << 17
    assert r.samples[0, 0] == 1 << 17


def test_progress_follows_the_bakes_events_not_a_clock():
    """Every chunk reports progress, however fast the machine: a fast bake still shows its middle."""
    seen = []
    bake_ao(plane(), [plane(z=0.3, uv=False, name="lid")], resolution=32, samples=16, chunk_rays=512,
            tile_size=16, progress=seen.append, threads=1)
    # 32 x 32 texels x 16 samples = 16384 texel-samples in chunks of 512: 32 chunks, plus the end.
    assert len(seen) >= 32
    assert seen == sorted(seen) and seen[-1] == 1.0
    assert sum(0.2 < f < 0.8 for f in seen) >= 16


# --- a bake that covers nothing is an error, never an empty success ----------------------------------

@pytest.mark.parametrize("case, words", [
    ("outside", "lie outside the image's UV square"),
    ("no_uv_area", "have no area in the UV map"),
])
def test_a_bake_that_covers_no_texel_is_refused_naming_the_mesh_and_why(case, words):
    p = plane()
    uvs = p.uvs + 3.0 if case == "outside" else np.zeros_like(p.uvs) + 0.5
    target = Mesh(p.positions, p.triangles, uvs, name="Crate")
    with pytest.raises(MeshError, match=words) as e:
        bake_ao(target, resolution=8, samples=4, threads=1)
    assert "'Crate'" in str(e.value) and "the bake covered no texel" in str(e.value)
    # Allowed to be empty (a UDIM tile listed but not touched), the same bake is all zero.
    r = bake_ao(target, resolution=8, samples=4, threads=1, empty_ok=True)
    assert not r.mask.any() and not r.ao.any() and not r.samples.any()


def test_a_udim_bake_that_covers_nothing_is_refused():
    from core import bake_udim

    p = plane()
    target = Mesh(p.positions, p.triangles, np.zeros_like(p.uvs) + 0.5, name="Flat")
    with pytest.raises(MeshError, match="'Flat'.*the bake covered no texel"):
        bake_udim(target, resolution=8, samples=4, tiles=[1001], threads=1)


@pytest.mark.parametrize("kw, words", [(dict(seed=1 << 64), "seed must be at most"),
                                       (dict(threads=10 ** 6), "threads must be at most")])
def test_huge_seeds_and_thread_counts_are_refused_by_name(kw, words):
    with pytest.raises(SettingsError, match=words):
        bake_ao(plane(), resolution=8, samples=4, **kw)
    from core.base.request import MAX_SEED

    assert bake_ao(plane(), resolution=8, samples=4, seed=MAX_SEED, threads=1).mask.any()
