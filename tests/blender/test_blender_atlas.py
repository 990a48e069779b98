"""Several objects into one image from Blender: Images set to One for All (Atlas), Node Image (as
Cycles bakes), a named image; the script's --atlas; what an existing image keeps."""

import json
import subprocess
import sys

import numpy as np
import pytest

from blender_helpers import ROOT, add_plane, image_ao, select_only

pytestmark = pytest.mark.blender

SCRIPT = str(ROOT / "scripts" / "bake_ao.py")


def into_half(obj, right):
    """Squeeze ``obj``'s UVs into the left or right half of the UV square."""
    for loop in obj.data.uv_layers.active.data:
        u, v = loop.uv
        loop.uv = (0.5 * u + (0.5 if right else 0.0), v)


def two_objects(bpy):
    """A floor (UVs on the left half) under a lid facing down at 0.5 (UVs on the right half)."""
    floor = add_plane(bpy, "Floor", size=4)
    lid = add_plane(bpy, "Lid", size=2, location=(0, 0, 0.5), rotation=(np.pi, 0, 0))
    into_half(floor, right=False)
    into_half(lid, right=True)
    return floor, lid


def core_of(bpy, obj, others):
    """core.bake_ao of ``obj`` alone with ``others`` as occluders, as the add-on reads them."""
    import core
    from mc_ao.extract import object_arrays

    depsgraph = bpy.context.evaluated_depsgraph_get()

    def mesh(o, uvs=True):
        a = object_arrays(o.evaluated_get(depsgraph), with_uvs=uvs, with_normals=True)
        return core.Mesh(a.positions, a.triangles, a.uvs if uvs else None, a.normals, name=a.name)

    s = bpy.context.scene.mc_ao
    return core.bake_ao(mesh(obj), [mesh(o, False) for o in others], resolution=(s.resolution, s.resolution),
                        samples=s.samples, margin=s.margin, threads=2, replicates=1, seed=s.seed)


def test_one_for_all_bakes_the_selected_objects_into_one_image(bpy, scene, capfd):
    floor, lid = two_objects(bpy)
    scene.mc_ao.images = "ATLAS"
    scene.mc_ao.atlas = "Kit"
    select_only(bpy, floor, lid)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    image = bpy.data.images["Kit"]
    assert "Floor_AO" not in bpy.data.images and "Lid_AO" not in bpy.data.images
    assert tuple(image.size) == (24, 24) and image.is_float and image.colorspace_settings.name == "Non-Color"
    ao, _ = image_ao(image)
    alone = core_of(bpy, floor, [lid])
    left = alone.mask
    np.testing.assert_array_equal(ao[left], alone.ao[left])
    lid_alone = core_of(bpy, lid, [floor])
    np.testing.assert_array_equal(ao[lid_alone.mask], lid_alone.ao[lid_alone.mask])
    assert ao[left].min() < 0.7 and ao[lid_alone.mask].mean() < 0.5  # each shades the other (the lid faces down)
    assert "mc_ao_atlas" in image.keys()


def test_the_panel_says_how_many_objects_go_into_one_image(bpy, scene):
    from mc_ao import panel
    from mc_ao.settings import BakeSettings

    floor, lid = two_objects(bpy)
    third = add_plane(bpy, "Third", size=1, location=(3, 0, 0))
    scene.mc_ao.images = "ATLAS"
    settings = BakeSettings.from_properties(scene.mc_ao)
    assert panel.atlas_line(settings, [floor, lid, third]) == "3 objects into one image 'Atlas'"
    scene.mc_ao.images = "OWN"
    assert panel.atlas_line(BakeSettings.from_properties(scene.mc_ao), [floor, lid]) is None


