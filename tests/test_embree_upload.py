"""The C-API upload of triangle meshes into Embree (core.tracing.embree_upload) against embreex's own
TriangleMesh: the same scene for Embree, so the same answer to every ray, and the bake is the same
either way."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from core import Mesh, bake_ao
from core.tracing import embree_upload
from core.tracing.tracer import OCCLUSION_ROBUST, embree_scene

ROOT = Path(__file__).resolve().parents[1]


def _binding_scene(positions, triangles, robust=True):
    """embreex's own TriangleMesh scene."""
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    scene = rtcore_scene.EmbreeScene(robust=robust)
    TriangleMesh(scene, np.asarray(positions, np.float32), np.asarray(triangles, np.int32))
    return scene


def _grid(n, seed=0):
    rng = np.random.default_rng(seed)
    t = np.linspace(0, 1, n + 1)
    u, v = np.meshgrid(t, t)
    z = 0.1 * np.sin(7 * u + rng.uniform(0, 6)) * np.cos(5 * v)
    positions = np.stack([u, v, z], -1).reshape(-1, 3)
    a = (np.arange(n)[None, :] + (n + 1) * np.arange(n)[:, None]).ravel()
    tris = np.concatenate([np.stack([a, a + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + n + 1], 1)])
    uvs = positions[:, :2][tris]
    return positions, tris, uvs


def test_available_here():
    """Where embreex's wheel is installed (CI, the add-on's wheels), the fast path is on; if this fails,
    reason() says what changed in embreex."""
    assert embree_upload.available(), embree_upload.reason()


def _rays(n=50_000, seed=3):
    rng = np.random.default_rng(seed)
    org = np.column_stack([rng.uniform(-0.2, 1.2, (n, 2)), rng.uniform(-0.5, 0.5, n)]).astype(np.float32)
    return org, rng.normal(size=(n, 3)).astype(np.float32)


def test_same_answers_as_the_binding():
    """Intersections (primitive, distance, barycentrics) and occlusion agree ray for ray with
    embreex's own scene, robust or not."""
    positions, tris, _ = _grid(60)
    mesh = Mesh(positions, tris, None, name="grid")
    org, dirs = _rays()
    n = len(org)
    for robust in (True, False):
        mine = embree_scene([mesh], robust=robust)[0]
        theirs = _binding_scene(positions, tris, robust=robust)
        a = mine.run(org, dirs, output=True)
        b = theirs.run(org, dirs, output=True)
        for key in ("primID", "geomID", "tfar", "u", "v", "Ng"):
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)
        assert 0.1 < (a["primID"] >= 0).mean() < 0.9  # both hits and misses were asked
        occ_a = mine.run(org, dirs, query="OCCLUDED", dists=np.full(n, 0.3, np.float32))
        occ_b = theirs.run(org, dirs, query="OCCLUDED", dists=np.full(n, 0.3, np.float32))
        np.testing.assert_array_equal(occ_a >= 0, occ_b >= 0)


def _sphere(n, seed=0):
    """A closed, slightly bumpy UV sphere of 2n(2n - 2) triangles about the origin."""
    th, ph = np.linspace(0, np.pi, n + 1)[1:-1], np.linspace(0, 2 * np.pi, 2 * n, endpoint=False)
    t, p = np.meshgrid(th, ph, indexing="ij")
    pos = np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], -1).reshape(-1, 3)
    pos = np.vstack([pos, [[0, 0, 1], [0, 0, -1]]])
    m = 2 * n
    i, j = np.meshgrid(np.arange(n - 2), np.arange(m), indexing="ij")
    a, b = (i * m + j).ravel(), (i * m + (j + 1) % m).ravel()
    top, bottom, last = len(pos) - 2, len(pos) - 1, (n - 2) * m
    ring = np.arange(m)
    tris = np.concatenate([np.stack([a, a + m, b], 1), np.stack([b, a + m, b + m], 1),
                           np.stack([np.full(m, top), ring, (ring + 1) % m], 1),
                           np.stack([np.full(m, bottom), last + (ring + 1) % m, last + ring], 1)])
    pos *= 1 + 0.01 * np.random.default_rng(seed).standard_normal((len(pos), 1))
    return pos, tris


