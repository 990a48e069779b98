"""The ground: an analytic infinite plane z = h (world up is +z, Blender's) that occludes without triangles.

``bake_ao(..., ground=None | 'auto' | h)`` adds it to every bake (texels, UDIM tiles, mesh corners,
selected to active, worker processes): :class:`core.tracing.tracer.Tracer` asks these functions after
Embree, for every ray it traces, so no target or path can miss it. It occludes exactly as a huge
plane mesh at z = h (normal +z) would, without the mesh's edges and without growing the scene's
size (which sets the rays' offsets off the surface):

- a ray whose segment crosses z = h from above (starting at or above it, ending below) is occluded;
  with a distance falloff, by the distance along the ray to the plane;
- a ray crossing it from below meets the plane's back: occluded too, unless the bake ignores back
  faces (``ignore_backfaces``), as a plane mesh's back face would be;
- contact: a sample point whose probe segment (the 2 * offset long segment through it along its
  geometric normal, :meth:`core.tracing.tracer.Tracer.contact`) meets z = h lies on the ground and is
  occluded in every direction, the rule for faces resting on a mesh. A box standing on the ground
  gets a black bottom and a contact shadow along its foot.

The height: ``'auto'`` is the lowest point of the baked surface (the target's; with selected to
active, the high-poly meshes', whose AO is baked), so each object of a batch gets its own contact;
a number is a world height. The bake moves the scene into its own frame (:func:`core.pipeline.prologue.frame_of`:
a translation and a uniform scale, so the plane stays horizontal); :func:`frame_height` takes the
height there.
"""


import numpy as np



def world_height(ground, lowest):
    """The ground's world height: ``lowest`` (the baked surface's lowest world z) for 'auto', the
    height itself otherwise, None without a ground."""
    if ground is None:
        return None
    return float(lowest) if ground == "auto" else float(ground)


def frame_height(height, centre_z, unit):
    """A world height in the bake's frame, where positions are (p - centre) / unit."""
    return None if height is None else (float(height) - float(centre_z)) / float(unit)


def crossing(oz, dz, tfar, h, two_sided, unlimited=False):
    """Per ray, whether its segment from ``oz`` (origin's z) over ``tfar`` times its direction's z
    ``dz`` crosses z = h: from above (starts at or above, ends below), or with ``two_sided`` also
    from below. Rays of length 0 (not traced) cross nothing. ``unlimited``: the bake has no
    maximum distance, so a traced ray is endless (Embree's rays stop at a float32 length; a ground
    farther than that still occludes every ray that heads for it, as an endless floor would)."""
    oz = np.asarray(oz, np.float64)
    tfar = np.asarray(tfar, np.float64)
    if unlimited:
        tfar = np.where(tfar > 0, np.inf, 0.0)
    with np.errstate(invalid="ignore"):  # inf * 0: a level ray stays level
        ez = oz + np.nan_to_num(tfar * np.asarray(dz, np.float64), nan=0.0)
    out = (oz >= h) & (ez < h)
    if two_sided:
        out |= (oz < h) & (ez > h)
    return out


def distance(oz, uz, reach, h, two_sided):
    """Per ray (unit direction's z ``uz``, length ``reach``: inf for an endless ray), the distance
    along it to z = h where it crosses it (see :func:`crossing`), else inf."""
    oz = np.asarray(oz, np.float64)
    uz = np.asarray(uz, np.float64)
    down = (oz >= h) & (uz < 0)
    if two_sided:
        down |= (oz < h) & (uz > 0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(down, (h - oz) / np.where(uz != 0, uz, 1.0), np.inf)
    return np.where(t <= np.asarray(reach, np.float64), t, np.inf)


def touching(pz, nz, lengths, h):
    """Per point (its z ``pz``, its unit geometric normal's z ``nz``), whether the segment of
    ``lengths`` either side of it along the normal meets z = h: the point lies on the ground."""
    pz = np.asarray(pz, np.float64)
    reach = np.abs(np.asarray(nz, np.float64)) * np.asarray(lengths, np.float64)
    return np.abs(pz - h) <= reach


__all__ = ["world_height", "frame_height", "crossing", "distance", "touching"]
