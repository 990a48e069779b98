"""Every option of a bake through worker processes gives the bits of one process: generated from the
request's option list (core.base.request.OPTIONS), for every kind of bake that takes the option.

A planted bug once dropped an option on its way to the workers (a cage ignored: mean AO 0.13 off) and
the suite, which tested a hand-picked few options with workers, passed. Here each option gets a value
other than its default (derived from its kind, limits and choices; the few options whose values have a
shape of their own take one from VALUES, and an option of a new kind fails the test until it has one),
with what it needs to have an effect (NEEDS), and the bake with ``workers=2`` is compared with the bake
in this process, every array of every result, bit for bit.
"""

import dataclasses
import inspect
import math

import numpy as np
import pytest

from core import Mesh, bake
from core.base.request import OPTIONS, BakeRequest

SQUARE = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
FACES = np.array([[0, 1, 2], [0, 2, 3]])
#: What every case bakes unless its option says otherwise: small and quick, adaptive off.
BASE = dict(resolution=16, samples=8, margin=2, seed=0, max_distance=1.0)
#: Values of options whose kind has a shape of its own (the plain kinds are derived below).
VALUES = {
    "resolution": (24, 16),
    "threads": 2,
    "tile_size": 16,
    "ground": "auto",
    "extrusion": 0.1,
    "quantities": ("ao", "thickness"),
    "tiles": (1001,),
    "distance": 0.5,
}
#: What an option needs beside it to change the bake (or to be accepted at all).
SELECTED_TO_ACTIVE = {"highpoly": True}
NEEDS = {
    "min_samples": dict(target_error=0.05, samples=64),
    "target_error": dict(samples=64),
    "falloff": dict(max_distance=1.0),
    "extrusion": SELECTED_TO_ACTIVE,
    "max_ray_distance": SELECTED_TO_ACTIVE,
    "quantity": dict(bent_normals=False),
}
#: Options a worker gets as the parent settled them (the tiles the parent cut, the extrusion it measured,
#: each UDIM tile as an image of its own; the parent denoises), not as given. Threads reach each worker
#: as given: the threads of each.
WORKER_CHOSEN = {"tile_size", "extrusion", "tiles", "denoise"}
#: Options that are the execution path itself, not a setting it must carry.
NOT_CARRIED = {"workers": "the option under test: 1 here, 2 there"}
#: The bake's inputs beside the request (core.bake's keywords that are not callbacks), each with the
#: kinds that take it and what it needs: a cage, the bent normals' space and the corners reach the
#: workers as the options do.
CALLBACKS = {"progress", "cancel", "on_tile", "on_rays"}
INPUTS = {
    "highpoly": (("image", "udim"), {}),
    "cage": (("image", "udim"), {"highpoly": True}),
    "bent_space": (("image", "udim"), {"bent_normals": True}),
    "corners": (("corners",), {}),
}


def target(kind):
    uvs = SQUARE[FACES][:, :, :2]
    if kind == "udim":
        uvs = uvs * [2.0, 1.0]  # over tiles 1001 and 1002
    wavy = SQUARE + [[0, 0, 0.0], [0, 0, 0.05], [0, 0, 0.1], [0, 0, 0.02]]
    return Mesh(wavy, FACES, uvs=uvs, name="target")


def occluders():
    return [Mesh(SQUARE * [0.6, 0.6, 0] + [0.2, 0.2, 0.3], FACES, name="lid")]


def highpoly():
    return [Mesh(SQUARE + [0, 0, 0.03], FACES, name="high")]


def input_value(name, kind):
    """A value of one of the bake's inputs beside the request."""
    if name == "highpoly":
        return highpoly()
    if name == "cage":  # the target pushed out a little, unevenly: the matching rays start elsewhere
        t = target(kind)
        return Mesh(t.positions + [[0, 0, 0.1], [0, 0, 0.2], [0, 0, 0.15], [0, 0, 0.08]], t.triangles, name="cage")
    if name == "bent_space":  # a rotation: the bent normals in another frame
        c, s = math.cos(0.3), math.sin(0.3)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    if name == "corners":
        return np.array([[0, 0], [0, 2], [1, 1]])
    raise AssertionError(f"the bake's input {name!r} has no value to try: add one to input_value()")


def other_value(option, base):
    """A value of ``option`` other than the one the base case bakes with."""
    now = base.get(option.name, option.default)
    if option.name in VALUES:
        return VALUES[option.name]
    if option.kind in VALUES:
        return VALUES[option.kind]
    if option.kind == "bool":
        return not now
    if option.kind == "choice":
        return next(c for c in option.choices if c != now)
    if option.kind == "int":
        value = (now or 0) + 1 if option.hi is None or (now or 0) + 1 <= option.hi else (now or 0) - 1
        if option.name == "chunk_rays":
            value = 64  # many chunks: the chunking is what it changes
        return value
    if option.kind == "float":
        if now is None or not math.isfinite(now):
            return 0.5
        return now + 0.5 if now > 0 else 0.05 if option.lo is not None else 0.5
    raise AssertionError(f"option {option.name!r} of kind {option.kind!r} has no value to try: add one to VALUES")


