"""Blender side of the GUI test of Fix Seams: a UV seam in the viewport before and after, read off the
screen on both sides.

Run by tests/gui/seams.sh inside ../shared/tools/blender-gui.sh: ``blender --factory-startup
--python tests/gui/check_seams.py``. It installs the zip named by $MC_AO_ZIP, appends Suzanne and
its ground from sample_scenes/suzanne.blend, shows Suzanne's AO image in the viewport as it is (Solid
shading, Texture colour, Flat lighting, the Standard view transform: the screen shows each lookup's
value, sRGB-encoded; the Image Texture node's Linear interpolation, Repeat), and bakes it with the
Bake AO operator at 256^2 and 64 samples, Fix Seams off. It finds the UV seam whose two sides differ
most in that image (Blender's Linear lookup of both sides' UVs, along every seam edge of Suzanne's
smooth surface), points the view at it, square on, a texel about 24 pixels wide, and screenshots the
window: $MC_AO_GUI_OUT/before.png. Then it bakes again with Fix
Seams on and takes after.png (seams.sh takes the screenshots, xwd of the screen, when asked). On each screenshot it reads the pixels on both sides of the seam, a
third of a texel from it, at five places along it, and the same pairs moved a texel into one side
(the picture's own change over that distance, no seam between): result.json has them, and
``passed`` says whether the seam's jump on screen is at most the picture's own change plus 3/255
after the fix, and at least twice the after's before it.
"""

import math
import os
import sys

import bmesh
import bpy
import numpy as np
from bpy_extras import view3d_utils
from mathutils import Vector

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # the checks' shared module
from guikit import guarded, install, log, start, write  # noqa: E402

OUT = start("check_seams", os.environ.get("MC_AO_GUI_OUT", "/tmp/out/mc_ao_seams"))
SCENE = os.path.join(os.environ.get("MC_AO_REPO", os.getcwd()), "sample_scenes", "suzanne.blend")
RES, SAMPLES = 256, 64
TEXEL_PIXELS = 24  # on screen
STEPS = (0.3, 0.4, 0.5, 0.6, 0.7)  # where along the seam edge the pixels are read
OFFSET = 1 / 3  # texels from the seam
state = {}


def scene_setup():
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    with bpy.data.libraries.load(SCENE, link=False) as (src, dst):
        dst.objects = [n for n in src.objects if n in ("Suzanne", "Ground")]
    for obj in dst.objects:
        bpy.context.scene.collection.objects.link(obj)
    suzanne = bpy.data.objects["Suzanne"]
    image = bpy.data.images.new("Suzanne_AO", RES, RES, float_buffer=True, is_data=True)
    material = bpy.data.materials.new("Seams")
    material.use_nodes = True
    node = material.node_tree.nodes.new("ShaderNodeTexImage")
    node.image, node.interpolation, node.extension = image, "Linear", "REPEAT"
    material.node_tree.nodes.active = node
    suzanne.data.materials.clear()
    suzanne.data.materials.append(material)
    for obj in bpy.context.view_layer.objects:
        obj.select_set(obj is suzanne)
    bpy.context.view_layer.objects.active = suzanne
    bpy.context.scene.view_settings.view_transform = "Standard"
    settings = bpy.context.scene.mc_ao
    settings.resolution, settings.samples = RES, SAMPLES
    settings.image_name = "Suzanne_AO"
    state["has_option"] = hasattr(settings, "fix_seams")


def view_area(window):
    area = max((a for a in window.screen.areas if a.type == "VIEW_3D"), key=lambda a: a.width * a.height)
    return area, next(r for r in area.regions if r.type == "WINDOW")


def bake(window, fix):
    settings = bpy.context.scene.mc_ao
    if state["has_option"]:
        settings.fix_seams = fix
    area, region = view_area(window)
    with bpy.context.temp_override(window=window, area=area, region=region):
        result = bpy.ops.object.mc_ao_bake()
    log("bake, fix seams", fix, result)
    image = bpy.data.images["Suzanne_AO"]
    px = np.empty(len(image.pixels), np.float32)
    image.pixels.foreach_get(px)
    return px.reshape(image.size[1], image.size[0], -1)[..., 0].astype(np.float64)


def lookup(img, uv):
    """Blender's Linear lookup (Repeat) of ``img`` (H, W) at uv (n, 2)."""
    h, w = img.shape
    x, y = uv[:, 0] * w - 0.5, uv[:, 1] * h - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    x0, y0 = x0.astype(int), y0.astype(int)
    c0, c1, r0, r1 = x0 % w, (x0 + 1) % w, y0 % h, (y0 + 1) % h
    return ((1 - fy) * ((1 - fx) * img[r0, c0] + fx * img[r0, c1]) + fy * ((1 - fx) * img[r1, c0] + fx * img[r1, c1]))


