"""The bake request (core.base.request): every option defined once, checked once, the same through every
public call and into a worker process; the public calls stay narrow."""

import inspect
import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import core
from core import SettingsError, bake, bake_ao, bake_maps, bake_udim, bake_udim_maps, bake_vertex_ao, bake_vertex_maps
from core.base.request import BY_NAME, KINDS, OPTIONS, BakeRequest
from scenes import plane

ROOT = Path(__file__).resolve().parent.parent
CALLS = {"bake_ao": ("image", bake_ao), "bake_maps": ("image", bake_maps), "bake_udim": ("udim", bake_udim),
         "bake_udim_maps": ("udim", bake_udim_maps), "bake_vertex_ao": ("corners", bake_vertex_ao),
         "bake_vertex_maps": ("corners", bake_vertex_maps)}
#: A value other than the default that every option takes (checked below against its limits).
OTHER = {"samples": 8, "min_samples": 4, "target_error": 0.05, "distribution": "uniform", "source": "halton", "seed": 7,
         "replicates": 3, "max_distance": 2.5, "falloff": 1.0, "ignore_backfaces": True, "ground": -0.25,
         "quantity": "thickness", "quantities": ("thickness", "ao"), "thickness_distance": 0.25, "resolution": (24, 16), "margin": 3,
         "tiles": (1001, 1002), "empty_ok": True, "merge": False, "extrusion": 0.05, "max_ray_distance": 0.5,
         "bent_normals": True, "denoise": True, "fix_seams": False, "threads": 2, "workers": 2, "tile_size": (32, 16),
         "chunk_rays": 4096, "constant_answer": True}


def lid():
    from core import Mesh

    p = np.array([[0.25, 0.25, 0.3], [0.75, 0.25, 0.3], [0.75, 0.75, 0.3], [0.25, 0.75, 0.3]])
    return Mesh(p, np.array([[0, 1, 2], [0, 2, 3]]), name="lid")


def test_the_request_module_loads_neither_numpy_nor_embreex():
    code = ("import sys; import core.base.request as r; r.BakeRequest(samples=4); import core; core.__version__; "
            "assert not {'numpy', 'embreex', 'OpenImageIO'} & set(sys.modules), sorted(sys.modules)")
    subprocess.run([sys.executable, "-c", code], cwd=ROOT, check=True)


def test_every_option_is_defined_once_with_a_kind_a_default_a_group_and_a_meaning():
    assert len(BY_NAME) == len(OPTIONS) and set(OTHER) == set(BY_NAME)
    for o in OPTIONS:
        assert o.meaning and o.group in ("sampling", "rays", "target", "selected_to_active", "outputs", "execution")
        assert set(o.kinds) <= set(KINDS) and o.kinds
        assert getattr(BakeRequest(), o.name) == (tuple(o.default) if isinstance(o.default, list) else o.default)
        assert OTHER[o.name] != o.default, o.name


def test_the_sources_option_lists_the_point_sets_the_library_has():
    from core.base.request import SOURCES
    from core.montecarlo import sources

    assert set(BY_NAME["source"].choices) == set(SOURCES) == set(sources.SOURCES)
    for cls in sources.SOURCES.values():  # each point set says its own rules for the bake's pools
        assert cls.reorder in ("xor", "offset") and cls.shift in ("xor", "add") and 0 < cls.error_rate <= 1
        assert cls.pattern_span(100) in (cls.pattern_length(100), 2 * cls.pattern_length(100))


@pytest.mark.parametrize("name", sorted(BY_NAME))
def test_each_option_round_trips_through_plain_data(name):
    """What a worker process gets: plain data (JSON can hold it, infinity aside), the same request back."""
    kind = "udim" if name == "tiles" else "corners" if name == "merge" else "image"
    value = OTHER[name]
    extra = {"falloff": {"max_distance": 2.0}}.get(name, {})  # what the rules between options ask beside it
    r = BakeRequest(kind=kind, **{name: value}, **extra)
    plain = r.to_dict()
    assert BakeRequest.from_dict(plain) == r
    json.dumps({k: v for k, v in plain.items() if not (isinstance(v, float) and math.isinf(v))})
    assert getattr(BakeRequest.from_dict(plain), name) == (tuple(value) if isinstance(value, list) else value)


@pytest.mark.parametrize("call", sorted(CALLS))
def test_an_unknown_keyword_names_the_closest_option(call):
    kind, fn = CALLS[call]
    with pytest.raises(TypeError, match=rf"{call}\(\) got an unexpected keyword argument 'sampels'; did you mean "
                                        r"'samples'\?"):
        fn(plane(), sampels=4)
    with pytest.raises(TypeError, match=r"'min_sample'; did you mean 'min_samples'"):
        fn(plane(), min_sample=4)


