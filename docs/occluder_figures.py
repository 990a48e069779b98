"""The README's pictures of occluder sets and of a thickness map, and the memory that instances take.

    .venv/bin/python docs/occluder_figures.py            # writes docs/occluder_sets.png, docs/thickness_map.png
    .venv/bin/python docs/occluder_figures.py --memory   # prints what 100 instances of a 5120-triangle sphere cost

Bakes with the add-on in the bpy module (no GUI) and writes the pictures with core.files.imageio (OpenImageIO).
"""

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "tests" / "blender"))

GAP = 6  # pixels of grey between the panels of a picture
GAP_GREY = 0.45


def setup():
    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    import mc_ao

    mc_ao.register()
    return bpy


def bake(bpy, obj, image_name, **settings):
    from blender_helpers import image_ao, select_only

    s = bpy.context.scene.mc_ao
    for key, value in settings.items():
        setattr(s, key, value)
    bpy.context.view_layer.update()
    select_only(bpy, obj)
    assert bpy.ops.object.mc_ao_bake() == {"FINISHED"}
    return image_ao(bpy.data.images[image_name])[0].copy()


def side_by_side(panels):
    h = max(p.shape[0] for p in panels)
    out = [np.full((h, GAP), GAP_GREY, np.float32)]
    for p in panels:
        out += [p, np.full((h, GAP), GAP_GREY, np.float32)]
    row = np.concatenate(out, axis=1)
    return np.pad(row, ((GAP, GAP), (0, 0)), constant_values=GAP_GREY)


def write(path, grey):
    from core.files import imageio

    # row 0 is the bottom (Blender's order), as core.files.imageio takes it
    rgb = np.repeat(grey[..., None], 3, axis=2).astype(np.float32)
    imageio.write_image(str(path), rgb, bits=8)
    print("wrote", path)


def occluder_sets(bpy, res=192, samples=64):
    """A floor under box A (collection Props) and box B (collection Floor Props, inside Props) and a
    hidden ball C (hidden in the viewport, rendered): All Rendered; Include Props with Exclude Floor Props;
    B not occluding others; Only Local."""
    from blender_helpers import add_cube, add_plane, clean_scene

    scene = clean_scene(bpy)
    s = scene.mc_ao
    s.resolution, s.samples, s.margin, s.max_distance, s.processes = res, samples, 0, 1.5, 1
    floor = add_plane(bpy, "Floor", size=4)
    a = add_cube(bpy, "A", size=0.8, location=(-1.0, -0.6, 0.5))
    b = add_cube(bpy, "B", size=0.8, location=(1.0, -0.6, 0.5))
    bpy.ops.mesh.primitive_uv_sphere_add(radius=0.45, location=(0, 1.1, 0.55))
    c = bpy.context.active_object
    c.name = "C"
    props = bpy.data.collections.new("Props")
    scene.collection.children.link(props)
    inner = bpy.data.collections.new("Floor Props")
    props.children.link(inner)
    for obj, coll in ((a, props), (b, inner)):
        for u in list(obj.users_collection):
            u.objects.unlink(obj)
        coll.objects.link(obj)
    c.hide_set(True)
    panels = [bake(bpy, floor, "Floor_AO")]
    s.occluder_collections.add().collection = props
    s.exclude_collections.add().collection = inner
    panels.append(bake(bpy, floor, "Floor_AO"))
    s.occluder_collections.clear()
    s.exclude_collections.clear()
    b.mc_ao.occlude_others = False
    c.hide_render = True
    panels.append(bake(bpy, floor, "Floor_AO"))
    panels.append(bake(bpy, floor, "Floor_AO", only_local=True))
    write(ROOT / "docs" / "occluder_sets.png", side_by_side(panels))


def thickness_map(bpy, res=256, samples=64):
    """Suzanne's AO and thickness (rays into the head up to 0.5), side by side."""
    bpy.ops.wm.open_mainfile(filepath=str(ROOT / "sample_scenes" / "suzanne.blend"))
    s = bpy.context.scene.mc_ao
    s.resolution, s.samples, s.margin, s.max_distance, s.processes = res, samples, 4, 0.5, 1
    s.quantity = {"AO", "THICKNESS"}
    suzanne = bpy.data.objects["Suzanne"]
    bake(bpy, suzanne, "Suzanne_AO")
    thick = bpy.data.images["Suzanne_Thickness"]
    from blender_helpers import image_ao

    views = [render_with(bpy, suzanne, image, res) for image in (bpy.data.images["Suzanne_AO"], thick)]
    write(ROOT / "docs" / "thickness_map.png", side_by_side(views + [image_ao(thick)[0]]))


