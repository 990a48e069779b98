"""The panel's estimate against the bakes it prices: each setting, on the bench's scenes.

For each case (a sample scene, its objects, a setting changed from the defaults) this opens the
scene in the bpy module with the add-on registered, reads the estimate the panel would show
(mc_ao.baking.bake_cost with the machine's load at that moment, the threads and processes the
operator takes), then clicks Bake AO as a script does (bpy.ops.object.mc_ao_bake(), which returns
when the bake is done) and times it. The ratio is estimate / measured; the target is 0.5-2 on this
machine. The panel's estimate is calibrated by the bakes before it in the session (mc_ao.baking.
calibrated): the cases run in order as a user's session does, the first uncalibrated; the table has
the uncalibrated ratio too. The load average before each bake is in the table: on a shared machine it is the larger
part of a bake's time, and the estimate reads it.

Run: ``.venv/bin/python -m bench.sections.estimate [--samples 64] [--resolution 512] [--only NAME ...]
[--json bench/results/estimate.json] [--check]`` (``--check``: exit 1 when a ratio is outside 0.5-2).
"""

import argparse
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

SCENES = ROOT / "sample_scenes"

#: (name, .blend file, objects to select (the active last), settings beside the defaults).
CASES = [
    ("AO", "suzanne", ["Suzanne"], {}),
    ("AO, 4x samples", "suzanne", ["Suzanne"], {"samples": "x4"}),
    ("AO, 2x size", "suzanne", ["Suzanne"], {"resolution": "x2"}),
    ("Denoise", "suzanne", ["Suzanne"], {"denoise": True}),
    ("Thickness", "suzanne", ["Suzanne"], {"quantity": {"THICKNESS"}, "max_distance": 0.2}),
    ("AO and thickness", "suzanne", ["Suzanne"], {"quantity": {"AO", "THICKNESS"}, "max_distance": 0.2}),
    ("Bent normals", "suzanne", ["Suzanne"], {"bent_normals": True}),
    ("Error map", "suzanne", ["Suzanne"], {"error_map": True}),
    ("Adaptive 0.01", "suzanne", ["Suzanne"], {"target_error": 0.01}),
    ("Ground", "props", ["Crate", "Barrel"], {"ground": "AUTO"}),
    ("Color attribute", "suzanne", ["Suzanne"], {"target": "VERTEX_COLORS"}),
    ("Two objects", "suzanne", ["Ground", "Suzanne"], {}),
    ("Room, distance 1", "room", ["Table", "Crate"], {"max_distance": 1.0}),
    ("UDIM", "udim", ["Bust"], {"use_udim": True}),
    ("Selected to Active", "rock", ["Rock_high", "Rock_low"], {"use_selected_to_active": True,
                                                               "cage_extrusion": 0.1}),
    ("Dense terrain", "dense", ["Terrain"], {"samples": "x0.5"}),
]


def run_case(bpy, name, blend, objects, values, samples, resolution):
    from mc_ao import baking, operators
    from mc_ao.properties import resolve_threads
    from mc_ao.settings import BakeSettings

    bpy.ops.wm.open_mainfile(filepath=str(SCENES / f"{blend}.blend"), load_ui=False)
    scene = bpy.context.scene
    s = scene.mc_ao
    s.samples, s.resolution = samples, resolution
    for key, value in values.items():
        if isinstance(value, str) and value.startswith("x"):
            value = max(1, int(getattr(s, key) * float(value[1:])))
        setattr(s, key, value)
    layer = bpy.context.view_layer
    for obj in layer.objects:
        obj.select_set(obj.name in objects)
    layer.objects.active = bpy.data.objects[objects[-1]]
    settings = BakeSettings.from_properties(s).in_effect()
    choice, reason = operators.choice_of(bpy.context)
    if reason is not None:
        raise RuntimeError(f"{name}: {reason}")
    kwargs = {}
    if settings.use_selected_to_active:
        from mc_ao import selected_to_active

        kwargs = dict(highpoly=selected_to_active.high_objects(bpy.context.selected_objects, layer.objects.active,
                                                               None), cage=None)
    load = os.getloadavg()[0]
    raw = baking.bake_cost(settings, choice.targets, bpy.context.evaluated_depsgraph_get(),
                           selected=bpy.context.selected_objects, view_layer=layer,
                           threads=resolve_threads(bpy.context, settings), **kwargs)
    estimate = baking.calibrated(raw)  # what the panel shows: learnt from this session's bakes before
    start = time.perf_counter()
    result = bpy.ops.object.mc_ao_bake()
    measured = time.perf_counter() - start
    if result != {"FINISHED"}:
        raise RuntimeError(f"{name}: the bake ended with {result}: {operators.last_outcome}")
    return {"case": name, "scene": blend, "estimate_s": round(estimate.seconds, 3), "measured_s": round(measured, 3),
            "ratio": round(estimate.seconds / measured, 3), "uncalibrated_ratio": round(raw.seconds / measured, 3),
            "load_before": round(load, 2),
            "load_after": round(os.getloadavg()[0], 2), "estimate_text": estimate.describe()}


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=64)
    ap.add_argument("--resolution", type=int, default=512)
    ap.add_argument("--only", nargs="*", help="cases whose name contains one of these")
    ap.add_argument("--json", type=Path)
    ap.add_argument("--check", action="store_true", help="exit 1 when a ratio is outside 0.5-2")
    args = ap.parse_args(argv)
    import bpy

    import mc_ao

    mc_ao.register()
    rows = []
    print(f"{'case':22s} {'estimate':>9s} {'measured':>9s} {'ratio':>6s} {'uncal.':>6s} {'load':>5s}")
    for name, blend, objects, values in CASES:
        if args.only and not any(o.lower() in name.lower() for o in args.only):
            continue
        row = run_case(bpy, name, blend, objects, values, args.samples, args.resolution)
        rows.append(row)
        print(f"{name:22s} {row['estimate_s']:8.2f}s {row['measured_s']:8.2f}s {row['ratio']:6.2f} "
              f"{row['uncalibrated_ratio']:6.2f} {row['load_before']:5.1f}", flush=True)
    ratios = [r["ratio"] for r in rows]
    outside = [r["case"] for r in rows if not 0.5 <= r["ratio"] <= 2.0]
    print(f"ratios {min(ratios):.2f}-{max(ratios):.2f}; outside 0.5-2: {outside or 'none'}")
    if args.json:
        args.json.write_text(json.dumps({"samples": args.samples, "resolution": args.resolution, "cpus": os.cpu_count(),
                                         "rows": rows}, indent=1))
    return 1 if args.check and outside else 0


if __name__ == "__main__":
    sys.exit(main())
