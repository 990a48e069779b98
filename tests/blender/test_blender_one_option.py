"""A bake option is defined in one place, core.base.request.OPTIONS, and reaches every path from there.

The test copies the code (core, mc_ao, mc_ao_batch, scripts) into a folder of its own and adds one
option, ``dummy_level`` (an int from 1 to 9, default 3, that changes nothing), to core.base.request's
OPTIONS, the one place; nothing else of the product is edited. The copy's request also notes every
request it makes, with the process's id, in a log (the test's instrument, appended to the copy):
so a value is seen where it arrives. Then, each in a process of its own that imports the copy:

- the panel's properties: ``scene.mc_ao.dummy_level`` with the core's default, limits and meaning, and
  the Sampling panel draws it, greyed out for a colour-attribute bake (the option is for images and UDIM
  tiles), whose core call leaves it out;
- the operator's core call: a value set on the scene reaches the core's request in Blender's process
  and in the bake's worker processes (another process id);
- the script's options: ``--dummy-level`` in its help, a value out of the core's limits refused (exit 2)
  in the script's words, a value baked reaches the core call and the workers;
- the manifest keys: ``dummy_level = 5`` goes onto the task's command line, a bad value stops the batch,
  and the new option at its default leaves the fingerprints of a library as they were.
"""

import json
import os
import shutil
import subprocess
import sys
import textwrap

import pytest

from blender_helpers import ROOT

pytestmark = pytest.mark.blender

OPTION = ('    Option("dummy_level", "int", 3, "sampling", "a test\'s option, which changes nothing in the bake", '
          'lo=1, hi=9, kinds=("image", "udim")),\n')
ANCHOR = "\n)\nBY_NAME = {o.name: o for o in OPTIONS}\n"
# The test's instrument: every request made (in any process) is noted with its process id.
LOG_HOOK = '''

def _logged_post_init(self, _made=_Request.__post_init__):
    _made(self)
    import json, os
    path = os.environ.get("MC_AO_TEST_REQUEST_LOG")
    if path:
        with open(path, "a") as f:
            f.write(json.dumps({"pid": os.getpid(), "kind": self.kind, "samples": self.samples,
                                "dummy_level": self.dummy_level}) + "\\n")


BakeRequest.__post_init__ = _logged_post_init
'''


@pytest.fixture(scope="module")
def copy(tmp_path_factory):
    """The code with ``dummy_level`` added to core.base.request.OPTIONS (and the request log)."""
    root = tmp_path_factory.mktemp("one_option")
    for name in ("core", "mc_ao", "mc_ao_batch", "scripts"):
        shutil.copytree(ROOT / name, root / name, ignore=shutil.ignore_patterns("__pycache__"))
    request = root / "core" / "base" / "request.py"
    text = request.read_text()
    assert text.count(ANCHOR) == 1, "core.base.request.OPTIONS no longer ends as this test expects"
    request.write_text(text.replace(ANCHOR, "\n" + OPTION + ANCHOR[1:]) + LOG_HOOK)
    return root


def run_python(copy, code, log, timeout=300):
    env = dict(os.environ, MC_AO_TEST_REQUEST_LOG=str(log), PYTHONPATH=str(copy))
    proc = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=copy, env=env, capture_output=True,
                          text=True, timeout=timeout)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    return proc


def requests(log, samples):
    """The requests of the test's bakes (of ``samples``), not the worker pool's own self-test."""
    seen = [json.loads(line) for line in log.read_text().splitlines()] if log.exists() else []
    return [r for r in seen if r["samples"] == samples]


