"""Baked images across undo and redo: after Ctrl-Z an image shows the pixels it had before the bake that
was undone, after Ctrl-Shift-Z the bake's again, whether its pixels are packed or it loads from a file.

Blender's memfile undo gives back an image datablock as it was at the undo step (its packed data, its
settings, its custom properties), but keeps the image's decoded pixels (the ImBuf cache it preserves
across undo steps): an image baked twice still shows the second bake after Ctrl-Z, and a reload then
shows the first. So each finished bake tags the image with a token (a custom property, which undo
restores with the datablock), and after every undo and redo an image whose token is not the one its
pixels came from is read again: a packed or generated image from its data (``buffers_free``); an image
that loads from a file, from the pixels kept here for that token while the file holds another bake's
(a later bake overwrote it; Blender cannot bring them back). Such an image is then modified with
respect to its file, as it is: the file holds the later bake until the user saves.

Kept pixels are bounded (:data:`KEEP_BYTES`, the oldest go first); without them the file is read.
"""

import collections
import uuid

import bpy

from . import images as _images

#: The custom property a baked image carries: which bake its pixels are.
PROPERTY = "mc_ao_bake"
#: Bytes of pixels kept for file images (each bake's, for undo), at most.
KEEP_BYTES = 1 << 30

# Keyed by the image's session_uid, which undo and redo keep for the same datablock and a new image (one
# made after a baked image was deleted, under its name) does not share.
_shown = {}  # image -> the token whose pixels its buffer holds
_in_file = {}  # image -> the token whose pixels its file holds
_kept = collections.OrderedDict()  # (image, token) -> pixels (H, W, C) float32


def _loads_from_file(image):
    return image.source == "FILE" and image.packed_file is None


def record(image):
    """Tag ``image`` as baked now (after its pixels are stored, packed or saved and linked)."""
    token = uuid.uuid4().hex[:16]
    image[PROPERTY] = token
    uid = image.session_uid
    _shown[uid] = token
    if _loads_from_file(image):
        _in_file[uid] = token
        pixels = _images.pixels_of(image)
        _kept[(uid, token)] = pixels
        while sum(p.nbytes for p in _kept.values()) > KEEP_BYTES and len(_kept) > 1:
            _kept.popitem(last=False)


def after_undo():
    """undo_post / redo_post: every image whose restored token is not its pixels' is read again."""
    for image in bpy.data.images:
        uid = image.session_uid
        token = image.get(PROPERTY)
        shown = _shown.get(uid)
        if token == shown or shown is None:  # as baked, or never baked in this session
            continue
        if token is None:  # back to before its first bake here
            _shown.pop(uid, None)
            if image.source == "GENERATED" and image.packed_file is None:
                continue  # its pixels then were never stored anywhere: the bake's stay
            image.buffers_free()  # its packed data or its file, as they were
        else:
            _shown[uid] = token
            kept = _kept.get((uid, token))
            if (_loads_from_file(image) and kept is not None and _in_file.get(uid) != token
                    and kept.shape[:2] == (image.size[1], image.size[0])):
                _images.set_pixels(image, kept)  # the file holds another bake: these pixels are only here
                continue
            image.buffers_free()  # read again from its packed data, its file, or regenerated
        _redraw(image)


def _redraw(image):
    image.update_tag()  # the 3D Viewport's texture follows a depsgraph tag (mc_ao.images.set_pixels)
    for window in bpy.context.window_manager.windows:
        for area in window.screen.areas:
            area.tag_redraw()


def forget():
    """A file was loaded (load_post) or the add-on goes: nothing of the last file's images is kept."""
    _shown.clear()
    _in_file.clear()
    _kept.clear()


__all__ = ["PROPERTY", "record", "after_undo", "forget"]
