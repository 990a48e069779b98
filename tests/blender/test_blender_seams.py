"""Fix Seams through the add-on: the script's --fix-seams / --no-fix-seams on the README's Suzanne, the
panel's property, and the batch manifest's key."""

import subprocess
import sys

import numpy as np
import pytest

from blender_helpers import ROOT

pytestmark = pytest.mark.blender

SCRIPT = str(ROOT / "scripts" / "bake_ao.py")
SUZANNE = ROOT / "sample_scenes" / "suzanne.blend"
RES = 64


@pytest.fixture(scope="module")
def suzanne_mesh(bpy):
    """Suzanne as the add-on hands her to the core (the evaluated mesh, its UVs and corner normals)."""
    from core import Mesh
    from mc_ao.extract import object_arrays

    bpy.ops.wm.open_mainfile(filepath=str(SUZANNE), load_ui=False)
    obj = bpy.data.objects["Suzanne"]
    a = object_arrays(obj.evaluated_get(bpy.context.evaluated_depsgraph_get()), with_uvs=True, with_normals=True)
    return Mesh(a.positions, a.triangles, a.uvs, a.normals, name="Suzanne")


def bake(tmp_path, *extra):
    out = tmp_path / ("off" if "--no-fix-seams" in extra else "on")
    proc = subprocess.run([sys.executable, SCRIPT, str(SUZANNE), "--objects", "Suzanne", "--samples", "8",
                           "--resolution", str(RES), "--threads", "2", "--format", "exr", "--bits", "float",
                           "--output", str(out), *extra], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    from core.files import imageio

    ao, metadata = imageio.read_image(out / "Suzanne_AO.exr")
    return np.squeeze(ao)[..., 0] if np.squeeze(ao).ndim == 3 else np.squeeze(ao), metadata


def test_the_script_fixes_seams_unless_told_not_to(suzanne_mesh, tmp_path):
    from core.geometry.seams import seam_lookups

    on, meta_on = bake(tmp_path)
    off, meta_off = bake(tmp_path, "--no-fix-seams")
    # each file says whether its seams were fixed (the core's metadata when on, the settings' when off)
    assert meta_on["fix_seams"] is True and meta_off["fix_seams"] is False
    L = seam_lookups(suzanne_mesh, RES)
    assert L.points > 1000 and not L.crease.any()
    # The same bake otherwise: both sides of Suzanne's seams agree, and the texels no seam lookup reads
    # are the raw bake's bits.
    assert L.mismatch(on) < 0.1 * L.mismatch(off)
    read = np.zeros(RES * RES, bool)
    read[L.index.reshape(-1)] = True
    untouched = ~read.reshape(RES, RES)
    assert untouched.sum() > 1000  # at 64^2 the seams reach most texels
    assert np.array_equal(on[untouched].view(np.uint32), off[untouched].view(np.uint32))


def test_fix_seams_is_a_scene_setting_on_by_default_and_greyed_for_colour_attributes(scene):
    from mc_ao.settings import BakeSettings

    assert scene.mc_ao.fix_seams is True
    s = BakeSettings.from_properties(scene.mc_ao)
    assert s.bake_kwargs()["fix_seams"] is True
    off = BakeSettings.from_properties(scene.mc_ao, fix_seams=False)
    assert off.bake_kwargs()["fix_seams"] is False
    vertex = BakeSettings.from_properties(scene.mc_ao, target="VERTEX_COLORS")
    assert vertex.greyed("fix_seams") and "fix_seams" not in vertex.bake_kwargs()


def _task(tmp_path, value, words):
    """The one task of a manifest whose defaults set fix_seams to ``value`` (None: not at all), after
    checking the words of its command line that name the option."""
    from mc_ao_batch.manifest import plan

    tmp_path.mkdir(exist_ok=True)
    line = "" if value is None else f"fix_seams = {str(value).lower()}\n"
    manifest = tmp_path / "library.toml"
    manifest.write_text(f'[defaults]\nsamples = 4\n{line}\n[[bake]]\nblend = "{SUZANNE.as_posix()}"\n')
    (task,) = plan(manifest, tmp_path / "out")
    assert [a for a in task.args if "fix-seams" in a] == words
    return task


@pytest.mark.parametrize("value, words", [(False, ["--no-fix-seams"]), (True, ["--fix-seams"]), (None, [])])
def test_the_manifest_key_reaches_the_script_as_its_option(tmp_path, value, words):
    _task(tmp_path, value, words)


def test_the_manifest_key_leaves_a_librarys_fingerprint_alone_unless_it_turns_the_fix_off(tmp_path):
    """fix_seams = true is the default (the fingerprint of a manifest without the key, so a library
    baked before the key existed is still found done under its output version); false is another bake."""
    default = _task(tmp_path / "a", None, [])
    on = _task(tmp_path / "b", True, ["--fix-seams"])
    off = _task(tmp_path / "c", False, ["--no-fix-seams"])
    assert default.fingerprint == on.fingerprint != off.fingerprint
    assert dict(default.older) == dict(on.older) != dict(off.older)


def test_the_image_panel_draws_the_checkbox_under_margin(bpy, scene):
    import types

    from mc_ao import panel

    drawn = []

    class Layout:  # records the properties the panel draws, in order
        def __getattr__(self, attr):
            def call(*args, **kwargs):
                if attr in ("prop", "prop_search") and len(args) >= 2:
                    drawn.append(args[1])
                return self
            return call

    layout = Layout()
    panel.VIEW3D_PT_mc_ao_image.draw(types.SimpleNamespace(layout=layout, split_layout=lambda: layout), bpy.context)
    assert drawn.index("fix_seams") == drawn.index("margin") + 1, drawn
    prop = type(scene.mc_ao).bl_rna.properties["fix_seams"]
    assert prop.name == "Fix Seams" and prop.default is True and "seam" in prop.description
