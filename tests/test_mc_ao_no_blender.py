"""What the script, the operator and the batch share in mc_ao, without Blender (schema, bakerun, filewriter): settings checks, file names, the
settings record, the worker's messages."""

import math
import os
import subprocess
import sys

import numpy as np
import pytest

from core import Mesh, SettingsError, bake_ao
from core.base.request import MAX_RESOLUTION, MAX_SAMPLES
from mc_ao import bakerun, filewriter, schema
from mc_ao.settings import BakeSettings

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def test_importing_needs_no_bpy():
    code = "import sys; sys.modules['bpy'] = None\nimport mc_ao.bakerun, mc_ao.filewriter, mc_ao.schema, mc_ao.settings, mc_ao.cli\nprint('ok')"
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True)
    assert out.returncode == 0 and out.stdout == "ok\n", out.stderr


def test_the_defaults_pass_the_checks():
    assert schema.problems(BakeSettings()) == []
    assert schema.problems(BakeSettings(samples=MAX_SAMPLES, resolution=MAX_RESOLUTION, max_distance=math.inf)) == []


@pytest.mark.parametrize("field, value, message", [
    ("samples", 0, f"must be from 1 to {MAX_SAMPLES}, not 0"),
    ("samples", MAX_SAMPLES + 1, f"must be from 1 to {MAX_SAMPLES}, not {MAX_SAMPLES + 1}"),
    ("samples", 2.5, "must be a whole number, not 2.5"),
    ("min_samples", -1, f"must be from 1 to {MAX_SAMPLES}, not -1"),
    ("resolution", MAX_RESOLUTION + 1, f"must be from 1 to {MAX_RESOLUTION}, not {MAX_RESOLUTION + 1}"),
    ("height", -1, f"must be from 0 to {MAX_RESOLUTION} (0 = as wide as high), not -1"),
    ("margin", -1, f"must be from 0 to {MAX_RESOLUTION}, not -1"),
    ("seed", -1, f"must be from 0 to {2**64 - 1}, not -1"),
    ("seed", 2**64, f"must be from 0 to {2**64 - 1}, not {2**64}"),
    ("threads", -2, "must be from 0 to 1024 (0 = every core), not -2"),
    ("threads", 10**30, f"must be from 0 to 1024 (0 = every core), not {10**30}"),
    ("target_error", math.nan, "must be a finite number >= 0 (0 = adaptive sampling off), not nan"),
    ("target_error", math.inf, "must be a finite number >= 0 (0 = adaptive sampling off), not inf"),
    ("max_distance", -1.0, "must be a distance >= 0 (0 or inf = unlimited), not -1.0"),
    ("max_distance", math.nan, "must be a distance >= 0 (0 or inf = unlimited), not nan"),
    ("max_distance", -math.inf, "must be a distance >= 0 (0 or inf = unlimited), not -inf"),
    ("source", "SOBOLISH", "must be one of SOBOL, HALTON, STRATIFIED, INDEPENDENT, not 'SOBOLISH'"),
    ("file_format", "JPEG", "must be one of PNG, OPEN_EXR, TIFF, not 'JPEG'"),
])
def test_each_bad_setting_is_named(field, value, message):
    assert schema.problems(BakeSettings(**{field: value})) == [(field, message)]


def test_the_checks_agree_with_the_core():
    """What the checks let through, the core bakes; the core refuses what they refuse (same limits)."""
    P = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    plane = Mesh(P, F, uvs=P[F][:, :, :2])
    for settings in (BakeSettings(samples=1, resolution=4, max_distance=math.inf, margin=0),
                     BakeSettings(samples=MAX_SAMPLES + 1, resolution=4),
                     BakeSettings(resolution=4, max_distance=-1.0),
                     BakeSettings(resolution=4, target_error=math.nan)):
        ok = not schema.problems(settings)
        try:
            bake_ao(plane, **settings.bake_kwargs(threads=1))
        except SettingsError:
            assert not ok, settings
        else:
            assert ok, settings


def test_the_settings_record_is_what_the_core_writes():
    settings = BakeSettings(samples=8, min_samples=32, target_error=0.02, resolution=8, height=4,
                            max_distance=0.0, source="HALTON", distribution="UNIFORM", margin=1, seed=5,
                            ignore_backfaces=True, occluders="SELF", uv_map="Bake")
    P = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    result = bake_ao(Mesh(P, F, uvs=P[F][:, :, :2]), **settings.bake_kwargs(threads=1))
    record = filewriter.settings_record(settings)
    shared = {k: result.metadata[k] for k in record if k in result.metadata}
    assert shared == {k: record[k] for k in shared} and len(shared) >= 10
    assert record["max_distance"] == math.inf and record["min_samples"] == 8
    assert record["occluders"] == "self" and record["uv_map"] == "Bake"


