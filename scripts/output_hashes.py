"""Fingerprints of every output array the core bakes: the proof that a restructuring changed no bit.

    .venv/bin/python scripts/output_hashes.py                   # print the list
    .venv/bin/python scripts/output_hashes.py --check           # compare with the committed list of this numpy line
    .venv/bin/python scripts/output_hashes.py --write           # (re)write the committed list of this numpy line
    .venv/bin/python scripts/output_hashes.py -k udim           # only the cases whose name holds "udim"

Each case bakes a scene through the core's public calls (images, UDIM tiles, mesh corners, maps of
several quantities, selected to active, bent normals, denoise, worker processes, a Dask cluster) and
prints one line per array of its result: ``case field dtype shape sha256``; then a line for the
metadata and one for the report (their plain values, without the wall times and the processes'
memory, and any "...seconds"). The scenes are the tests' (a plane under a lid, boxes, UDIM tiles) and the bench's
(``bench/data/scene_suzanne.npz``, the displaced terrain under a low-poly plane), numpy only, so that
both numpy lines run it (no bpy: ``.venv-numpy2`` has none).

The committed lists are ``scripts/output_hashes/numpy<major>.txt``, one per numpy line: the bits of a
bake are the same for any threads, tiles and worker processes within one numpy line, not across them
(on main 56df36e the two lists differ only in the bent normals of the smooth-shaded Suzanne, in their last
bits, and in the Dask cases, which need ``distributed``: ``.venv-numpy2`` has none). A case that cannot run here (Dask without
``distributed``) prints ``skipped`` with the reason, so a list's lines are always the same cases.
A change that is meant to move bits (a new output version) rewrites the lists with ``--write`` and says so.
"""

import argparse
import dataclasses
import hashlib
import json
import math
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

import core  # noqa: E402
from core import Mesh  # noqa: E402

LISTS = ROOT / "scripts" / "output_hashes"
#: Report entries that depend on the machine, not on the bake: the processes' memory and where the
#: tiles ran (threads or processes: the cores, the pool) (and any entry named "...seconds": a time).
MACHINE_KEYS = {"worker_memory", "parallel"}
#: Result fields that are wall or CPU times.
TIME_FIELDS = {"seconds", "trace_seconds", "trace_cpu_seconds"}
QUAD = np.array([[0, 1, 2], [0, 2, 3]])


# -- scenes ------------------------------------------------------------------------------------------

def plane(x0=0.0, y0=0.0, x1=1.0, y1=1.0, z=0.0, name="plane"):
    p = np.array([[x0, y0, z], [x1, y0, z], [x1, y1, z], [x0, y1, z]], float)
    return Mesh(p, QUAD, (p[QUAD][:, :, :2] - [x0, y0]) / [x1 - x0, y1 - y0], name=name)