def test_occlusion_scene_without_robust_mode():
    """The bake traces its occlusion rays in a scene without Embree's robust mode (OCCLUSION_ROBUST,
    chosen for speed), everything else in robust scenes. What that gives up, measured on a closed
    sphere: of a million rays from inside it in random directions at most ten leak through without
    robust mode and none with it; rays aimed exactly at its shared edges and vertices leak through
    without robust mode more than five times as often as with it (robust mode does its job)."""
    assert OCCLUSION_ROBUST is False
    positions, tris = _sphere(120)
    fast, robust = embree_scene([Mesh(positions, tris, None, name="sphere")], robust=False)[0], \
        embree_scene([Mesh(positions, tris, None, name="sphere")])[0]
    assert embree_upload.scene_flags(fast) == 0
    assert embree_upload.scene_flags(robust) == embree_upload.RTC_SCENE_FLAG_ROBUST
    rng = np.random.default_rng(5)
    n = 1_000_000
    org = rng.uniform(-0.5, 0.5, (n, 3)).astype(np.float32)  # well inside (radius 1 +- 3%)
    dirs = rng.normal(size=(n, 3))
    dirs = (dirs / np.linalg.norm(dirs, axis=1, keepdims=True)).astype(np.float32)
    far = np.full(n, 10, np.float32)
    leaks = [int((scene.run(org, dirs, query="OCCLUDED", dists=far.copy()) < 0).sum()) for scene in (fast, robust)]
    # Random rays pass within a rounding error of an edge about once in a million.
    assert leaks[1] == 0 and leaks[0] <= 10, leaks
    edges = np.concatenate([tris[:, [0, 1]], tris[:, [1, 2]], tris[:, [2, 0]]])
    aim = np.concatenate([positions, 0.5 * (positions[edges[:, 0]] + positions[edges[:, 1]])])
    org = rng.normal(scale=0.1, size=aim.shape).astype(np.float32)
    d = (aim - org).astype(np.float32)
    far = np.full(len(d), 10, np.float32)
    aimed = [(scene.run(org, d, query="OCCLUDED", dists=far.copy()) < 0).mean() for scene in (fast, robust)]
    assert aimed[1] < 0.01 and aimed[0] > 5 * aimed[1], aimed  # robust mode does what it is for


def test_which_scenes_are_robust():
    """The bake's occlusion rays go to a scene without robust mode; its contact probes and the
    high-poly matching rays, which start on surfaces, to robust scenes (without robust mode a
    low-poly plane lying on the high-poly one finds nothing: tests/test_highpoly.py)."""
    from core.highpoly.scene import HighPolyScene
    from core.highpoly.input import SelectedToActive
    from core.tracing.tracer import Tracer

    positions, tris, uvs = _grid(4)
    low, occ = Mesh(positions, tris, uvs, name="low"), Mesh(positions + [0, 0, 0.5], tris, None, name="occ")
    tracer = Tracer([low, occ])
    robust = embree_upload.RTC_SCENE_FLAG_ROBUST
    assert embree_upload.scene_flags(tracer.scene) == 0
    assert embree_upload.scene_flags(tracer.contact_scene) == robust
    for occluders in ([], [occ]):
        s2a = SelectedToActive.check(low, [Mesh(positions + [0, 0, 0.01], tris, None, name="high")], 0.1, 0.0, None)
        hp = HighPolyScene(s2a, occluders, False, 0.0, float("inf"))
        assert embree_upload.scene_flags(hp.tracer.scene) == 0
        assert embree_upload.scene_flags(hp.match_scene) == robust


def test_several_meshes_and_vertex_offsets():
    """Meshes concatenated into one geometry: triangle k of the second mesh is found as primitive
    len(first) + k, at the position of the second mesh's vertices."""
    p1, t1, _ = _grid(3)
    p2 = p1 + [0, 0, 1.0]
    mine = embree_scene([Mesh(p1, t1, None, name="a"), Mesh(p2, t1, None, name="b")])[0]
    org = np.array([[0.3, 0.3, 2.0], [0.3, 0.3, 0.5]], np.float32)
    out = mine.run(org, np.array([[0, 0, -1]], np.float32), output=True)
    assert out["primID"][0] >= len(t1) and out["primID"][1] < len(t1)
    np.testing.assert_allclose(out["tfar"], [2.0 - 1.0 - 0.1 * np.sin(7 * 0.3) * np.cos(1.5), 0.5], atol=0.2)


