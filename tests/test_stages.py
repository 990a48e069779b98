"""bench.sections.stages: the stage timer finds every function the bench names in the core, its
stages add up to the run's thread CPU time, and the core is left as it was."""

import numpy as np

from bench.harness.stagetimer import StageTimer, resolve
from bench.sections.stages import FIXED_STEPS, TILE_STAGES, bake, floors, scenes


def test_every_named_stage_is_in_the_core_and_the_table_adds_up():
    import core.engine.kernel
    import core.geometry.raster

    before = (core.engine.kernel.Kernel.__dict__["run"], core.geometry.raster.rasterize_tile)
    scene = scenes(["suzanne"])["suzanne"]
    timer = StageTimer(TILE_STAGES + FIXED_STEPS)
    with timer.run():
        r = bake(*scene, 32, 4)
    assert timer.missing == []
    rows = timer.table()
    assert abs(sum(s for _, s, _ in rows) - timer.total) < 1e-9
    calls = {label: c for label, _, c in rows}
    for label in ("rasterise", "kernel: gather", "kernel: Embree call", "surface table", "Embree scene"):
        assert calls[label] > 0, label
    assert r.rays > 0 and r.mask.any()
    # Unwrapped afterwards: the same function objects as before.
    assert (core.engine.kernel.Kernel.__dict__["run"], core.geometry.raster.rasterize_tile) == before


def test_a_function_imported_by_name_is_timed_where_it_is_called():
    import core.pipeline.run  # noqa: F401  (every module of a bake loaded)

    hits = resolve("rasterize_tile")
    assert hits and len({id(f) for _, _, f in hits}) == 1
    timer = StageTimer([("rasterise", "rasterize_tile")])
    with timer.run():
        # every module that holds the function by name holds the timed one
        assert all(getattr(owner, attr) is not f for owner, attr, f in hits)
    assert all(getattr(owner, attr) is f for owner, attr, f in hits)


def test_the_floors_are_read_from_floor_txt():
    f = floors()
    assert f[("smooth", 32)]["map"] > 0 and f[("flat", 64)]["gather"] > 0
    assert np.isclose(sum(f[("smooth", 32)].values()), 49.8, atol=0.2)