def srgb(x):
    x = np.clip(np.asarray(x, np.float64), 0, 1)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def test_an_existing_image_keeps_its_size_depth_colour_space_and_the_other_objects_texels(bpy, scene, capfd):
    """An 8-bit sRGB image of 32 x 16 with a pattern in it: the bake goes in at its size, as the sRGB
    encoding of the AO (as Cycles stores it), over the objects' texels only; baking one object again
    keeps the other's texels."""
    from blender_helpers import pattern_image, run_bake

    floor, lid = two_objects(bpy)
    pattern_image(bpy, "Atlas", 32, 16)
    image = bpy.data.images["Atlas"]
    image.colorspace_settings.name = "sRGB"
    before = np.array(image.pixels[:]).reshape(16, 32, 4)
    scene.mc_ao.images = "ATLAS"
    select_only(bpy, floor, lid)
    result, error, out = run_bake(bpy, capfd)
    assert result == {"FINISHED"}, error
    assert "image 'Atlas' kept its 32x16, 8-bit, sRGB" in out
    image = bpy.data.images["Atlas"]
    assert tuple(image.size) == (32, 16) and not image.is_float and image.colorspace_settings.name == "sRGB"
    from mc_ao.images import record_bytes

    record = __import__("core").AtlasRecord.from_bytes(record_bytes(image))
    after = np.array(image.pixels[:]).reshape(16, 32, 4)
    import core

    owned = record.owner >= 0
    # the objects' texels hold the sRGB encoding of the record's values, to the byte
    cov = np.flatnonzero(owned.reshape(-1))
    want = np.round(srgb(record.ao) * 255) / 255
    np.testing.assert_allclose(after.reshape(-1, 4)[cov, 0], want, atol=0.5 / 255)
    # texels no object reaches (not covered, beyond the margins) keep the pattern
    changed = np.any(np.abs(after - before) > 1e-6, axis=2)
    assert changed.sum() < changed.size
    np.testing.assert_array_equal(after[~changed], before[~changed])
    lid_texels = after.reshape(-1, 4)[np.flatnonzero((record.owner == record.names.index("Lid")).reshape(-1))].copy()

    # The floor again, alone: the lid's texels, the size, depth and colour space stay.
    floor.location.x += 0.1
    select_only(bpy, floor)
    result, error, out = run_bake(bpy, capfd)
    assert result == {"FINISHED"}, error
    assert "image 'Atlas' kept its 32x16, 8-bit, sRGB and the texels of Lid" in out
    image = bpy.data.images["Atlas"]
    assert tuple(image.size) == (32, 16) and not image.is_float and image.colorspace_settings.name == "sRGB"
    again = np.array(image.pixels[:]).reshape(-1, 4)
    rec2 = core.AtlasRecord.from_bytes(record_bytes(image))
    assert rec2.names == ("Floor", "Lid")
    np.testing.assert_array_equal(again[np.flatnonzero((rec2.owner == 1).reshape(-1))], lid_texels)


def test_materials_image_bakes_objects_sharing_an_image_together(bpy, scene, capfd):
    from blender_helpers import run_bake

    floor, lid = two_objects(bpy)
    shared = bpy.data.images.new("Shared", 24, 24, float_buffer=True, is_data=True)
    mat = bpy.data.materials.new("Kit")
    if bpy.app.version < (5, 0, 0):
        mat.use_nodes = True
    node = mat.node_tree.nodes.new("ShaderNodeTexImage")
    node.image = shared
    mat.node_tree.nodes.active = node
    for obj in (floor, lid):
        obj.data.materials.append(mat)
    scene.mc_ao.images = "NODE"
    select_only(bpy, floor, lid)
    result, error, _ = run_bake(bpy, capfd)
    assert result == {"FINISHED"}, error
    ao, _ = image_ao(bpy.data.images["Shared"])
    assert ao[:, :12].max() > 0 and ao[:, 12:].max() > 0
    assert "Floor_AO" not in bpy.data.images
    plain = add_plane(bpy, "Plain", size=1, location=(5, 0, 0))
    select_only(bpy, floor, plain)
    result, error, _ = run_bake(bpy, capfd)
    assert result is None and "Plain has no material whose active node is an Image Texture with an image" in error


def test_a_named_image_refuses_two_objects_and_says_how_to_bake_them_together(bpy, scene, capfd):
    from blender_helpers import run_bake

    floor, lid = two_objects(bpy)
    scene.mc_ao.image_name = "Atlas"
    select_only(bpy, floor, lid)
    result, error, _ = run_bake(bpy, capfd)
    assert result is None
    assert "would both bake into image 'Atlas'" in error and "set Images to One for All" in error


