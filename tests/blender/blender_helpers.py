"""Scene builders and image readers for the Blender tests (a module of its own: a name no other test folder uses)."""

from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]


def clean_scene(bpy):
    """Remove every object, mesh and image, and reset the scene's bake settings."""
    for obj in list(bpy.data.objects):
        bpy.data.objects.remove(obj)
    for collection in (bpy.data.meshes, bpy.data.images, bpy.data.materials):
        for block in list(collection):
            collection.remove(block)
    scene = bpy.context.scene
    bpy.context.view_layer.update()
    if hasattr(scene, "mc_ao"):
        for name in scene.mc_ao.bl_rna.properties.keys():
            if name not in {"rna_type", "name"}:
                scene.mc_ao.property_unset(name)
    return scene


def add_plane(bpy, name="Plane", size=4.0, location=(0, 0, 0), rotation=(0, 0, 0)):
    bpy.ops.mesh.primitive_plane_add(size=size, location=location, rotation=rotation)
    obj = bpy.context.active_object
    obj.name = obj.data.name = name
    return obj


def add_cube(bpy, name="Cube", size=2.0, location=(0, 0, 0)):
    bpy.ops.mesh.primitive_cube_add(size=size, location=location)
    obj = bpy.context.active_object
    obj.name = obj.data.name = name
    return obj


def select_only(bpy, *objects):
    for obj in bpy.context.view_layer.objects:
        if obj is not None:
            obj.select_set(obj in objects)
    bpy.context.view_layer.objects.active = objects[0] if objects else None


def image_ao(image):
    """The R channel of an image as (H, W) float32 (what the bake wrote as AO), and the alpha."""
    w, h = image.size
    px = np.empty(w * h * 4, dtype=np.float32)
    image.pixels.foreach_get(px)
    px = px.reshape(h, w, 4)
    return px[..., 0], px[..., 3]