def test_bake_identical_with_either_upload(monkeypatch):
    """The bake does not know which path built its scene: bit-identical AO."""
    positions, tris, uvs = _grid(40)
    lid = Mesh(np.array([[0, 0, 0.3], [1, 0, 0.3], [1, 1, 0.3], [0, 1, 0.3]]) * [0.6, 0.6, 1] + [0.2, 0.2, 0],
               np.array([[0, 1, 2], [0, 2, 3]]), None, name="lid")
    target = Mesh(positions, tris, uvs, name="grid")
    kw = dict(resolution=32, samples=16, threads=1, max_distance=0.5, seed=5)
    fast = bake_ao(target, [lid], **kw).ao
    monkeypatch.setitem(embree_upload._state, "ok", False)
    slow = bake_ao(target, [lid], **kw).ao
    np.testing.assert_array_equal(fast, slow)


def test_refuses_a_committed_scene_and_bad_indices():
    positions, tris, _ = _grid(2)
    scene = _binding_scene(positions, tris)
    scene.run(np.zeros((1, 3), np.float32), np.array([[0, 0, 1]], np.float32))  # commits
    with pytest.raises(ValueError, match="committed"):
        embree_upload.attach_triangles(scene, positions, tris)
    from embreex import rtcore_scene

    with pytest.raises(ValueError, match="vertex that does not exist"):
        embree_upload.attach_triangles(rtcore_scene.EmbreeScene(), positions, tris + len(positions))


def test_layout_check_refuses_other_objects():
    """The scene handle is read only from an object laid out as embreex's EmbreeScene."""

    class EmbreeScene:  # same name, different object
        is_committed = 0

    with pytest.raises(TypeError):
        embree_upload._scene_handle(EmbreeScene())


def test_environment_turns_it_off():
    """MC_AO_EMBREE_UPLOAD=0: embreex's own path, said why, and the bake still runs."""
    code = ("import numpy as np; from core.tracing import embree_upload as u; from core.tracing.tracer import embree_scene; "
            "from core import Mesh; print(u.available(), u.reason()); "
            "s = embree_scene([Mesh(np.eye(3), np.array([[0, 1, 2]]), None, name='t')])[0]; "
            "print(s.run(np.array([[0.2, 0.2, 1.0]], np.float32), np.array([[0, 0, -1]], np.float32))[0])")
    env = {"MC_AO_EMBREE_UPLOAD": "0", "PATH": "/usr/bin:/bin"}
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, check=True)
    lines = out.stdout.split("\n")
    assert lines[0] == "False turned off by MC_AO_EMBREE_UPLOAD=0"
    assert lines[1] == "0"  # the ray hits triangle 0


def _marked_lines(stdout, marker):
    """The child's own lines: those after `marker`, whatever Blender printed around them (bpy 5.2
    prints "Using OCIO=..." before anything the script prints)."""
    return [line[len(marker):] for line in stdout.splitlines() if line.startswith(marker)]


def test_marked_lines_ignore_blenders_own_output():
    out = "Using OCIO=/opt/bpy/datafiles/colormanagement/config.ocio\nMC_AO: True /x/embreex.libs/e.so\nMC_AO: 2\n"
    assert _marked_lines(out, "MC_AO: ") == ["True /x/embreex.libs/e.so", "2"]


def test_blenders_own_embree_is_not_taken():
    """Blender (and the bpy module) load their own libembree4 before the add-on imports embreex: the
    upload must call the library embreex's scenes come from, not the first Embree in the process."""
    pytest.importorskip("bpy")
    marker = "MC_AO: "
    code = ("import bpy, sys; from core.tracing import embree_upload as u; "
            f"print({marker!r} + str(u.available()), u._library_path()); "
            f"print({marker!r} + str(len({{p for _, _, p in (u._mapped_files() or []) if 'embree4' in p}})))")
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, check=True)
    lines = _marked_lines(out.stdout, marker)
    assert len(lines) == 2, out.stdout
    ok, path = lines[0].split(" ", 1)
    assert ok == "True" and Path(path).parent.name in ("embreex.libs", ".dylibs"), out.stdout
    if sys.platform.startswith("linux"):
        assert int(lines[1]) >= 2  # both were there to choose from


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="reads /proc/self/maps")
def test_library_is_the_one_that_made_the_scene(monkeypatch):
    """Another Embree mapped first (as Blender's is) is passed over: the library is the file holding the
    virtual table of a scene embreex made."""
    real = embree_upload._mapped_files()
    other = (0x1000, 0x2000, "/elsewhere/bpy/lib/libembree4.so.4")
    monkeypatch.setattr(embree_upload, "_mapped_files", lambda: [other] + real)
    path = embree_upload._library_path()
    assert path is not None and path != other[2] and "embree" in Path(path).name
