"""mc_ao.outputs without Blender: the registry of output kinds, a new kind of map as one subclass,
the all-or-none save of an object's files, and the service (plan -> run -> outcome) writing files
for a job that needs no Blender."""

import os
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from core import Mesh, bake_ao
from core.files.imageio import read_image
from mc_ao import filewriter, outputs, service
from mc_ao.outputs import base, maps
from mc_ao.settings import BakeSettings

pytestmark = pytest.mark.skipif(not filewriter.oiio_available(), reason="needs OpenImageIO (no bpy here)")

PACKAGE = Path(outputs.__file__).parent


class PlaneJob:
    """A job as mc_ao.baking.Job runs it, without Blender: a unit square in the UV square."""

    object_name = "Plane"
    image_name = "Plane_AO"
    selected_to_active = False
    highpoly = ()
    quantity = "ao"

    def __init__(self, name="Plane"):
        self.object_name, self.image_name = name, f"{name}_AO"

    def run(self, settings, threads=None, progress=None, cancel=None, on_tile=None, quantity=None):
        P = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
        F = np.array([[0, 1, 2], [0, 2, 3]])
        kw = settings.bake_kwargs(threads)
        if quantity is not None:
            kw["quantity"] = quantity
        return bake_ao(Mesh(P, F, uvs=P[F][:, :, :2], name=self.object_name), **kw,
                       progress=progress, cancel=cancel, on_tile=on_tile)


SETTINGS = BakeSettings(resolution=8, samples=4, margin=1, threads=1, processes=1)


# -- the registry ------------------------------------------------------------------------------------

def test_every_kind_is_registered_and_has_a_file_of_its_own():
    names = [k.name for k in outputs.KINDS]
    assert names == ["image", "error_map", "bent_normals", "id_map", "channel", "color_attribute"]
    for kind in outputs.KINDS:
        assert issubclass(kind, base.OutputKind)
        assert (PACKAGE / f"{kind.__module__.rpartition('.')[2]}.py").is_file()
    assert len({k.__module__ for k in outputs.KINDS}) == len(outputs.KINDS)


@pytest.mark.parametrize("settings, kinds", [
    (BakeSettings(), ["image"]),
    (BakeSettings(error_map=True, bent_normals=True), ["image", "error_map", "bent_normals"]),
    (BakeSettings(use_udim=True, error_map=True), ["image", "error_map"]),
    (BakeSettings(target="VERTEX_COLORS"), ["color_attribute"]),
])
def test_the_kinds_of_a_bake_follow_its_settings(settings, kinds):
    assert [k.name for k in outputs.kinds_for(settings)] == kinds


def test_files_keep_their_names(tmp_path):
    """The planned files are named as before the kinds existed: a library's files stay "done"."""
    settings = BakeSettings(error_map=True, bent_normals=True)
    files = outputs.plan_files(outputs.kinds_for(settings), str(tmp_path), [PlaneJob()], [("PNG", 8), ("OPEN_EXR", "half")])
    got = {name: [(os.path.basename(f.path), f.stderr_path and os.path.basename(f.stderr_path)) for f in entry]
           for name, entry in files.items()}
    assert got == {"Plane_AO": [("Plane_AO.png", "Plane_AO_stderr.exr"), ("Plane_AO.exr", None)],
                   "Plane_BentNormal": [("Plane_BentNormal.png", None), ("Plane_BentNormal.exr", None)]}


class InvertedOutput(maps.MapOutput):
    """A new kind of map, as a thickness map or a packed image would be: one subclass."""

    name = "inverted"
    content = "inverted_ao"

    @classmethod
    def applies(cls, settings):
        return True

    def image_name(self, job):
        return f"{job.object_name}_Inverted"

    def source(self, result):
        return 1.0 - result.ao


def test_a_new_map_kind_is_one_subclass_and_a_line_in_kinds(tmp_path, monkeypatch):
    monkeypatch.setattr(outputs, "KINDS", outputs.KINDS + (InvertedOutput,))
    plan = service.plan(SETTINGS, [PlaneJob()], str(tmp_path), [("OPEN_EXR", "float")])
    assert [k.name for k in plan.kinds] == ["image", "inverted"]
    outcomes = run(plan)
    assert [o.status for o in outcomes] == ["ok"] and not outcomes[0].file_error
    ao, inverted = read_image(tmp_path / "Plane_AO.exr")[0], read_image(tmp_path / "Plane_Inverted.exr")[0]
    np.testing.assert_array_equal(inverted, 1.0 - ao)


class ThicknessBeside(maps.MapOutput):
    """A map of another core quantity than the job's own: baked once more for it."""

    name = "thickness_beside"
    quantity = "thickness"
    content = "thickness"

    @classmethod
    def applies(cls, settings):
        return True

    def image_name(self, job):
        return f"{job.object_name}_Beside"


def test_a_kind_of_another_quantity_gets_that_quantitys_bake(tmp_path, monkeypatch):
    monkeypatch.setattr(outputs, "KINDS", outputs.KINDS + (ThicknessBeside,))
    plan = service.plan(SETTINGS, [PlaneJob()], str(tmp_path), [("OPEN_EXR", "float")])
    assert plan.quantities == [None, "thickness"]
    (outcome,) = run(plan)
    assert set(outcome.results) == {None, "thickness"}
    assert outcome.results["thickness"].metadata["quantity"] == "thickness"
    assert outcome.result.metadata.get("quantity", "ao") == "ao"
    direct = PlaneJob().run(SETTINGS, threads=1, quantity="thickness")
    beside, meta = read_image(tmp_path / "Plane_Beside.exr")
    np.testing.assert_array_equal(beside, direct.ao)  # the same bits: counter-based randomness
    assert meta["content"] == "thickness"