def test_file_names_stay_in_the_folder_and_apart(tmp_path):
    names = ["../x_AO", "/abs/x_AO", "a/b_AO", "a_b_AO", "Cube_AO", "cube_AO", "CON", "..", "x" * 300]
    plan = filewriter.output_files(str(tmp_path / "out"), names, [("PNG", 8), ("OPEN_EXR", "half")], stderr=True)
    paths = [p for files in plan.values() for f in files for p in (f.path, f.stderr_path) if p]
    assert len(paths) == 3 * len(names) == len({p.casefold() for p in paths})
    assert all(os.path.dirname(p) == str(tmp_path / "out") for p in paths)
    assert plan["a_b_AO"][0].path.endswith("/a_b_AO.png") and plan["a_b_AO"][0].stderr_path.endswith("/a_b_AO_stderr.exr")
    assert plan["a_b_AO"][1].stderr_path is None and plan["a_b_AO"][1].bits == "half"


def test_a_standard_error_file_that_would_be_another_images_file_is_refused(tmp_path):
    with pytest.raises(SettingsError, match="would both be saved as 'Ground_stderr.exr'"):
        filewriter.output_files(str(tmp_path), ["Ground", "Ground_stderr"], [("OPEN_EXR", "half")], stderr=True)


def test_a_planted_link_cannot_lead_a_file_out_of_the_folder(tmp_path):
    (tmp_path / "out").mkdir()
    (tmp_path / "out" / "Ground_AO.png").symlink_to(tmp_path / "elsewhere.png")
    with pytest.raises(SettingsError, match="outside the output folder"):
        filewriter.output_files(str(tmp_path / "out"), ["Ground_AO"], [("PNG", 8)])


class CoreJob:
    """A job as mc_ao.baking.Job runs it, without Blender."""

    object_name = image_name = "plane"

    def __init__(self, uvs_scale=1.0):
        P = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
        F = np.array([[0, 1, 2], [0, 2, 3]])
        self.mesh = (P, F, P[F][:, :, :2] * uvs_scale)

    def run(self, settings, threads=None, progress=None, cancel=None, on_tile=None):
        P, F, uv = self.mesh
        return bake_ao(Mesh(P, F, uvs=uv, name=self.object_name), **settings.bake_kwargs(threads),
                       progress=progress, cancel=cancel, on_tile=on_tile)


def messages(run):
    out = []
    while not out or out[-1][0] != "end":
        out.append(run.next_message())
    return out


def test_a_run_reports_progress_results_and_errors_then_ends():
    settings = BakeSettings(resolution=8, samples=4, margin=0)
    run = bakerun.BakeRun([CoreJob(uvs_scale=1e17), CoreJob()], settings, threads=1, live=True)
    run.start()
    got = messages(run)
    run.stop()
    kinds = [m[0] for m in got]
    assert kinds[0] == "error" and "UV coordinates beyond" in str(got[0][2])
    assert kinds[-2:] == ["done", "end"] and "progress" in kinds and "tile" in kinds
    assert sorted(run.started) == [0, 1] and not bakerun.RUNS


@pytest.mark.parametrize("limit", [63, 255])  # Blender 4.2-4.4, 5.0 and later
def test_image_names_fit_blenders_limit_and_stay_apart(limit):
    settings = BakeSettings()
    assert settings.image_name_for("Cube", limit) == "Cube_AO"
    assert settings.image_name_for("x" * (limit - 3), limit) == "x" * (limit - 3) + "_AO"  # just fits
    names = ["n" * 300 + "1", "n" * 300 + "2", "é" * 200, "x" * (limit - 2)]
    got = [settings.image_name_for(n, limit) for n in names]
    assert len(set(got)) == len(got)
    for name, image in zip(names, got):
        assert len(image.encode()) <= limit and image.endswith("_AO")
        assert name.startswith(image[:-len("-12345678_AO")]) and image == settings.image_name_for(name, limit)
    long_template = BakeSettings(image_name="{object}_" + "t" * 300)
    assert len(long_template.image_name_for("Cube", limit).encode()) <= limit
    assert BakeSettings(image_name="{object}&{object}").image_name_for("é" * 100, limit).count("&") == 1


def test_a_file_of_another_kind_is_not_written_over_at_write_time(tmp_path):
    """Files found only after the bake (UDIM tiles) get the planning's check where they are written;
    the object's other files are then not written either (all or none)."""
    pytest.importorskip("OpenImageIO")
    from core.files.imageio import write_image
    from mc_ao import outputs

    pixels = np.full((2, 2), 0.5, np.float32)
    blend = tmp_path / "Ground_AO.1001.png"
    blend.write_bytes(b"BLENDER-v402 somebody's scene")
    fine = tmp_path / "Ground_AO.1002.png"
    writes = [outputs.FileWrite(str(p), lambda target: write_image(target, pixels, bits=8)) for p in (blend, fine)]
    with pytest.raises(outputs.SaveError) as info:
        outputs.save_files(writes)
    assert info.value.path == str(blend) and "is a .blend file, not a PNG image" in str(info.value)
    assert blend.read_bytes() == b"BLENDER-v402 somebody's scene" and not fine.exists()
