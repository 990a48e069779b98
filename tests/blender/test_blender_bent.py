"""Bent normals in Blender: "<object>_BentNormal" beside the AO image, from the same rays;
its tangent space is the one Cycles' Normal Map node decodes (checked through a Cycles normal bake),
its object space Blender's; meshes Blender computes no tangents for are refused by name."""

import numpy as np

from blender_helpers import add_cube, add_plane, new_session, select_only

SIZE = 64


def pixels(image):
    w, h = image.size
    out = np.empty(w * h * 4, np.float32)
    image.pixels.foreach_get(out)
    return out.reshape(h, w, 4)


def unit(v):
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def ball_beside_a_wall(bpy):
    """A smooth UV sphere, turned and scaled unevenly, its UVs squeezed to u in [0, 1/2] and those of
    its -x half mirrored into [1/2, 1] (bitangent sign -1 there), beside a cube."""
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, radius=1)
    ball = bpy.context.active_object
    ball.name = "Ball"
    bpy.ops.object.shade_smooth()
    layer = ball.data.uv_layers.active
    for poly in ball.data.polygons:
        for li in poly.loop_indices:
            u, v = layer.uv[li].vector
            layer.uv[li].vector = (1 - 0.5 * u, v) if poly.center.x < 0 else (0.5 * u, v)
    ball.rotation_euler = (0.3, 0.2, 0.5)
    ball.scale = (1.0, 1.3, 0.9)
    add_cube(bpy, "Wall", size=2, location=(1.6, 0, 0))
    select_only(bpy, ball)
    return ball


def cycles_decodes(bpy, scene, obj, tangent_image):
    """Cycles' NORMAL bake in object space of ``obj`` shaded through a Normal Map node (tangent space,
    the bake's UV map) that reads ``tangent_image`` texel by texel: Blender's own decoding of it.
    Returns (H, W, 3) unit vectors and which texels Cycles baked (their centre on a triangle)."""
    material = bpy.data.materials.new("Decode")
    if material.node_tree is None:
        material.use_nodes = True
    tree = material.node_tree
    principled = next(n for n in tree.nodes if n.bl_idname == "ShaderNodeBsdfPrincipled")
    tex = tree.nodes.new("ShaderNodeTexImage")
    tex.image = tangent_image
    tex.interpolation = "Closest"
    normal_map = tree.nodes.new("ShaderNodeNormalMap")
    normal_map.space = "TANGENT"
    normal_map.uv_map = obj.data.uv_layers.active.name
    tree.links.new(tex.outputs["Color"], normal_map.inputs["Color"])
    tree.links.new(normal_map.outputs["Normal"], principled.inputs["Normal"])
    out = bpy.data.images.new("Decoded", SIZE, SIZE, float_buffer=True, is_data=True)
    out.pixels.foreach_set(np.full(SIZE * SIZE * 4, -5.0, np.float32))  # texels Cycles leaves alone stay -5
    target = tree.nodes.new("ShaderNodeTexImage")
    target.image = out
    tree.nodes.active = target
    obj.data.materials.append(material)
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 1  # the first sample of a bake pixel is at its centre
    select_only(bpy, obj)
    assert bpy.ops.object.bake(type="NORMAL", normal_space="OBJECT", margin=0, use_clear=False) == {"FINISHED"}
    px = pixels(out)
    return unit(px[..., :3] * 2 - 1), px[..., 0] > -5