# -- all or none -------------------------------------------------------------------------------------

def writer(pixels, bits):
    from core.files.imageio import write_image

    return lambda target: write_image(target, pixels, bits=bits)


def old_files(tmp_path):
    """A.png and B.png, images of an earlier bake; returns their paths and bytes."""
    from core.files.imageio import write_image

    a, b = tmp_path / "A.png", tmp_path / "B.png"
    write_image(a, np.full((4, 4), 0.25, np.float32), bits=8)
    write_image(b, np.full((4, 4), 0.75, np.float32), bits=8)
    return a, b, a.read_bytes(), b.read_bytes()


def assert_only(tmp_path, expected):
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted(expected)  # no temporary file left


def test_a_failing_format_leaves_every_old_file_byte_identical(tmp_path):
    a, b, old_a, old_b = old_files(tmp_path)
    good = np.full((4, 4), 0.5, np.float32)
    writes = [base.FileWrite(str(a), writer(good, 8)), base.FileWrite(str(b), writer(good, "half"))]  # no half PNG
    with pytest.raises(base.SaveError) as info:
        base.save_files(writes)
    assert info.value.path == str(b) and str(b) in str(info.value) and "bits='half'" in str(info.value)
    assert a.read_bytes() == old_a and b.read_bytes() == old_b
    assert_only(tmp_path, ["A.png", "B.png"])


def test_a_failed_move_puts_back_the_files_already_moved(tmp_path, monkeypatch):
    a, b, old_a, old_b = old_files(tmp_path)
    good = np.full((4, 4), 0.5, np.float32)
    real, calls = os.replace, []

    def replace_failing_second(src, dst):
        if str(dst) == str(b):
            raise OSError(28, "No space left on device")
        calls.append(dst)
        return real(src, dst)

    monkeypatch.setattr(os, "replace", replace_failing_second)
    with pytest.raises(base.SaveError) as info:
        base.save_files([base.FileWrite(str(a), writer(good, 8)), base.FileWrite(str(b), writer(good, 8))])
    assert str(b) in str(info.value)
    assert any(str(d) == str(a) for d in calls)  # A was replaced, then put back
    assert a.read_bytes() == old_a and b.read_bytes() == old_b
    assert_only(tmp_path, ["A.png", "B.png"])


def test_an_interrupt_while_writing_leaves_every_old_file_byte_identical(tmp_path):
    a, b, old_a, old_b = old_files(tmp_path)

    def interrupted(target):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        base.save_files([base.FileWrite(str(a), writer(np.zeros((4, 4), np.float32), 8)),
                         base.FileWrite(str(b), interrupted)])
    assert a.read_bytes() == old_a and b.read_bytes() == old_b
    assert_only(tmp_path, ["A.png", "B.png"])


def test_all_files_are_written_when_all_can_be(tmp_path):
    a, b, old_a, old_b = old_files(tmp_path)
    pixels = np.linspace(0, 1, 16, dtype=np.float32).reshape(4, 4)
    assert base.save_files([base.FileWrite(str(a), writer(pixels, 16)), base.FileWrite(str(b), writer(pixels, 8))]) \
        == [str(a), str(b)]
    np.testing.assert_allclose(read_image(a)[0], pixels, atol=0.5 / 65535)
    np.testing.assert_allclose(read_image(b)[0], pixels, atol=0.5 / 255)
    assert_only(tmp_path, ["A.png", "B.png"])


# -- the service without Blender ---------------------------------------------------------------------

def run(plan):
    got = []

    class Handler:
        def on_outcome(self, outcome):
            got.append(outcome)

    bake = service.Bake(plan, threads=1)
    bake.start()
    try:
        while not bake.handle(bake.next_message(), Handler()):
            pass
    finally:
        bake.stop()
    return got


def test_the_service_writes_an_objects_files_or_none_and_says_which(tmp_path):
    settings = replace(SETTINGS, error_map=True)
    (tmp_path / "B_AO.exr").write_bytes(b"the user's file")  # a file of another kind: refused at plan time
    with pytest.raises(Exception, match="B_AO.exr"):
        service.plan(settings, [PlaneJob("A"), PlaneJob("B")], str(tmp_path), [("PNG", 8), ("OPEN_EXR", "half")])
    (tmp_path / "B_AO.exr").unlink()
    plan = service.plan(settings, [PlaneJob("A"), PlaneJob("B")], str(tmp_path), [("PNG", 8), ("OPEN_EXR", "float")])
    os.mkdir(tmp_path / "B_AO_stderr.exr")  # B's standard-error file cannot be written (a folder)
    a, b = run(plan)
    assert a.baked and not a.file_error
    assert sorted(map(os.path.basename, a.files)) == ["A_AO.exr", "A_AO.png", "A_AO_stderr.exr"]
    assert b.baked and b.files == [] and "B_AO_stderr.exr" in b.file_error
    assert "none of its files was written" in service.file_error_message(b)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["A_AO.exr", "A_AO.png", "A_AO_stderr.exr", "B_AO_stderr.exr"]
    assert read_image(tmp_path / "A_AO.exr")[0].shape == (8, 8)