def inputs():
    """core.bake's keywords beside the request, callbacks left out."""
    return [p.name for p in inspect.signature(bake).parameters.values()
            if p.kind == p.KEYWORD_ONLY and p.name not in CALLBACKS]


def cases():
    out = []
    for option in OPTIONS:
        if option.name in NOT_CARRIED:
            continue
        for kind in option.kinds:
            out.append(pytest.param(option.name, kind, id=f"{option.name}-{kind}"))
    for name in inputs():
        for kind in INPUTS.get(name, ((),))[0]:
            out.append(pytest.param(name, kind, id=f"{name}-{kind}"))
    return out


def arrays(obj, path="result", seen=None):
    """Every numpy array reachable from a result (fields, dicts, lists), with where it lies."""
    seen = set() if seen is None else seen
    if id(obj) in seen:
        return
    seen.add(id(obj))
    if isinstance(obj, np.ndarray):
        yield path, obj
    elif isinstance(obj, dict):
        for k in sorted(obj, key=str):
            yield from arrays(obj[k], f"{path}[{k!r}]", seen)
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            yield from arrays(v, f"{path}[{i}]", seen)
    elif dataclasses.is_dataclass(obj) or hasattr(obj, "__dict__"):
        fields = vars(obj) if hasattr(obj, "__dict__") else {f.name: getattr(obj, f.name) for f in
                                                             dataclasses.fields(obj)}
        for k, v in fields.items():
            if k not in ("report", "metadata", "seconds"):
                yield from arrays(v, f"{path}.{k}", seen)


def test_every_option_and_input_has_a_case():
    names = {o.name for o in OPTIONS} | set(inputs())
    assert set(inputs()) <= set(INPUTS), f"add the new inputs of core.bake to INPUTS: {set(inputs()) - set(INPUTS)}"
    assert {p.values[0] for p in cases()} | set(NOT_CARRIED) == names
    for option in OPTIONS:
        if option.name not in NOT_CARRIED:
            other_value(option, BASE)  # every option has a value to try


@pytest.mark.parametrize("name, kind", cases())
def test_worker_processes_give_the_bits_of_one_process(name, kind, monkeypatch):
    from core.execution import executor

    # Two workers of VALUES["threads"] threads each on any machine: the clamp by cores (tested in
    # tests/test_worker_boot.py) would bake them in this process where the cores are fewer, and the
    # option would never reach a worker.
    cores = executor.cpu_count()
    monkeypatch.setattr(executor, "cpu_count", lambda: max(cores, 2 * VALUES["threads"]))
    base = {k: v for k, v in BASE.items() if kind in next(o for o in OPTIONS if o.name == k).kinds}
    extra = {}
    if name in INPUTS:
        needs = dict(INPUTS[name][1])
        extra[name] = input_value(name, kind)
    else:
        needs = dict(NEEDS.get(name, {}))
    if needs.pop("highpoly", False):
        extra["highpoly"] = highpoly()
    settings = dict(base, **needs)
    if name not in INPUTS:
        settings[name] = other_value(next(o for o in OPTIONS if o.name == name), settings)
    request = BakeRequest(kind=kind, **settings)
    one = bake(target(kind), occluders(), request.replace(workers=1), **extra)
    two = bake(target(kind), occluders(), request.replace(workers=2), **extra)
    for result in two.values():
        tiles = getattr(result, "tiles", None)
        report = next(iter(tiles.values())).report if tiles else result.report
        # the tiles were baked by two worker processes (no fallback to this process's threads), each
        # with the option as given here (the request it baked with, as its report line says)
        assert [m["process"] for m in report["worker_memory"]] == ["parent", "worker 0", "worker 1"], report
        if name not in INPUTS:
            for m in report["worker_memory"][1:]:
                got = m["request"][name]
                assert got == settings[name] or list(np.atleast_1d(got)) == list(np.atleast_1d(settings[name])) \
                    or name in WORKER_CHOSEN, (name, got, settings[name])
    a, b = list(arrays(one)), list(arrays(two))
    assert [p for p, _ in a] == [p for p, _ in b] and a
    for (path, x), (_, y) in zip(a, b):
        assert x.dtype == y.dtype and x.shape == y.shape, path
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), f"{name} ({kind}): {path}"