def test_script_atlas_writes_one_file_and_a_second_run_keeps_every_object(bpy, scene, tmp_path):
    floor, lid = two_objects(bpy)
    blend = tmp_path / "kit.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    out = tmp_path / "out"
    args = [sys.executable, SCRIPT, str(blend), "--objects", "Floor", "Lid", "--atlas", "Atlas", "--format", "exr",
            "--resolution", "32", "--samples", "8", "--output", str(out), "--quiet",
            "--summary-json", str(tmp_path / "s.json")]
    first = subprocess.run(args, capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert first.returncode == 0, first.stderr
    assert sorted(p.name for p in out.iterdir()) == ["Atlas.atlas.npz", "Atlas.exr"]
    import OpenImageIO as oiio

    def pixels():
        return oiio.ImageBuf(str(out / "Atlas.exr")).get_pixels(oiio.FLOAT)

    before = pixels(), (out / "Atlas.atlas.npz").read_bytes()
    import core

    record = core.AtlasRecord.read(out / "Atlas.atlas.npz")
    assert record.names == ("Floor", "Lid") and (record.width, record.height) == (32, 32)
    second = subprocess.run(args, capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert second.returncode == 0, second.stderr
    assert "kept Floor, Lid (unchanged)" in second.stdout + second.stderr
    np.testing.assert_array_equal(pixels(), before[0])  # the texels, every one (the metadata says 0 rays now)
    assert (out / "Atlas.atlas.npz").read_bytes() == before[1]
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["exit_code"] == 0


def test_channel_packing_into_an_atlas(bpy, scene, capfd):
    """Channel R into an occlusion-roughness-metallic image: the atlas's AO in red, green and blue as
    they were."""
    from blender_helpers import run_bake

    floor, lid = two_objects(bpy)
    orm = bpy.data.images.new("ORM", 24, 24, float_buffer=True, is_data=True)
    orm.generated_color = (1.0, 0.6, 0.0, 1.0)
    scene.mc_ao.images = "ATLAS"
    scene.mc_ao.channel = "R"
    scene.mc_ao.into = orm
    select_only(bpy, floor, lid)
    result, error, _ = run_bake(bpy, capfd)
    assert result == {"FINISHED"}, error
    px = np.array(bpy.data.images["ORM"].pixels[:]).reshape(24, 24, 4)
    ao, _ = image_ao(bpy.data.images["Atlas"])
    np.testing.assert_allclose(px[..., 0], ao, atol=1e-7)
    np.testing.assert_allclose(px[..., 1], 0.6, atol=1e-6)
    np.testing.assert_allclose(px[..., 2], 0.0, atol=1e-6)
    assert ao[:, :12].max() > 0 and ao[:, 12:].max() > 0


def two_pairs(bpy):
    """Two low-poly planes (UVs in the two halves), each under a high-poly plane with a bump."""
    lows = []
    for k, x in enumerate((-3.0, 3.0)):
        low = add_plane(bpy, f"P{k}_low", size=2, location=(x, 0, 0))
        into_half(low, right=bool(k))
        high = add_plane(bpy, f"P{k}_high", size=2, location=(x, 0, 0.01))
        sub = high.modifiers.new("Subdivide", "SUBSURF")
        sub.subdivision_type, sub.levels = "SIMPLE", 3
        lows.append(low)
    bpy.ops.mesh.primitive_cube_add(size=0.5, location=(-3.0, 0, 0.3))
    bpy.context.active_object.name = "Bump"
    return lows


def test_selected_to_active_pairs_into_one_image_from_the_script(bpy, scene, tmp_path):
    two_pairs(bpy)
    blend = tmp_path / "pairs.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, SCRIPT, str(blend), "--match-suffix", "_high", "_low", "--atlas", "Pairs",
                           "--extrusion", "0.1", "--resolution", "32", "--samples", "8", "--output", str(out),
                           "--quiet"], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in out.iterdir()) == ["Pairs.atlas.npz", "Pairs.png"]
    import core

    record = core.AtlasRecord.read(out / "Pairs.atlas.npz")
    assert record.names == ("P0_low", "P1_low")
    owner = record.owner
    assert np.all(owner[:, :16][owner[:, :16] >= 0] == 0) and np.all(owner[:, 16:][owner[:, 16:] >= 0] == 1)
    ao = record.ao
    left = record.owner.reshape(-1)[record.covered] == 0
    assert ao[left].min() < 0.5 and ao[left].mean() < ao[~left].mean()  # the bump shades P0's high-poly


def test_an_id_map_gives_each_object_its_own_colour(bpy, scene, capfd, tmp_path):
    from blender_helpers import run_bake

    from core.geometry.atlas import id_colour

    floor, lid = two_objects(bpy)
    scene.mc_ao.images = "ATLAS"
    scene.mc_ao.id_map = True
    scene.mc_ao.save_to_file = True
    scene.mc_ao.output_dir = str(tmp_path)
    select_only(bpy, floor, lid)
    result, error, _ = run_bake(bpy, capfd)
    assert result == {"FINISHED"}, error
    image = bpy.data.images["Atlas_ID"]
    px = np.array(image.pixels[:]).reshape(24, 24, 4)[..., :3]
    for name, cols in (("Floor", slice(2, 10)), ("Lid", slice(14, 22))):
        np.testing.assert_allclose(px[8:16, cols], np.broadcast_to(id_colour(name), (8, 8, 3)), atol=0.5 / 255)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Atlas.atlas.npz", "Atlas.png", "Atlas_ID.png"]
    # One per Object greys ID Map out in the panel: it does nothing there (the script refuses it).
    scene.mc_ao.images = "OWN"
    scene.mc_ao.save_to_file = False
    select_only(bpy, floor)
    result, error, _ = run_bake(bpy, capfd)
    assert result == {"FINISHED"}, error
    assert "Floor_AO" in bpy.data.images and "Floor_AO_ID" not in bpy.data.images