def seams(obj):
    """Every smooth UV seam edge of ``obj``: (world ends, each side's face: (uv ends, the face's
    third corner in world and uv), world normal)."""
    bm = bmesh.new()
    bm.from_mesh(obj.data)
    uv = bm.loops.layers.uv.active
    m = obj.matrix_world
    out = []
    for e in bm.edges:
        if len(e.link_faces) != 2 or not e.smooth or not all(f.smooth for f in e.link_faces):
            continue
        sides = []
        for f in e.link_faces:
            loops = {lp.vert: lp for lp in f.loops}
            ends = [Vector(loops[v][uv].uv) for v in e.verts]
            others = [lp for lp in f.loops if lp.vert not in e.verts]
            sides.append((ends, m @ others[0].vert.co, Vector(others[0][uv].uv)))
        if all((a - b).length < 1e-7 for a, b in zip(sides[0][0], sides[1][0])):
            continue  # the same UVs on both sides: no seam
        ends = [m @ v.co for v in e.verts]
        normal = (m.to_3x3() @ (e.verts[0].normal + e.verts[1].normal)).normalized()
        out.append((ends, sides, normal))
    bm.free()
    return out


def side_point(ends, side, t, offset_texels):
    """The world point ``offset_texels`` into ``side``'s face from the edge's point at ``t``, and
    its uv."""
    (u0, u1), third, uv3 = side
    p = ends[0].lerp(ends[1], t)
    q = u0.lerp(u1, t)
    # In the face's plane: the direction from the edge towards the third corner, square to the edge.
    d = (ends[1] - ends[0]).normalized()
    inward = third - p
    inward = (inward - d * inward.dot(d)).normalized()
    du = (u1 - u0).normalized()
    inward_uv = uv3 - q
    inward_uv = (inward_uv - du * inward_uv.dot(du))
    # World length of one texel along the inward direction, from the face's own map.
    uv_per_world = inward_uv.length / max((third - p).dot(inward), 1e-12)
    step = offset_texels / (RES * uv_per_world)
    return p + inward * step, q + inward_uv.normalized() * (offset_texels / RES)


def choose(img):
    """The seam edge to show: the largest jump between its sides' lookups, against how much the
    picture changes by itself a texel into each side (a seam on a smooth, mid-grey stretch reads
    best), at least 4 texels long."""
    best = None
    for ends, sides, normal in seams(bpy.data.objects["Suzanne"]):
        length = max((s[0][1] - s[0][0]).length for s in sides) * RES
        if length < 4:
            continue
        at = {(i, o): np.array([list(side_point(ends, sides[i], t, o)[1]) for t in STEPS])
              for i in (0, 1) for o in (0.0, 1.0)}
        a0, b0 = lookup(img, at[0, 0.0]), lookup(img, at[1, 0.0])
        jump = float(np.mean(np.abs(a0 - b0)))
        change = float(np.mean(np.abs(lookup(img, at[0, 1.0]) - a0)) + np.mean(np.abs(lookup(img, at[1, 1.0]) - b0)))
        level = float(np.mean(a0 + b0) / 2)
        score = jump - 2 * change if 0.4 <= level <= 0.95 else -1.0
        if best is None or score > best[0]:
            best = (score, jump, ends, sides, normal)
    return best[1:]


def point_view(window, ends, normal):
    area, region = view_area(window)
    space = area.spaces.active
    space.shading.type = "SOLID"
    space.shading.color_type = "TEXTURE"
    space.shading.light = "FLAT"
    space.overlay.show_overlays = False
    r3d = space.region_3d
    r3d.view_perspective = "PERSP"
    r3d.view_location = (ends[0] + ends[1]) / 2
    r3d.view_rotation = normal.to_track_quat("Z", "Y")
    r3d.view_distance = 0.5
    area.tag_redraw()
    return area, region


def zoom(area, region, ends, sides):
    """A texel TEXEL_PIXELS wide on screen: the projected size scales as 1 / distance (the view's
    matrices are those of its last redraw)."""
    r3d = area.spaces.active.region_3d
    a, b = side_point(ends, sides[0], 0.5, 0.0)[0], side_point(ends, sides[0], 0.5, 1.0)[0]
    pa = view3d_utils.location_3d_to_region_2d(region, r3d, a)
    pb = view3d_utils.location_3d_to_region_2d(region, r3d, b)
    r3d.view_distance *= (pa - pb).length / TEXEL_PIXELS
    area.tag_redraw()
    return (pa - pb).length