def test_an_option_of_another_kind_of_bake_is_refused_by_name():
    with pytest.raises(TypeError, match=r"bake_vertex_ao\(\) got an unexpected keyword argument 'margin': margin "
                                        r"applies to bakes of images and UDIM tiles, not of mesh corners"):
        bake_vertex_ao(plane(), margin=2)
    with pytest.raises(TypeError, match=r"'tiles': tiles applies to bakes of UDIM tiles, not of images"):
        bake_ao(plane(), tiles=[1001])
    with pytest.raises(TypeError, match=r"'quantities': it bakes one quantity"):
        bake_ao(plane(), quantities=("ao",))
    with pytest.raises(TypeError, match=r"bake_maps\(\) got an unexpected keyword argument 'quantity'"):
        bake_maps(plane(), quantity="ao")


def test_no_public_bake_call_spells_out_more_than_twelve_parameters():
    for name in ("bake", *CALLS):
        params = [p for p in inspect.signature(getattr(core, name)).parameters.values()
                  if p.kind is not inspect.Parameter.VAR_KEYWORD]
        assert len(params) <= 12, (name, len(params))


def test_a_bad_value_is_refused_once_with_the_options_name():
    for name, bad in (("samples", 0), ("seed", -1), ("margin", -1), ("replicates", 17), ("threads", 0),
                      ("distribution", "gaussian"), ("source", "random"), ("workers", 0), ("quantity", "ao2"),
                      ("quantities", ("ao", "ao")), ("tiles", (3,)), ("ground", "floor"), ("extrusion", -1.0),
                      ("max_ray_distance", -1.0), ("max_distance", 0.0), ("falloff", -1.0), ("target_error", -1.0),
                      ("resolution", 0), ("tile_size", 0), ("chunk_rays", 0), ("min_samples", 0), ("denoise", "yes")):
        with pytest.raises(SettingsError) as e:
            BakeRequest(kind="udim" if name == "tiles" else "image", **{name: bad})
        assert name.split("_")[0] in str(e.value).replace(" ", "_") or name in str(e.value), (name, str(e.value))
    with pytest.raises(SettingsError, match="denoise needs replicates >= 2"):
        BakeRequest(denoise=True, replicates=1)
    with pytest.raises(SettingsError, match="finite max_distance"):
        BakeRequest(falloff=1.0)
    with pytest.raises(SettingsError, match="does not apply to a thickness map"):
        BakeRequest(quantity="thickness", ground="auto")
    BakeRequest(quantities=("thickness", "ao"), ground="auto", ignore_backfaces=True, bent_normals=True)  # AO's only


def test_bake_of_a_request_is_the_bits_of_the_call_of_its_kind():
    target, occ = plane(), [lid()]
    args = dict(samples=16, seed=3, max_distance=2.0, threads=1)
    for kind, call, extra in (("image", bake_ao, dict(resolution=16)), ("corners", bake_vertex_ao, {}),
                              ("udim", bake_udim, dict(resolution=16))):
        want = call(target, occ, **extra, **args)
        got = bake(target, occ, BakeRequest(kind=kind, **extra, **args))["ao"]
        for field in ("ao", "stderr", "samples", "mask"):
            assert np.array_equal(getattr(want, field), getattr(got, field)), (kind, field)
        assert want.metadata == got.metadata
    maps = bake(target, occ, BakeRequest(resolution=16, quantities=("ao", "thickness"), **args))
    ref = bake_maps(target, occ, resolution=16, **args)
    for q in ("ao", "thickness"):
        assert np.array_equal(maps[q].ao, ref[q].ao) and maps[q].metadata == ref[q].metadata


def test_a_request_reaches_the_worker_processes_whole(monkeypatch):
    """Every option that goes to a worker arrives as given: the job's plain request, rebuilt there
    (core.pipeline.remote.build), is the parent's request with the tiles the parent chose."""
    from core.execution import executor

    sent = []
    run_tiles = executor.run_tiles

    def capture(remote, processes, threads, job, *args):
        sent.append(BakeRequest.from_dict(job["request"]))
        return run_tiles(remote, processes, threads, job, *args)

    monkeypatch.setattr(executor, "run_tiles", capture)
    target, occ = plane(), [lid()]
    options = dict(resolution=16, samples=8, source="stratified", seed=11, max_distance=2.0, ground=-0.5, margin=2,
                   threads=1, tile_size=16)
    r = BakeRequest(workers=2, **options)
    out = bake(target, occ, r)["ao"]
    assert sent == [r.replace(tile_size=(16, 16))], "the bake did not go to worker processes whole"
    for entry in out.report.worker_memory[1:]:  # each worker says what it baked with
        assert BakeRequest.from_dict(entry["request"]) == r.replace(tile_size=(16, 16), threads=1)
    ref = bake_ao(target, occ, **options)
    assert np.array_equal(out.ao, ref.ao) and np.array_equal(out.stderr, ref.stderr)
