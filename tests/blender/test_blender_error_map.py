"""The error map in Blender: the Error Map setting keeps each texel's standard error beside the AO."""

import numpy as np
import pytest

from blender_helpers import add_cube, add_plane, image_ao, select_only

pytestmark = pytest.mark.blender


def _scene(bpy):
    ground = add_plane(bpy, "Ground", size=4)
    add_cube(bpy, "Block", size=1.5, location=(0.3, 0.2, 1.2))
    select_only(bpy, ground)
    return ground


def test_the_error_map_is_the_cores_standard_error(bpy, scene):
    from mc_ao import baking
    from mc_ao.settings import BakeSettings

    ground = _scene(bpy)
    scene.mc_ao.error_map = True
    scene.mc_ao.samples = 64
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    ao, _ = image_ao(bpy.data.images["Ground_AO"])
    image = bpy.data.images["Ground_AO_stderr"]
    assert image.is_float and image.colorspace_settings.name == "Non-Color" and tuple(image.size) == (24, 24)
    se, _ = image_ao(image)
    # The same bake through the core (the job the operator ran, with its settings): the same numbers.
    settings = BakeSettings.from_properties(scene.mc_ao)
    assert settings.replicates == 2
    (job,) = baking.plan(bpy.context.evaluated_depsgraph_get(), [ground], settings, selected=[ground])
    r = job.run(settings, threads=2)
    np.testing.assert_array_equal(se, r.stderr)
    np.testing.assert_array_equal(ao, r.ao)
    shaded = r.mask & (r.ao < 0.95) & (r.ao > 0.05)
    assert shaded.any() and np.all(se[shaded] > 0)
    # Kept like the AO: packed, with a fake user, so that it survives saving the file.
    assert image.packed_file is not None and image.use_fake_user


def test_replicates_where_the_error_is_used_and_not_otherwise():
    from mc_ao.settings import BakeSettings

    assert BakeSettings().replicates == 1  # the least noise for the rays
    assert BakeSettings(error_map=True).replicates == 2
    assert BakeSettings(target_error=0.01).replicates == 2  # adaptive sampling stops on the error
    assert BakeSettings(error_map=True).bake_kwargs()["replicates"] == 2


def test_no_error_map_image_without_the_setting(bpy, scene):
    _scene(bpy)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    assert "Ground_AO_stderr" not in bpy.data.images


def test_save_to_file_writes_the_error_map_beside_the_ao(bpy, scene, tmp_path):
    from core.files import imageio

    _scene(bpy)
    scene.mc_ao.error_map = True
    scene.mc_ao.save_to_file = True
    scene.mc_ao.file_format = "OPEN_EXR"
    scene.mc_ao.output_dir = str(tmp_path)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    pixels, meta = imageio.read_image(tmp_path / "Ground_AO_stderr.exr")
    se, _ = image_ao(bpy.data.images["Ground_AO_stderr"])
    np.testing.assert_allclose(pixels, se, rtol=1e-6)
    assert meta["content"] == "stderr" and meta["replicates"] == 2


def test_adaptive_bakes_in_blender_stop_open_texels_early(bpy, scene):
    # Noise Threshold on: the open part of the plane stops at Min Samples, the shadow goes on.
    ground = add_plane(bpy, "Ground", size=8)
    add_cube(bpy, "Block", size=1.0, location=(0.0, 0.0, 0.8))
    select_only(bpy, ground)
    s = scene.mc_ao
    s.resolution, s.samples, s.min_samples, s.target_error, s.max_distance = 32, 1024, 16, 0.03, 1.0
    s.error_map = True
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    ao, _ = image_ao(bpy.data.images["Ground_AO"])
    se, _ = image_ao(bpy.data.images["Ground_AO_stderr"])
    assert np.any(ao < 0.8) and np.mean(ao == 1.0) > 0.3
    # The shadow's texels end within the target (95%: t quantile about 2); open texels away from
    # it have no error at all (beside it they take their neighbours' and go on sampling).
    shadow = (ao > 0.05) & (ao < 0.95)
    assert np.mean(2.1 * se[shadow] <= 0.03 * 1.05) > 0.95
    assert np.mean(se[ao == 1.0] == 0.0) > 0.8