def probes(region, r3d, ends, sides):
    """Window pixel positions of the pairs across the seam and of the control pairs (both in side A)."""
    def screen(p):
        s = view3d_utils.location_3d_to_region_2d(region, r3d, p)
        return [int(round(s.x)) + region.x, int(round(s.y)) + region.y]

    out = {"across": [], "control": []}
    for t in STEPS:
        a = side_point(ends, sides[0], t, OFFSET)[0]
        b = side_point(ends, sides[1], t, OFFSET)[0]
        a2 = side_point(ends, sides[0], t, OFFSET + 1.0)[0]
        a3 = side_point(ends, sides[0], t, OFFSET + 1.0 + 2 * OFFSET)[0]
        out["across"].append((screen(a), screen(b)))
        out["control"].append((screen(a2), screen(a3)))
    return out


def load(name):
    """The screenshot seams.sh took (xwd of the whole screen): grey levels (H, W), row 0 at the bottom."""
    img = bpy.data.images.load(os.path.join(OUT, name))
    px = np.empty(len(img.pixels), np.float32)
    img.pixels.foreach_get(px)
    w, h = img.size
    bpy.data.images.remove(img)
    return px.reshape(h, w, -1)[..., :3].mean(axis=2)


def screenshot(name, then):
    """Ask seams.sh for a screenshot ``name`` (ready_<name>.json), then run ``then`` once it is there."""
    write(f"ready_{name}.json", {"name": name})

    @guarded
    def wait():
        if os.path.exists(os.path.join(OUT, f"shot_{name}")):
            then(load(name))
            return None
        return 0.5

    bpy.app.timers.register(wait, first_interval=0.5)


def read(pixels, pairs):
    def at(p):
        x, y = p
        return float(pixels[y - 1:y + 2, x - 1:x + 2].mean())  # 3 x 3 around it

    return [abs(at(a) - at(b)) for a, b in pairs]


@guarded
def start():
    install()
    scene_setup()
    window = bpy.context.window_manager.windows[0]
    state["window"] = window
    img = bake(window, False)
    jump, ends, sides, normal = choose(img)
    state.update(ends=ends, sides=sides, jump_before_image=jump, zoom=[])
    state["area"], state["region"] = point_view(window, ends, normal)
    bpy.app.timers.register(settle, first_interval=2.0)
    return None


@guarded
def settle():
    """Zoom in three redraws, then take the pixel positions and ask for the first screenshot."""
    area, region, ends, sides = state["area"], state["region"], state["ends"], state["sides"]
    if len(state["zoom"]) < 3:
        state["zoom"].append(zoom(area, region, ends, sides))
        return 2.0
    state["probes"] = probes(region, area.spaces.active.region_3d, ends, sides)
    screenshot("before.png", before)
    return None


def before(pixels):
    window = state["window"]
    state["before"] = {k: read(pixels, v) for k, v in state["probes"].items()}
    img = bake(window, True)
    sides = state["sides"]
    uva = np.array([list(sides[0][0][0].lerp(sides[0][0][1], t)) for t in STEPS])
    uvb = np.array([list(sides[1][0][0].lerp(sides[1][0][1], t)) for t in STEPS])
    state["jump_after_image"] = float(np.mean(np.abs(lookup(img, uva) - lookup(img, uvb))))
    for a in window.screen.areas:
        a.tag_redraw()
    bpy.app.timers.register(lambda: screenshot("after.png", after), first_interval=3.0)


def after(pixels):
    state["after"] = {k: read(pixels, v) for k, v in state["probes"].items()}
    b, a = state["before"], state["after"]
    mean = lambda v: sum(v) / len(v)  # noqa: E731
    result = {
        "option": state["has_option"], "texel_pixels": state["zoom"],
        "image_jump_before": state["jump_before_image"], "image_jump_after": state["jump_after_image"],
        "screen_jump_before": mean(b["across"]), "screen_jump_after": mean(a["across"]),
        "screen_control_before": mean(b["control"]), "screen_control_after": mean(a["control"]),
        "probes": state["probes"], "before": b, "after": a,
    }
    result["passed"] = bool(state["has_option"]
                            and result["screen_jump_after"] <= result["screen_control_after"] + 3 / 255
                            and result["screen_jump_before"] >= 2 * result["screen_jump_after"])
    write("result.json", result)
    bpy.ops.wm.quit_blender()


os.makedirs(OUT, exist_ok=True)
bpy.app.timers.register(start, first_interval=2.0)