def render_with(bpy, obj, image, res, samples=8):
    """A Cycles render of ``obj`` showing ``image`` as its colour (emission: no lighting), grey (R)."""
    scene = bpy.context.scene
    mat = bpy.data.materials.new("Show")
    if mat.node_tree is None:
        mat.use_nodes = True
    nodes, links = mat.node_tree.nodes, mat.node_tree.links
    nodes.clear()
    tex, emit, out = nodes.new("ShaderNodeTexImage"), nodes.new("ShaderNodeEmission"), nodes.new("ShaderNodeOutputMaterial")
    tex.image = image
    image.colorspace_settings.name = "Non-Color"
    links.new(tex.outputs["Color"], emit.inputs["Color"])
    links.new(emit.outputs[0], out.inputs["Surface"])
    obj.data.materials.clear()
    obj.data.materials.append(mat)
    for other in scene.objects:
        other.hide_render = other is not obj and other.type == "MESH"
    if scene.camera is None:
        cam = bpy.data.objects.new("Camera", bpy.data.cameras.new("Camera"))
        scene.collection.objects.link(cam)
        scene.camera = cam
    loc = obj.matrix_world.translation
    scene.camera.location = (loc.x + 1.5, loc.y - 3.3, loc.z + 0.5)
    scene.camera.data.lens = 95
    direction = loc - scene.camera.location
    scene.camera.rotation_euler = direction.to_track_quat("-Z", "Y").to_euler()
    scene.render.engine = "CYCLES"
    scene.cycles.device, scene.cycles.samples = "CPU", samples
    scene.render.resolution_x = scene.render.resolution_y = res
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    scene.world = scene.world or bpy.data.worlds.new("World")
    scene.world.color = (1, 1, 1)
    scene.render.film_transparent = False
    path = str(ROOT / "docs" / ".render.png")
    scene.render.filepath = path
    bpy.ops.render.render(write_still=True)
    from core.files import imageio

    pixels, _ = imageio.read_image(path)
    Path(path).unlink()
    return np.asarray(pixels, np.float32)[..., 0]


def instance_memory(bpy, count=100):
    """What ``count`` collection instances of a 5120-triangle sphere cost a bake of the floor under them."""
    from blender_helpers import add_plane, clean_scene
    from mc_ao import baking, corelink
    from mc_ao.settings import BakeSettings

    scene = clean_scene(bpy)
    floor = add_plane(bpy, "Floor", size=20)
    src = bpy.data.collections.new("Src")
    scene.collection.children.link(src)
    bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=5, radius=0.4)
    ball = bpy.context.active_object
    for u in list(ball.users_collection):
        u.objects.unlink(ball)
    src.objects.link(ball)
    bpy.context.view_layer.layer_collection.children["Src"].exclude = True
    side = int(round(count ** 0.5))
    for i in range(count):
        empty = bpy.data.objects.new(f"Ball{i}", None)
        empty.instance_type, empty.instance_collection = "COLLECTION", src
        empty.location = (-9 + 18 * (i % side) / (side - 1), -9 + 18 * (i // side) / (side - 1), 0.5)
        scene.collection.objects.link(empty)
    bpy.context.view_layer.update()
    settings = BakeSettings(resolution=64, samples=16, processes=1, threads=1, max_distance=2.0)
    depsgraph = bpy.context.evaluated_depsgraph_get()
    t = time.perf_counter()
    (job,) = baking.plan(depsgraph, [floor], settings, selected=[floor])
    gathered = time.perf_counter() - t
    triangles = sum(len(o.triangles) for o in job.occluders)
    held = sum(o.positions.nbytes + o.triangles.nbytes + (o.normals.nbytes if o.normals is not None else 0)
               for o in job.occluders)
    cost = corelink.load("execution.cost")
    per_triangle = getattr(cost, "BYTES_PER_OCCLUDER_TRIANGLE", None) or cost.BYTES_PER_TRIANGLE
    print(f"{count} instances of a {len(ball.data.polygons)}-triangle sphere: {len(job.occluders)} occluder "
          f"meshes, {triangles} triangles, gathered in {gathered:.2f} s")
    print(f"  arrays the plan holds: {held / 2 ** 20:.1f} MiB ({held / triangles:.0f} B a triangle)")
    print(f"  core.execution.cost per process holding the scene: {per_triangle * triangles / 2 ** 20:.0f} MiB "
          f"({per_triangle} B a triangle): x N for N worker processes")
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    job.run(settings, threads=1)
    after = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    print(f"  measured: peak resident memory grew {(after - before) / 1024:.0f} MiB during the bake "
          "(this process, 1 process, 64^2 x 16)")


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--memory", action="store_true", help="print the memory of instances instead")
    args = parser.parse_args()
    bpy = setup()
    if args.memory:
        instance_memory(bpy)
        return
    occluder_sets(bpy)
    thickness_map(bpy)


if __name__ == "__main__":
    main()