def test_tangent_space_is_what_cycles_normal_map_node_decodes(bpy, scene):
    """The bake in Object space and in Tangent space (same seed: the same rays, the same bent
    normals); Cycles decodes the tangent-space map with its Normal Map node (its MikkTSpace tangents,
    unnormalised interpolation, the normal normalised from Blender 5.1 on, bitangent sign, a mirrored
    UV half included) and bakes the result in object space: it is our object-space map, texel for
    texel, to a tenth of a degree (on 4.2.23, 5.0.1, 5.1.2 and 5.2.3; with the other versions'
    convention the worst texel is 0.8-1.1 degrees off).

    Compared on texels inside one triangle (where both bakers use the same surface point) whose bent
    normal leans less than 40 degrees from the shading normal: Cycles bends a normal-mapped normal
    that would reflect the view below the surface (ensure_valid_specular_reflection), which for a
    bake looking along the normal means leans past 45 degrees."""
    import core
    from core.post.bent import barycentric
    from core.geometry.raster import prepare, rasterize_tile
    from mc_ao import baking
    from mc_ao.settings import BakeSettings

    ball = ball_beside_a_wall(bpy)
    s = scene.mc_ao
    s.resolution, s.samples, s.margin, s.bent_normals = SIZE, 64, 0, True
    s.bent_space, s.image_name = "OBJECT", "{object}_AO_object"
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    bpy.data.images["Ball_BentNormal"].name = "Ball_BentNormal_object"
    s.bent_space, s.image_name = "TANGENT", "{object}_AO"
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    ours = unit(pixels(bpy.data.images["Ball_BentNormal_object"])[..., :3] * 2 - 1)
    tangent = pixels(bpy.data.images["Ball_BentNormal"])[..., :3] * 2 - 1
    decoded, baked = cycles_decodes(bpy, scene, ball, bpy.data.images["Ball_BentNormal"])

    # Texels inside one triangle, and each one's lean (in its own tangent frame, the angle from +Z).
    job, = baking.plan(bpy.context.evaluated_depsgraph_get(), [ball], BakeSettings.from_properties(s),
                       selected=[ball], view_layer=bpy.context.view_layer)
    uvtris = prepare(core.Mesh(job.target.positions, job.target.triangles, job.target.uvs), SIZE, SIZE)
    frag = rasterize_tile(uvtris, np.flatnonzero(uvtris.valid), SIZE, SIZE, 0, 0, SIZE, SIZE)
    whole = frag.texels[frag.full_tri >= 0]
    rows, cols = whole // SIZE, whole % SIZE
    keep = baked[rows, cols]
    rows, cols, tri = rows[keep], cols[keep], frag.full_tri[frag.full_tri >= 0][keep]
    frames = job.target.extra["bent_space"]
    w = barycentric(uvtris.corners, tri, cols + 0.5, rows + 0.5)
    T = np.einsum("nk,nkc->nc", w, frames.tangents[tri])
    N = np.einsum("nk,nkc->nc", w, frames.normals[tri])
    sign = np.where(np.einsum("nk,nk->n", w, frames.signs[tri]) < 0, -1.0, 1.0)
    B = sign[:, None] * np.cross(N, T)
    c = tangent[rows, cols]
    in_space = unit(c[:, :1] * T + c[:, 1:2] * B + c[:, 2:] * N)
    lean = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", in_space, unit(N)), -1, 1)))
    near = lean < 40
    assert np.any(sign[near] < 0) and np.any(sign[near] > 0)
    assert np.median(lean) > 0.5 and lean.max() > 30  # the wall bends them
    angle = np.degrees(np.arccos(np.clip(np.einsum("ij,ij->i", decoded[rows, cols], ours[rows, cols]), -1, 1)))
    # Texels whose every sample is occluded (inside the wall) have no bent normal: they hold the
    # shading normal as a placeholder, (0, 0, 1) in tangent space.
    seen = pixels(bpy.data.images["Ball_AO"])[rows, cols, 0] > 0
    assert (~seen).any() and (near & seen).sum() > 300
    assert angle[near & seen].max() < 0.1, np.sort(angle[near & seen])[-5:]


def test_the_normal_map_convention_follows_the_blender_version(bpy):
    """Blender 5.1 changed its Normal Map node to normalise the interpolated normal: the frames made
    for this Blender use its convention (the test above checks each against Cycles)."""
    from mc_ao.bent import normal_map_unit_normal

    assert not normal_map_unit_normal((4, 2, 23)) and not normal_map_unit_normal((5, 0, 1))
    assert normal_map_unit_normal((5, 1, 0)) and normal_map_unit_normal((5, 2, 3))
    assert normal_map_unit_normal() == (tuple(bpy.app.version[:2]) >= (5, 1))