def test_script_rebakes_only_the_objects_within_reach_of_a_moved_one(bpy, scene, tmp_path):
    """Three planes in a row, the AO distance reaching the next one only; the last one moved: the
    second run bakes it and its neighbour, keeps the first, and its file holds what a full bake of the
    moved scene holds, texel for texel."""
    import OpenImageIO as oiio

    planes = []
    for k in range(3):
        obj = add_plane(bpy, f"Tile{k}", size=1, location=(1.5 * k, 0, 0), rotation=(0, 0.3, 0))
        for loop in obj.data.uv_layers.active.data:
            u, v = loop.uv
            loop.uv = ((u + k) / 3, v)
        planes.append(obj)
    blend = tmp_path / "row.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    planes[2].location.x += 0.2
    moved = tmp_path / "moved.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(moved))

    def run(path, out):
        proc = subprocess.run([sys.executable, SCRIPT, str(path), "--objects", "Tile0", "Tile1", "Tile2", "--atlas", "Row",
                               "--format", "exr", "--bits", "float",
                               "--max-distance", "0.8", "--resolution", "48x16", "--samples", "8", "--output", str(out),
                               "--quiet"], capture_output=True, text=True, timeout=600, cwd=ROOT)
        assert proc.returncode == 0, proc.stderr
        return proc.stdout + proc.stderr, oiio.ImageBuf(str(out / "Row.exr")).get_pixels(oiio.FLOAT)

    run(blend, tmp_path / "out")
    said, partial = run(moved, tmp_path / "out")
    assert "baked Tile1, Tile2; kept Tile0 (unchanged)" in said
    _, full = run(moved, tmp_path / "full")
    np.testing.assert_array_equal(partial, full)



def test_overlapping_uvs_and_an_unlimited_reach_are_said(bpy, scene, capfd):
    from blender_helpers import run_bake

    floor, lid = two_objects(bpy)
    into_half(lid, right=False)  # the lid's UVs now over the floor's half too: stacked UVs
    scene.mc_ao.images = "ATLAS"
    select_only(bpy, floor, lid)
    result, error, out = run_bake(bpy, capfd)
    assert result == {"FINISHED"}, error
    assert "the UVs of Floor and Lid overlap on" in out
    lid.location.z += 0.1
    result, error, out = run_bake(bpy, capfd)
    assert result == {"FINISHED"}, error
    assert "the distance is unlimited, so every object reaches every other" in out


def test_selected_to_active_pairs_by_collection_into_one_image(bpy, scene, tmp_path):
    """--match-collections: each low-poly baked from the other objects of its own collection."""
    lows = two_pairs(bpy)
    for k, low in enumerate(lows):
        coll = bpy.data.collections.new(f"Asset{k}")
        bpy.context.scene.collection.children.link(coll)
        for obj in (low, bpy.data.objects[f"P{k}_high"]):
            for old in list(obj.users_collection):
                old.objects.unlink(obj)
            coll.objects.link(obj)
    bump = bpy.data.objects["Bump"]
    for old in list(bump.users_collection):
        old.objects.unlink(bump)
    bpy.data.collections["Asset0"].objects.link(bump)  # a high-poly part of asset 0
    blend = tmp_path / "assets.blend"
    bpy.ops.wm.save_as_mainfile(filepath=str(blend))
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, SCRIPT, str(blend), "--objects", "P0_low", "P1_low", "--match-collections",
                           "--atlas", "Assets", "--extrusion", "0.1", "--resolution", "32", "--samples", "8",
                           "--output", str(out)], capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    import core

    record = core.AtlasRecord.read(out / "Assets.atlas.npz")
    assert record.names == ("P0_low", "P1_low")
    left = record.owner.reshape(-1)[record.covered] == 0
    assert record.ao[left].min() < 0.5 and record.ao[left].mean() < record.ao[~left].mean()
    refused = subprocess.run([sys.executable, SCRIPT, str(blend), "--match-collections", "--output", str(out)],
                             capture_output=True, text=True, timeout=600, cwd=ROOT)
    assert refused.returncode == 2 and "--match-collections needs --objects" in refused.stderr