def test_the_panel_and_the_operator(copy, tmp_path):
    log = tmp_path / "requests.log"
    proc = run_python(copy, f"""
        import json, os, sys, types
        sys.path.insert(0, {str(copy)!r})
        import bpy
        bpy.ops.wm.read_factory_settings(use_empty=True)
        import mc_ao
        assert mc_ao.__file__.startswith({str(copy)!r}), mc_ao.__file__
        mc_ao.register()
        prop = bpy.context.scene.mc_ao.bl_rna.properties["dummy_level"]
        drawn = []

        class Layout:  # records what the panel draws
            def prop(self, data, name, **kw):
                drawn.append(name)
            def __getattr__(self, name):
                return lambda *a, **kw: self

        from mc_ao import panel
        layout = Layout()
        panel.VIEW3D_PT_mc_ao_sampling.draw(types.SimpleNamespace(layout=layout, split_layout=lambda: layout),
                                           bpy.context)
        bpy.ops.mesh.primitive_plane_add(size=2)
        scene = bpy.context.scene
        scene.mc_ao.resolution, scene.mc_ao.samples, scene.mc_ao.processes = 64, 4, 2
        scene.mc_ao.dummy_level = 7
        result = bpy.ops.object.mc_ao_bake()
        # A colour-attribute bake, a kind the option is not for: greyed out, left out of the core call.
        from mc_ao.settings import BakeSettings
        greyed = [BakeSettings(target=t).greyed("dummy_level") for t in ("IMAGE_TEXTURES", "VERTEX_COLORS")]
        scene.mc_ao.target, scene.mc_ao.samples, scene.mc_ao.processes = "VERTEX_COLORS", 5, 1
        corners = bpy.ops.object.mc_ao_bake()
        bpy.ops.wm.save_as_mainfile(filepath={str(tmp_path / "plane.blend")!r})
        print("RESULT", json.dumps({{"default": prop.default, "min": prop.hard_min, "max": prop.hard_max,
                                    "description": prop.description, "drawn": drawn, "result": sorted(result), "corners": sorted(corners), "greyed": greyed,
                                    "pid": os.getpid()}}))
        mc_ao.unregister()  # ends its worker processes
        sys.stdout.flush()
        if tuple(bpy.app.version[:2]) == (4, 2):
            os._exit(0)  # bpy 4.2 can crash in its own exit handler (tests/blender/conftest.py)
    """, log)
    out = json.loads(proc.stdout.split("RESULT ", 1)[1].splitlines()[0])
    assert (out["default"], out["min"], out["max"]) == (3, 1, 9)
    assert out["description"] == "A test's option, which changes nothing in the bake"
    assert "dummy_level" in out["drawn"]
    assert out["result"] == ["FINISHED"]
    seen = requests(log, 4)
    assert seen and {r["dummy_level"] for r in seen} == {7}, seen
    assert out["pid"] in {r["pid"] for r in seen}  # the core call in Blender's process
    assert {r["pid"] for r in seen} - {out["pid"]}, seen  # and the request a worker process rebuilt
    assert out["corners"] == ["FINISHED"] and out["greyed"] == [False, True]
    assert [(r["kind"], r["dummy_level"]) for r in requests(log, 5)] == [("corners", 3)]


def test_the_script_and_the_manifest(copy, tmp_path):
    blend = tmp_path / "plane.blend"
    run_python(copy, f"""
        import bpy
        bpy.ops.wm.read_factory_settings(use_empty=True)
        bpy.ops.mesh.primitive_plane_add(size=2)
        bpy.ops.wm.save_as_mainfile(filepath={str(blend)!r})
        if tuple(bpy.app.version[:2]) == (4, 2):
            import os
            os._exit(0)  # bpy 4.2 can crash in its own exit handler (tests/blender/conftest.py)
    """, tmp_path / "unused.log")
    script = [sys.executable, str(copy / "scripts" / "bake_ao.py"), str(blend)]
    env = dict(os.environ, MC_AO_TEST_REQUEST_LOG=str(tmp_path / "script.log"))
    helped = subprocess.run(script + ["--help"], capture_output=True, text=True, env=env, timeout=120)
    assert "--dummy-level N" in helped.stdout and "changes nothing in the bake" in helped.stdout
    bad = subprocess.run(script + ["--dummy-level", "0", "--output", str(tmp_path / "bad")], capture_output=True,
                         text=True, env=env, timeout=120)
    assert bad.returncode == 2 and "bake_ao: error: --dummy-level must be from 1 to 9, not 0" in bad.stderr
    proc = subprocess.Popen(script + ["--dummy-level", "5", "--resolution", "64", "--samples", "4", "--processes", "2",
                                      "--output", str(tmp_path / "out"), "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    out, err = proc.communicate(timeout=300)
    assert proc.returncode == 0, out + err
    seen = requests(tmp_path / "script.log", 4)
    assert seen and {r["dummy_level"] for r in seen} == {5}, seen
    assert proc.pid in {r["pid"] for r in seen} and {r["pid"] for r in seen} - {proc.pid}, seen
    # The file records it in its metadata, as every setting that is not at its default.
    summary = run_python(copy, f"""
        from core.files.imageio import read_image
        print(read_image({str(tmp_path / "out" / "Plane_AO.png")!r})[1]["dummy_level"])
    """, tmp_path / "unused.log")
    assert summary.stdout.split() == ["5"]

    # The manifest: the key goes onto the task's command line; a bad value stops the batch; at its
    # default it leaves a library's fingerprints as the code without the option made them.
    check = f"""
        import json, pathlib, sys
        from mc_ao_batch.manifest import ManifestError, plan
        folder = pathlib.Path({str(tmp_path)!r})
        manifest = folder / "m.toml"
        out = {{}}
        for name, entry in (("set", "dummy_level = 5\\n"), ("default", "samples = 8\\n"), ("bad", "dummy_level = 10\\n")):
            manifest.write_text(f"[[bake]]\\nblend = 'plane.blend'\\n{{entry}}")
            try:
                task, = plan(manifest, folder / "batch")
                out[name] = [task.args, task.fingerprint]
            except ManifestError as exc:
                out[name] = str(exc)
        print(json.dumps(out))
    """
    with_option = json.loads(run_python(copy, check, tmp_path / "unused.log").stdout)
    without = json.loads(run_python(ROOT, check, tmp_path / "unused.log").stdout)
    assert with_option["set"][0] == ["--dummy-level", "5"]
    assert "--dummy-level must be from 1 to 9, not 10" in with_option["bad"]
    assert "dummy_level" in without["bad"]  # the code without the option does not know the key
    assert with_option["default"] == without["default"]
