"""What the Bake AO button's poll can tell before the click, cheaply: the bake's image names against
each other and against Blender's images, and the Into image of Channel. Poll runs at every redraw,
so only names and datablock fields are read here, no file and no pixels (an image not yet loaded is
left to the checks after the click, mc_ao.service.plan, which stay the ones that hold for the script).
"""

from . import baking

__all__ = ["own_image_is_into", "problem"]

#: Image.source values an image of a plain bake can be (a tiled one takes UDIM bakes only).
PLAIN_SOURCES = {"GENERATED", "FILE"}


def image_names(settings, target_name):
    """Every image a bake of ``target_name`` makes or fills: each quantity's, the bent normals', the
    error map's."""
    max_bytes = baking.id_name_max_bytes()
    names = [settings.quantity_image_name_for(target_name, q, max_bytes) for q in settings.quantities]
    if settings.bent_normals and not settings.vertex_colors:
        names.append(settings.bent_image_name_for(target_name, max_bytes))
    if settings.error_map and not settings.vertex_colors:
        names += [settings.stderr_image_name_for(target_name, max_bytes)] if "ao" in settings.quantities else []
    return names


def own_image_is_into(into, owner):
    """The refusal of an Into image that is ``owner``'s (an object's name) own image: the poll's and the
    bake's checks say it in these words."""
    return (f"image {into!r} is both {owner}'s own image and the Into image: one would replace the other; "
            "choose another Into or Image name")


def problem(settings, targets, images):
    """Why a bake of ``targets`` (objects) with ``settings`` (in effect) would be refused after the
    click, as far as names and ``images`` (bpy.data.images, or name -> image) tell; or None."""
    if settings.vertex_colors:
        return None  # a colour attribute: no image
    from . import atlas

    if atlas.shared(settings):
        return _shared_problem(settings, targets, images)
    owners = {}
    for obj in targets:
        for name in image_names(settings, obj.name):
            if name in owners:
                return baking.image_name_clash(owners[name], obj.name, name)
            owners[name] = obj.name
            image = images.get(name)
            if image is None:
                continue
            if settings.use_udim and image.source != "TILED":
                return (f"image {name!r} is a {image.source.lower()} image, not a tiled (UDIM) one: rename or "
                        "remove it, or choose another Image name")
            if not settings.use_udim and image.source not in PLAIN_SOURCES:
                return f"image {name!r} is a {image.source.lower()} image: bake into a plain image (another Image name)"
    if settings.channel != "NONE":
        return _into_problem(settings, targets, owners, images)
    return None


def _shared_problem(settings, targets, images):
    """:func:`problem` of a bake into shared images (One for All, Node Image): the objects share their
    image by design; each image a plain one; the Into image of Channel the size of the image the
    objects bake into (an existing image keeps its own)."""
    from .atlas import groups
    from .extract import ExtractError

    try:
        shared = groups(settings, targets, baking.id_name_max_bytes())
    except ExtractError as exc:
        return str(exc)
    for name, _ in shared:
        image = images.get(name)
        if image is not None and image.source not in PLAIN_SOURCES:
            return f"image {name!r} is a {image.source.lower()} image: bake into a plain image"
    if settings.channel == "NONE":
        return None
    into = settings.into
    if not into:
        return f"Into: choose the image whose {settings.channel} channel receives the AO"
    if len(shared) > 1:
        return (f"{shared[0][0]!r} and {shared[1][0]!r} would both write into the {settings.channel} channel of "
                f"{into!r}, each the whole channel: bake one image's objects at a time into it")
    if into == shared[0][0]:
        return (f"image {into!r} is both the image the objects bake into and the Into image: one would replace the "
                "other; choose another Into or Atlas name")
    image = images.get(into)
    if image is None:
        return f"Into: there is no image named {into!r} any more; choose the image to write the AO into"
    own = images.get(shared[0][0])
    want = _known_size(own) if own is not None else None
    want = want or tuple(settings.size)
    size = _known_size(image)
    if size is not None and size != want:
        return (f"Into image {into!r} is {size[0]}x{size[1]}, not the bake's {want[0]}x{want[1]}: bake at its size "
                f"to write into its {settings.channel} channel")
    return None


def _into_problem(settings, targets, owners, images):
    into = settings.into
    if not into:
        return f"Into: choose the image whose {settings.channel} channel receives the AO"
    if into in owners:
        return own_image_is_into(into, owners[into])
    if len(targets) > 1:
        return (f"{targets[0].name} and {targets[1].name} would both write into the {settings.channel} channel of "
                f"{into!r}, each the whole channel: bake one object at a time into it")
    image = images.get(into)
    if image is None:
        return f"Into: there is no image named {into!r} any more; choose the image to write the AO into"
    size = _known_size(image)
    w, h = settings.size
    if size is not None and size != (w, h):
        return (f"Into image {into!r} is {size[0]}x{size[1]}, not the bake's {w}x{h}: set Size to "
                f"{size[0]}{'' if size[0] == size[1] else ' and Height to %d' % size[1]} to write into its "
                f"{settings.channel} channel")
    return None


def _known_size(image):
    """The size of ``image`` where Blender knows it without loading anything: a generated image's, or
    one whose pixels are in memory; else None (the check after the click reads it)."""
    if getattr(image, "has_data", False):
        return tuple(int(s) for s in image.size)
    if image.source == "GENERATED":
        return int(image.generated_width), int(image.generated_height)
    return None