def box(lo, hi, name="box", uvs=False):
    """A closed axis-aligned box, outward winding; ``uvs``: each face its own cell of a 3 x 2 atlas."""
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    p = np.array([[x, y, z] for z in (z0, z1) for y in (y0, y1) for x in (x0, x1)], float)
    f = np.array([[0, 2, 3], [0, 3, 1], [4, 5, 7], [4, 7, 6], [0, 1, 5], [0, 5, 4],
                  [2, 6, 7], [2, 7, 3], [0, 4, 6], [0, 6, 2], [1, 3, 7], [1, 7, 5]])
    uv = None
    if uvs:
        cell = np.array([[[0.05, 0.05], [0.95, 0.05], [0.95, 0.95]], [[0.05, 0.05], [0.95, 0.95], [0.05, 0.95]]])
        uv = np.concatenate([(cell + [k % 3, k // 3]) / [3, 2] for k in range(6)])
    return Mesh(p, f, uv, name=name)


def lid():
    p = np.array([[0.25, 0.25, 0.3], [0.75, 0.25, 0.3], [0.75, 0.75, 0.3], [0.25, 0.75, 0.3]])
    return Mesh(p, QUAD, name="lid")


def suzanne():
    """The bench's scene (bench/data/scene_suzanne.npz): Suzanne (smooth, smart-project UVs) over a
    plane between two blocks; AO distance 1.5."""
    d = np.load(ROOT / "bench" / "data" / "scene_suzanne.npz", allow_pickle=False)
    target = Mesh(d["P"], d["F"], uvs=d["UV"], normals=d["N"], name="Suzanne")
    occ = [Mesh(d[f"O{i}P"], d[f"O{i}F"], name=f"occluder{i}") for i in range(int(d["occluders"]))]
    return target, occ, float(d["distance"])


def grid(n, size=4.0, amplitude=0.25, seed=0):
    """The bench's displaced grid (bench/harness/scene.py): (positions, triangles, uvs)."""
    rng = np.random.default_rng(seed)
    t = np.linspace(0.0, 1.0, n + 1)
    u, v = np.meshgrid(t, t)
    z = np.zeros_like(u)
    for _ in range(6):
        kx, ky = rng.uniform(1.0, 4.0, 2)
        ph = rng.uniform(0, 2 * math.pi, 2)
        z += np.sin(2 * math.pi * kx * u + ph[0]) * np.sin(2 * math.pi * ky * v + ph[1])
    z *= amplitude / 6 * 2
    p = np.stack([(u - 0.5) * size, (v - 0.5) * size, z], -1).reshape(-1, 3)
    uv = np.stack([u, v], -1).reshape(-1, 2)
    i = np.arange(n)
    a = (i[None, :] + (n + 1) * i[:, None]).ravel()
    quads = np.stack([a, a + 1, a + n + 2, a + n + 1], 1)
    f = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
    return p, f, uv[f]


def terrain():
    """The bench's selected-to-active terrain (bench/sections/highpoly.py), smaller: a low plane under
    a displaced high-poly grid, and the low plane's cage."""
    p, f, _ = grid(48)
    high = Mesh(p, f, name="terrain_high")
    low_p = np.array([[-2, -2, -0.5], [2, -2, -0.5], [2, 2, -0.5], [-2, 2, -0.5]], float)
    low = Mesh(low_p, QUAD, uvs=(low_p[QUAD][:, :, :2] + 2) / 4, name="terrain_low")
    cage = Mesh(low_p + [0, 0, 0.9], QUAD, name="terrain_cage")
    return low, high, cage


def udim_strip():
    """Three quads side by side, their UVs in tiles 1001, 1002 and 1011 (one triangle of the last
    crossing into 1012), under a lid."""
    quads = []
    for k, (du, dv) in enumerate(((0, 0), (1, 0), (0, 1))):
        p = np.array([[k, 0, 0], [k + 1, 0, 0], [k + 1, 1, 0], [k, 1, 0]], float)
        uv = np.array([[0.1, 0.1], [0.9, 0.1], [0.9 if k < 2 else 1.3, 0.9], [0.1, 0.9]]) + [du, dv]
        quads.append((p, uv))
    p = np.concatenate([q[0] for q in quads])
    f = np.concatenate([QUAD + 4 * k for k in range(3)])
    uv = np.concatenate([q[1][QUAD] for q in quads])
    cover = Mesh(np.array([[0.5, 0.2, 0.4], [2.5, 0.2, 0.4], [2.5, 0.8, 0.4], [0.5, 0.8, 0.4]]), QUAD, name="cover")
    return Mesh(p, f, uv, name="strip"), [cover]


def tangent_frames(mesh):
    """Tangent frames of ``mesh`` for a tangent-space bent-normal map: a tangent orthogonal to each
    corner's normal, sign +1, world space."""
    n = mesh.normals
    t = np.cross(n, [0.0, 0.0, 1.0])
    flat = np.linalg.norm(t, axis=-1) < 1e-6
    t[flat] = np.cross(n[flat], [1.0, 0.0, 0.0])
    t /= np.linalg.norm(t, axis=-1, keepdims=True)
    return core_bent().TangentFrames(t, np.ones(n.shape[:2]), n, np.eye(3))


def core_bent():
    """The core's bent-normal module."""
    from core.post import bent

    return bent


def core_imageio():
    from core.files import imageio

    return imageio


# -- the cases ----------------------------------------------------------------------------------------

def cases(dask_client):
    """(name, function returning a result, or {quantity: result}) of every case."""
    lid_plane = (plane(), [lid()])
    suz, suz_occ, suz_d = suzanne()
    low, high, cage = terrain()
    strip, strip_occ = udim_strip()
    cube = box((-0.5, -0.5, 0.0), (0.5, 0.5, 1.0), name="cube", uvs=True)
    base = dict(resolution=48, samples=32, threads=2)
    suz_kw = dict(resolution=96, samples=32, max_distance=suz_d, threads=2)
    out = []

    def add(name, fn):
        out.append((name, fn))

    # Images: the tests' plane under a lid, every sample source and distribution, the settings
    # that change the estimator.
    add("image/lid/default", lambda: core.bake_ao(*lid_plane, **base))
    for source in ("independent", "stratified", "halton"):
        add(f"image/lid/{source}", lambda source=source: core.bake_ao(*lid_plane, source=source, **base))
    add("image/lid/uniform", lambda: core.bake_ao(*lid_plane, distribution="uniform", **base))
    add("image/lid/falloff", lambda: core.bake_ao(*lid_plane, falloff=1.5, max_distance=0.6, **base))
    add("image/lid/replicates1", lambda: core.bake_ao(*lid_plane, replicates=1, seed=5, **base))
    add("image/lid/replicates4-margin0-tiles", lambda: core.bake_ao(*lid_plane, replicates=4, margin=0,
                                                                    tile_size=(16, 32), chunk_rays=999, **base))
    add("image/lid/adaptive", lambda: core.bake_ao(*lid_plane, resolution=48, samples=128, min_samples=8,
                                                   target_error=0.04, threads=2))
    add("image/lid/adaptive-halton-r1", lambda: core.bake_ao(*lid_plane, resolution=48, samples=128, min_samples=8,
                                                             target_error=0.04, source="halton", replicates=1,
                                                             threads=1))
    add("image/lid/backfaces", lambda: core.bake_ao(plane(), [lid(), plane(z=0.5, name="over")],
                                                    ignore_backfaces=True, **base))
    add("image/lid/seed-big-rect", lambda: core.bake_ao(*lid_plane, resolution=(40, 24), samples=20,
                                                        seed=(1 << 64) - 1, threads=1))
    add("image/boxes/ground-height", lambda: core.bake_ao(cube, [box((0.7, -0.5, 0), (1.2, 0.5, 0.6))],
                                                          ground=0.0, max_distance=2.0, **base))
    # The bench's scene.
    add("image/suzanne/default", lambda: core.bake_ao(suz, suz_occ, **suz_kw))
    add("image/suzanne/ground-auto", lambda: core.bake_ao(suz, [], ground="auto", **suz_kw))
    add("image/suzanne/thickness", lambda: core.bake_ao(suz, suz_occ, quantity="thickness", **suz_kw))
    add("image/cube/thickness", lambda: core.bake_ao(cube, [], quantity="thickness", max_distance=2.0, **base))
    add("image/suzanne/bent-world", lambda: core.bake_ao(suz, suz_occ, bent_normals=True, **suz_kw))
    add("image/suzanne/bent-matrix", lambda: core.bake_ao(suz, suz_occ, bent_normals=True,
                                                          bent_space=np.array([[0, 1, 0], [-1, 0, 0], [0, 0, 1.0]]),
                                                          **suz_kw))
    add("image/suzanne/bent-tangent", lambda: core.bake_ao(suz, suz_occ, bent_normals=True,
                                                           bent_space=tangent_frames(suz), **suz_kw))
    add("image/suzanne/denoise", lambda: core.bake_ao(suz, suz_occ, denoise=True, **suz_kw))
    add("image/lid/denoise-adaptive", lambda: core.bake_ao(*lid_plane, denoise=True, target_error=0.05,
                                                           samples=64, resolution=48, threads=2))
    # Maps of several quantities.
    add("maps/suzanne/ao-thickness", lambda: core.bake_maps(suz, suz_occ, **suz_kw))
    add("maps/suzanne/thickness-ao-bent-denoise", lambda: core.bake_maps(
        suz, suz_occ, quantities=("thickness", "ao"), bent_normals=True, denoise=True, ground="auto", **suz_kw))
    add("maps/cube/thickness-only", lambda: core.bake_maps(cube, [], quantities=["thickness"], max_distance=2.0,
                                                           **base))
    # UDIM tiles.
    add("udim/strip/default", lambda: core.bake_udim(strip, strip_occ, resolution=32, samples=32, threads=2))
    add("udim/strip/listed-tiles", lambda: core.bake_udim(strip, strip_occ, resolution=32, samples=16,
                                                          tiles=[1001, 1003, 1012], threads=1))
    add("udim/strip/denoise-bent", lambda: core.bake_udim(strip, strip_occ, resolution=32, samples=32, denoise=True,
                                                          bent_normals=True, threads=2))
    add("udim/strip/maps", lambda: core.bake_udim_maps(strip, strip_occ, resolution=32, samples=32, threads=2))
    # Mesh corners.
    add("corners/suzanne/default", lambda: core.bake_vertex_ao(suz, suz_occ, samples=32, max_distance=suz_d,
                                                               threads=2))
    add("corners/suzanne/no-merge-bent", lambda: core.bake_vertex_ao(suz, suz_occ, samples=16, max_distance=suz_d,
                                                                     merge=False, bent_normals=True, threads=2))
    add("corners/suzanne/denoise-ground-adaptive", lambda: core.bake_vertex_ao(
        suz, [], samples=64, min_samples=8, target_error=0.05, ground="auto", denoise=True, threads=2))
    add("corners/cube/some-corners", lambda: core.bake_vertex_ao(cube, [box((0.7, -0.5, 0), (1.2, 0.5, 0.6))],
                                                                 corners=np.array([[0, 0], [3, 2], [7, 1], [11, 2]]),
                                                                 samples=32, source="stratified", threads=1))
    add("corners/suzanne/maps", lambda: core.bake_vertex_maps(suz, suz_occ, samples=16, max_distance=suz_d,
                                                              threads=2))
    # Selected to active.
    s2a = dict(resolution=48, samples=32, max_distance=0.5, threads=2)
    add("s2a/terrain/extrusion", lambda: core.bake_ao(low, [], highpoly=[high], extrusion=1.0, **s2a))
    add("s2a/terrain/auto-extrusion", lambda: core.bake_ao(low, [], highpoly=high, **s2a))
    add("s2a/terrain/cage-max-ray", lambda: core.bake_ao(low, [], highpoly=[high], cage=cage, max_ray_distance=1.5,
                                                         **s2a))
    add("s2a/terrain/adaptive-ground", lambda: core.bake_ao(low, [], highpoly=[high], extrusion=1.0, ground="auto",
                                                            target_error=0.05, min_samples=8, resolution=48,
                                                            samples=64, max_distance=0.5, threads=2))
    add("s2a/terrain/maps", lambda: core.bake_maps(low, [], highpoly=[high], extrusion=1.0, **s2a))
    add("s2a/terrain/denoise", lambda: core.bake_ao(low, [], highpoly=[high], extrusion=1.0, denoise=True, **s2a))
    # Worker processes (the same bits as one process: the cases above again, on 2 workers).
    w2 = dict(workers=2, threads=1)
    add("workers2/suzanne/default", lambda: core.bake_ao(suz, suz_occ, **dict(suz_kw, **w2)))
    add("workers2/suzanne/maps-bent-denoise", lambda: core.bake_maps(suz, suz_occ, bent_normals=True, denoise=True,
                                                                     **dict(suz_kw, **w2)))
    add("workers2/corners/suzanne", lambda: core.bake_vertex_ao(suz, suz_occ, samples=32, max_distance=suz_d, **w2))
    add("workers2/corners/maps", lambda: core.bake_vertex_maps(suz, suz_occ, samples=16, max_distance=suz_d, **w2))
    add("workers2/s2a/terrain", lambda: core.bake_ao(low, [], highpoly=[high], extrusion=1.0,
                                                     **dict(s2a, **w2)))
    add("workers2/udim/strip", lambda: core.bake_udim(strip, strip_occ, resolution=32, samples=32, **w2))
    add("workers2/auto", lambda: core.bake_ao(*lid_plane, resolution=48, samples=32, workers="auto"))
    # A Dask cluster.
    if dask_client is None:
        add("dask/suzanne/default", None)
        add("dask/suzanne/maps", None)
    else:
        add("dask/suzanne/default", lambda: core.bake_ao(suz, suz_occ, **dict(suz_kw, workers=dask_client, threads=1)))
        add("dask/suzanne/maps", lambda: core.bake_maps(suz, suz_occ, **dict(suz_kw, workers=dask_client, threads=1)))
    # Files: the AO written and read back (the pixels a user gets).
    add("files/lid/png8-exr-half", lambda: files(core.bake_ao(*lid_plane, **base)))
    return out


def files(result):
    """A result written as an 8-bit PNG and a half-float EXR and read back: {name: pixels}."""
    imageio = core_imageio()
    with tempfile.TemporaryDirectory() as tmp:
        png, exr = Path(tmp) / "ao.png", Path(tmp) / "ao.exr"
        imageio.write_image(png, result.ao)
        imageio.write_image(exr, result.ao, bits="half")
        return {"png8": imageio.read_image(png)[0], "exr_half": imageio.read_image(exr)[0]}


# -- fingerprints -------------------------------------------------------------------------------------

def digest(a):
    a = np.ascontiguousarray(a)
    return hashlib.sha256(a.tobytes()).hexdigest()[:20]


def plain(value):
    """JSON-able plain data of ``value`` (dicts, lists, numbers, strings; a dataclass as its fields that
    are set, not None: the report, a dict before it had named fields, compares as it did)."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        value = {f.name: getattr(value, f.name) for f in dataclasses.fields(value) if getattr(value, f.name) is not None}
    if isinstance(value, dict):
        return {str(k): plain(v) for k, v in sorted(value.items(), key=lambda kv: str(kv[0]))
                if k not in MACHINE_KEYS and not str(k).endswith("seconds")}
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    if isinstance(value, np.ndarray):
        return f"array {value.dtype} {value.shape} {digest(value)}"
    if isinstance(value, (np.integer,)):
        return int(value)
    if isinstance(value, (np.floating, float)):
        return repr(float(value))
    return value


def result_lines(name, result):
    """The lines of one result: each array field, then the scalars, metadata and report."""
    if isinstance(result, dict) and all(isinstance(v, np.ndarray) for v in result.values()):
        return [f"{name} {k} {v.dtype} {'x'.join(map(str, v.shape))} {digest(v)}" for k, v in sorted(result.items())]
    lines = []
    fields = [f.name for f in dataclasses.fields(result)]
    for field in fields:
        value = getattr(result, field)
        if field in TIME_FIELDS or value is None:
            continue
        if isinstance(value, np.ndarray):
            lines.append(f"{name} {field} {value.dtype} {'x'.join(map(str, value.shape))} {digest(value)}")
        elif field == "tiles":
            for tile, r in sorted(value.items()):
                lines.extend(result_lines(f"{name}[{tile}]", r))
        elif field in ("metadata", "report"):
            text = json.dumps(plain(value), sort_keys=True)
            lines.append(f"{name} {field} {hashlib.sha256(text.encode()).hexdigest()[:20]}")
        else:
            lines.append(f"{name} {field} {plain(value)}")
    return lines


def run(pattern=None, verbose=False):
    dask_client = cluster = None
    try:
        import distributed
    except ImportError:
        distributed = None
    todo = [c for c in cases(None) if pattern is None or pattern in c[0]]
    if distributed is not None and any(name.startswith("dask/") for name, _ in todo):
        cluster = distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                           dashboard_address=None, silence_logs=40)
        dask_client = distributed.Client(cluster)
        dask_client.run(lambda: __import__("sys").path.insert(0, str(ROOT)))
        todo = [c for c in cases(dask_client) if pattern is None or pattern in c[0]]
    lines = []
    try:
        for name, fn in todo:
            t = time.perf_counter()
            if fn is None:
                lines.append(f"{name} skipped (no distributed in this environment)")
                continue
            out = fn()
            if isinstance(out, dict) and not all(isinstance(v, np.ndarray) for v in out.values()):
                for q, r in out.items():
                    lines.extend(result_lines(f"{name}:{q}", r))
            else:
                lines.extend(result_lines(name, out))
            if verbose:
                print(f"# {name}: {time.perf_counter() - t:.1f} s", file=sys.stderr)
    finally:
        if dask_client is not None:
            dask_client.close()
            cluster.close()
    return lines


def list_path():
    return LISTS / f"numpy{np.__version__.split('.')[0]}.txt"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true", help="compare with the committed list of this numpy line")
    ap.add_argument("--write", action="store_true", help="write the committed list of this numpy line")
    ap.add_argument("-k", dest="pattern", help="only the cases whose name holds this")
    ap.add_argument("-v", "--verbose", action="store_true", help="each case's time on stderr")
    args = ap.parse_args(argv)
    lines = run(args.pattern, args.verbose)
    header = f"# scripts/output_hashes.py, numpy {np.__version__.split('.')[0]}.x"
    if args.write:
        list_path().parent.mkdir(exist_ok=True)
        list_path().write_text("\n".join([header] + lines) + "\n")
        print(f"wrote {len(lines)} lines to {list_path().relative_to(ROOT)}")
        return 0
    if args.check:
        want = [line for line in list_path().read_text().splitlines() if not line.startswith("#")]
        if args.pattern is not None:
            names = {line.split(" ", 1)[0].split("[")[0].split(":")[0] for line in lines}
            want = [line for line in want if line.split(" ", 1)[0].split("[")[0].split(":")[0] in names]
        if want == lines:
            print(f"equal: {len(lines)} lines, {list_path().relative_to(ROOT)}")
            return 0
        import difflib

        sys.stdout.writelines(difflib.unified_diff([w + "\n" for w in want], [line + "\n" for line in lines],
                                                   str(list_path().relative_to(ROOT)), "this tree"))
        print(f"DIFFERENT from {list_path().relative_to(ROOT)}")
        return 1
    print("\n".join(lines))
    return 0


if __name__ == "__main__":
    sys.exit(main())
