"""Several quantities from one bake (core.targets.maps): AO and the thickness map of bake_maps, bake_udim_maps and
bake_vertex_maps are bit for bit the separate bakes of each quantity with the same settings (images, UDIM
tiles, mesh corners, threads, worker processes, a Dask cluster, selected to active), the set-up is taken
once, the AO-only settings reach the AO map alone, and bad quantities are refused by name."""

import numpy as np
import pytest

from core import (Mesh, SettingsError, bake_ao, bake_maps, bake_udim, bake_udim_maps, bake_vertex_ao,
                  bake_vertex_maps)
from core.targets import texels
from core.engine import tilebaker
from core.tracing import tracer as tracing
from scenes import QUAD, box, plane
from test_mc_ao_outputs import run as service_run  # the service run to its end, its outcomes
from test_workers import dask_client  # noqa: F401  (the module's Dask cluster fixture)

FIELDS = ("ao", "stderr", "samples", "mask", "bent", "miss", "raw_ao", "raw_stderr", "unit")


def unwrapped_box(lo=(0.0, 0.0, 0.0), hi=(1.0, 0.6, 0.4), name="crate", cells=(3, 2), origin=(0.0, 0.0)):
    """A closed box whose six faces are each mapped onto a cell of a 3 x 2 grid of the UV square (or
    a grid of ``cells`` placed at ``origin``: UDIM tiles), smooth corner normals bent outwards."""
    b = box(lo, hi, name=name)
    P, F = b.positions, b.triangles
    corners = P[F]
    fn = b.face_normals
    uv = np.zeros(corners.shape[:2] + (2,))
    lo, hi = np.array(lo, float), np.array(hi, float)
    for t in range(len(F)):
        axis = int(np.argmax(np.abs(fn[t])))
        a, c = [k for k in range(3) if k != axis]
        face = t // 2
        cell = np.array([face % cells[0], face // cells[0] % cells[1]], float)
        local = (corners[t][:, [a, c]] - lo[[a, c]]) / (hi - lo)[[a, c]]
        uv[t] = origin + (cell + 0.05 + 0.9 * local) / cells
    centre = (lo + hi) / 2
    n = corners - centre
    n = 0.5 * n / np.linalg.norm(n, axis=2, keepdims=True) + fn[:, None, :]
    return Mesh(P, F, uv, normals=n / np.linalg.norm(n, axis=2, keepdims=True), name=name)


def occluders():
    lid = Mesh(np.array([[-0.2, -0.2, 0.7], [1.2, -0.2, 0.7], [1.2, 0.8, 0.7], [-0.2, 0.8, 0.7]]), QUAD, name="lid")
    return [lid, box((1.05, 0.0, 0.0), (1.3, 0.3, 0.5), name="post")]


def same(a, b, what):
    for name in FIELDS:
        x, y = getattr(a, name), getattr(b, name)
        assert (x is None) == (y is None), (what, name)
        if x is not None:
            assert x.dtype == y.dtype and np.array_equal(x, y), (what, name)
    assert a.rays == b.rays, what


def check_maps(maps, singles, quantities=("ao", "thickness")):
    assert list(maps) == list(quantities)
    for q in quantities:
        same(maps[q], singles[q], q)
        assert maps[q].metadata["quantities"] == ",".join(quantities)
        assert maps[q].metadata["quantity"] == q
        assert "quantities" not in singles[q].metadata
        # The processes' memory (report['worker_memory']) is measured, not computed: the rest is the same.
        assert ({k: v for k, v in maps[q].report.items() if k != "worker_memory"}
                == {k: v for k, v in singles[q].report.items() if k != "worker_memory"})
        assert ("worker_memory" in maps[q].report) == ("worker_memory" in singles[q].report)


BASE = dict(resolution=48, samples=16, max_distance=0.5, seed=3, margin=2)


@pytest.mark.parametrize("kw", [
    dict(threads=1),
    dict(threads=2, tile_size=16, ground="auto", bent_normals=True),
    dict(threads=1, samples=64, min_samples=8, target_error=0.04, distribution="uniform", source="halton",
         falloff=1.0, ignore_backfaces=True),
    dict(threads=1, denoise=True, ground=-0.1),
    dict(workers=2, tile_size=(32, 16), ground="auto"),
])
def test_each_map_is_the_bits_of_its_own_bake(kw):
    target, occ = unwrapped_box(), occluders()
    args = dict(BASE, **kw)
    maps = bake_maps(target, occ, **args)
    ao = bake_ao(target, occ, **args)
    thickness_args = {k: v for k, v in args.items() if k not in ("ground", "ignore_backfaces", "bent_normals")}
    thick = bake_ao(target, occ, quantity="thickness", **thickness_args)
    check_maps(maps, {"ao": ao, "thickness": thick})
    assert maps["ao"].mask.sum() > 500
    # The two maps differ (the lid darkens the AO; the box's inside the thickness).
    assert not np.array_equal(maps["ao"].ao, maps["thickness"].ao)
    if kw.get("bent_normals"):
        assert maps["ao"].bent is not None and maps["thickness"].bent is None
    if kw.get("ground") is not None:
        assert maps["ao"].metadata["ground"] != "none" and maps["thickness"].metadata["ground"] == "none"
        assert "ground_height" not in maps["thickness"].metadata


def test_one_quantity_and_either_order():
    target, occ = unwrapped_box(), occluders()
    args = dict(BASE, threads=1)
    ref = {"ao": bake_ao(target, occ, **args), "thickness": bake_ao(target, occ, quantity="thickness", **args)}
    check_maps(bake_maps(target, occ, quantities=("thickness", "ao"), **args), ref, ("thickness", "ao"))
    check_maps(bake_maps(target, occ, quantities=["thickness"], **args), ref, ("thickness",))
    check_maps(bake_maps(target, occ, quantities="ao", **args), ref, ("ao",))


def counting(monkeypatch, module, name):
    calls = []
    real = getattr(module, name)

    def wrapper(*a, **k):
        calls.append(1)
        return real(*a, **k)

    monkeypatch.setattr(module, name, wrapper)
    return calls


def test_the_set_up_is_taken_once(monkeypatch):
    """Rasterising, the UV triangles and (the rays of both seeing the target alone) the Embree scene:
    as many for both maps as for one bake."""
    target = unwrapped_box()
    tiles = counting(monkeypatch, tilebaker, "rasterize_tile")
    prepared = counting(monkeypatch, texels, "prepare")
    scenes = counting(monkeypatch, tracing, "embree_scene")
    args = dict(BASE, threads=1, tile_size=16)
    bake_ao(target, **args)
    one = len(tiles), len(prepared), len(scenes)
    assert one[0] > 4
    bake_maps(target, **args)
    assert (len(tiles) - one[0], len(prepared) - one[1], len(scenes) - one[2]) == one
    # With occluders AO sees more than the target: the thickness map has a scene of the target alone.
    scenes.clear()
    bake_ao(target, occluders(), **args)
    single = len(scenes)
    bake_maps(target, occluders(), **args)
    assert len(scenes) - single == single + 1


def test_selected_to_active_maps_are_the_bits_of_their_bakes():
    low = unwrapped_box((0.0, 0.0, 0.0), (1.0, 0.6, 0.4), name="low")
    high = box((-0.02, -0.02, -0.02), (1.02, 0.62, 0.43), name="high")
    args = dict(BASE, threads=2, highpoly=[high], samples=32)
    for kw in (dict(), dict(workers=2)):
        maps = bake_maps(low, occluders(), **args, **kw)
        ref = {"ao": bake_ao(low, occluders(), **args, **kw),
               "thickness": bake_ao(low, occluders(), quantity="thickness", **args, **kw)}
        for q in ref:
            ref[q].report.pop("matching_seconds"), ref[q].report.pop("matching_cpu_seconds")
            maps[q].report.pop("matching_seconds"), maps[q].report.pop("matching_cpu_seconds")
        check_maps(maps, ref)
        assert maps["ao"].metadata["extrusion_auto"] and maps["ao"].report["matching_rays"] > 0


def test_udim_maps_are_the_bits_of_their_udim_bakes():
    a = unwrapped_box(name="a")
    # A second box on tile 1002, as one mesh.
    b = unwrapped_box((1.5, 0.0, 0.0), (2.0, 0.5, 0.5), name="b", origin=(1.0, 0.0))
    target = Mesh(np.concatenate([a.positions, b.positions]), np.concatenate([a.triangles, b.triangles + 8]),
                  np.concatenate([a.uvs, b.uvs]), normals=np.concatenate([a.normals, b.normals]), name="crates")
    args = dict(BASE, resolution=32, threads=1)
    maps = bake_udim_maps(target, occluders(), ground="auto", **args)
    ref = {"ao": bake_udim(target, occluders(), ground="auto", **args),
           "thickness": bake_udim(target, occluders(), quantity="thickness", **args)}
    check_maps(maps, ref)
    for q in ref:
        assert sorted(maps[q].tiles) == [1001, 1002]
        for t in (1001, 1002):
            same(maps[q].tiles[t], ref[q].tiles[t], (q, t))
    blocks = []
    bake_udim_maps(target, resolution=16, samples=4, on_tile=lambda q, t, r, c, blk: blocks.append((q, t)))
    assert {q for q, _ in blocks} == {"ao", "thickness"} and {t for _, t in blocks} == {1001, 1002}


@pytest.mark.parametrize("kw", [dict(threads=1, bent_normals=True, ground="auto"), dict(workers=2, denoise=True)])
def test_corner_maps_are_the_bits_of_their_corner_bakes(kw, monkeypatch):
    from core.targets import corners as vertices

    monkeypatch.setattr(vertices, "BLOCK", 16)  # several blocks
    target = unwrapped_box()
    args = dict(samples=32, max_distance=0.5, seed=2, **kw)
    maps = bake_vertex_maps(target, occluders(), **args)
    ref = {"ao": bake_vertex_ao(target, occluders(), **args),
           "thickness": bake_vertex_ao(target, occluders(), quantity="thickness",
                                       **{k: v for k, v in args.items() if k not in ("bent_normals", "ground")})}
    check_maps(maps, ref)


def test_a_dask_cluster_bakes_the_same_maps(dask_client):  # noqa: F811
    target, occ = unwrapped_box(), occluders()
    args = dict(BASE, tile_size=16, ground="auto")
    ref = bake_maps(target, occ, threads=1, **args)
    maps = bake_maps(target, occ, workers=dask_client, **args)
    for q in ref:
        same(maps[q], ref[q], q)


def test_the_on_tile_hook_names_the_quantity():
    seen = {}
    r = bake_maps(unwrapped_box(), resolution=32, samples=4, margin=0, threads=1,
                  on_tile=lambda q, rows, cols, block: seen.setdefault(q, []).append(block.size))
    assert set(seen) == {"ao", "thickness"} and sum(seen["ao"]) == sum(seen["thickness"]) == 32 * 32
    assert r["ao"].seconds > 0


@pytest.mark.parametrize("kw, message", [
    (dict(quantities=()), "empty"),
    (dict(quantities=("ao", "ao")), "more than once"),
    (dict(quantities=("ao", "thick")), "quantity"),
    (dict(quantities=5), "quantities"),
    (dict(quantities=("thickness",), ground="auto"), "ground"),
    (dict(quantities=("thickness",), ignore_backfaces=True), "ignore_backfaces"),
    (dict(quantities=("thickness",), bent_normals=True), "bent normals"),
])
def test_bad_quantities_are_refused_by_name(kw, message):
    target = unwrapped_box()
    with pytest.raises(SettingsError, match=message):
        bake_maps(target, resolution=16, samples=4, **kw)
    with pytest.raises(SettingsError, match=message):
        bake_vertex_maps(target, samples=4, **kw)
    with pytest.raises(SettingsError, match=message):
        bake_udim_maps(target, resolution=16, samples=4, **kw)


# -- the add-on's run (mc_ao.bakerun, no Blender): the jobs of one object's quantities in one bake -------

def arrays(mesh, name):
    from mc_ao.extract import MeshArrays

    return MeshArrays(name, mesh.positions, mesh.triangles.astype(np.int32),
                      None if mesh.uvs is None else mesh.uvs.astype(np.float32),
                      None if mesh.normals is None else mesh.normals.astype(np.float32))


@pytest.mark.parametrize("extra", [dict(), dict(ground="AUTO", ignore_backfaces=True), dict(use_udim=True),
                                   dict(target="VERTEX_COLORS")])
def test_the_add_on_bakes_an_objects_ao_and_thickness_in_one_bake(monkeypatch, extra):
    import core
    from mc_ao import baking, service
    from mc_ao.settings import BakeSettings

    if extra.get("target"):
        from core.geometry.corners import all_corners

        target = arrays(unwrapped_box(), "crate")
        target.extra = {"corners": all_corners(unwrapped_box())}
    else:
        target = arrays(unwrapped_box(), "crate")
    occ = [arrays(o, o.name) for o in occluders()]
    settings = BakeSettings(resolution=24, samples=8, margin=1, threads=1, processes=1,
                            quantity=("AO", "THICKNESS"), **extra)
    jobs = [baking.Job("crate", "crate_AO", target, occ, quantity="ao"),
            baking.Job("crate", "crate_Thickness", target, [], quantity="thickness")]
    calls = {"maps": 0, "single": 0}
    real = core.bake

    def counted(target, occluders, request, **k):  # the add-on's one core call: one request, one quantity or more
        calls["maps" if request.quantities is not None else "single"] += 1
        return real(target, occluders, request, **k)

    monkeypatch.setattr(core, "bake", counted)
    outcomes = service_run(service.plan(settings, jobs))
    assert [o.status for o in outcomes] == ["ok", "ok"], [o.error or o.trace for o in outcomes]
    assert calls == {"maps": 1, "single": 0}
    monkeypatch.undo()
    for job, outcome in zip(jobs, outcomes):
        same(outcome.results[None], job.run(settings, threads=1), job.quantity)
        assert outcome.results[None].metadata["quantities"] == "ao,thickness"