def test_a_bent_normal_image_beside_the_ao_image(bpy, scene):
    """A plane at the foot of a wall: "<object>_BentNormal" is Non-Color, float, packed, flat blue
    (0.5, 0.5, 1) in tangent space where there is no surface; the normals lean away from the wall."""
    ground = add_plane(bpy, "Ground", size=2)
    for d in ground.data.uv_layers.active.uv:  # the island in the middle half of the image
        d.vector = (0.25 + 0.5 * d.vector[0], 0.25 + 0.5 * d.vector[1])
    add_cube(bpy, "Wall", size=2, location=(2.0, 0, 1.0))  # its face x = 1 stands on the plane's edge
    select_only(bpy, ground)
    scene.mc_ao.bent_normals = True
    scene.mc_ao.margin = 0
    scene.mc_ao.samples = 256
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    image = bpy.data.images["Ground_BentNormal"]
    assert image.colorspace_settings.name == "Non-Color" and image.is_float and image.packed_file is not None
    assert image.use_fake_user
    px = pixels(image)
    np.testing.assert_array_equal(px[0, 0], [0.5, 0.5, 1.0, 1.0])
    island = px[6:18, 6:18, :3] * 2 - 1
    np.testing.assert_allclose(np.linalg.norm(island, axis=-1), 1.0, atol=1e-5)
    # Tangent +x (u along x): the wall at +x pushes the bent normals to -x: R below 1/2, more near it.
    assert island[..., 0].max() < 0 and island[:, -1, 0].mean() < island[:, 0, 0].mean() - 0.1
    assert abs(island[..., 1].mean()) < 0.05


def test_faces_of_more_than_four_corners_are_refused_in_tangent_space_by_name(bpy, scene):
    bpy.ops.mesh.primitive_circle_add(vertices=8, fill_type="NGON")
    disk = bpy.context.active_object
    disk.name = "Disk"
    bpy.ops.object.mode_set(mode="EDIT")
    bpy.ops.uv.smart_project()
    bpy.ops.object.mode_set(mode="OBJECT")
    select_only(bpy, disk)
    scene.mc_ao.bent_normals = True
    session, reports = new_session()
    assert not session.start(bpy.context, live=False)
    assert reports[-1] == ("ERROR", "Disk: 1 face has more than 4 corners; Blender computes tangents for "
                                    "triangles and quads only: add a Triangulate modifier, or bake the bent "
                                    "normals in Object space")
    assert bpy.data.images.get("Disk_AO") is None
    scene.mc_ao.bent_space = "OBJECT"
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    assert bpy.data.images["Disk_BentNormal"].size[0] == 24
    disk.modifiers.new("Triangulate", "TRIANGULATE")
    scene.mc_ao.bent_space = "TANGENT"
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}


def test_udim_bent_normals_are_a_tiled_image_too(bpy, scene):
    from mc_ao import udim

    ground = add_plane(bpy, "Ground", size=2)
    for d in ground.data.uv_layers.active.uv:
        d.vector = (2 * d.vector[0], d.vector[1])
    select_only(bpy, ground)
    scene.mc_ao.use_udim = True
    scene.mc_ao.bent_normals = True
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    image = bpy.data.images["Ground_BentNormal"]
    assert image.source == "TILED" and [t.number for t in image.tiles] == [1001, 1002]
    tiles = udim.tile_pixels(image)
    for px in tiles.values():  # an open plane: the bent normal is the normal, (0.5, 0.5, 1)
        np.testing.assert_allclose(px[..., 2], 1.0, atol=0.02)  # 16 samples: noise, no bias


def test_an_image_name_clash_is_refused(bpy, scene):
    """An AO image named like the bent-normal image (Image "{object}_BentNormal") is refused before baking."""
    select_only(bpy, add_plane(bpy, "Ground", size=2))
    scene.mc_ao.bent_normals = True
    scene.mc_ao.image_name = "{object}_BentNormal"
    session, reports = new_session()
    assert not session.start(bpy.context, live=False)
    assert reports[-1] == ("ERROR", "Ground's images would both be named 'Ground_BentNormal' (its AO and its "
                                    "bent normals or error map): choose another Image name")
