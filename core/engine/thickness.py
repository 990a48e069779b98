"""The thickness map: ambient occlusion with the normal inverted, occluded by the object itself alone.

``bake_ao(..., quantity='thickness')`` bakes, per texel, the mean over its footprint of

    T(x) = (1/pi) * integral over the hemisphere around -n of V(x, w) * cos(theta) dw

where -n is the inverted shading normal (the hemisphere pointing into the mesh), theta the angle to
it, and V = 1 where the ray from x along w meets no surface of the object within ``max_distance``,
0 where it meets the far side. It is the AO estimator (:func:`core.engine.estimators.sample_terms`) on
rays cast into the mesh: the same sampler, patterns, error map, adaptive sampling, targets (images,
UDIM tiles, colour attributes, selected to active) and tile baker; only the kernel's direction
stage flips (:class:`core.engine.kernel.TileContext` with ``inward``: origins pushed off the surface to the
inside, directions negated, which for both warps (Malley's disk, the sphere point of the smooth
form) gives the same distribution about -n as about n), and the tracer holds the object alone.

Which definition, and how it reads. This follows Substance's "Thickness map from mesh" baker
(Substance 3D Bakers documentation, https://substance3d.adobe.com/documentation/bake/
thickness-map-from-mesh-172818642.html, and Substance Painter's "Thickness" page,
https://docs.substance3d.com/spdoc/thickness-142213479.html): "very similar to the ambient occlusion
baker, but it casts the rays in the opposite direction of the surface normal (so it's as if you were
baking an AO with the normal inverted)", with black values the thin parts of the model and white
values the thick parts, and a maximum occluder distance and a cosine or uniform ray distribution.
So here: **black = thin** (most inward rays meet the far side within ``max_distance``), **white =
thick** (rays travel ``max_distance`` inside without meeting it). Some tools and tutorials store
the inverse (white = thin, for subsurface scattering masks); invert the image for those. For a slab
of thickness d and cosine rays, T = (d / D)^2 for D = max_distance > d (a ray meets the far side
when cos(theta) >= d / D, with cosine-weighted probability 1 - (d / D)^2); on a sphere of radius R,
whose chord at angle theta is 2 R cos(theta), T = 1 - (D / 2R)^2 for D < 2R and 0 beyond.

Rules, stated where the established bakers leave them open:

- *Occluders*: the object itself only (with selected to active, the high-poly meshes). Other
  objects, the ``occluders`` passed, contact with them and the ground plane play no part: thickness
  is a property of the object. A ground with thickness is refused (it cannot apply), and so is
  ``ignore_backfaces`` (every far side is met from behind: nothing would ever count) and bent normals.
- *Open meshes*: a ray that leaves through an opening without meeting the far side within
  ``max_distance`` counts as not meeting it (V = 1): a single-sided plane is white everywhere, a
  cup's wall reads its own thickness only where its rays meet the far wall.
- *Smooth-shading terminators*: a direction of the inverted shading hemisphere that points out
  through the geometric surface (possible where interpolated normals bend away from the face)
  counts as meeting the surface at distance 0 (V = 0, thin), without being traced: the mirror of AO's
  rule for directions below the surface (:mod:`core.pipeline.run`), and like it continuous across the
  terminator.
"""

import dataclasses
import math


#: A thickness map's distance when none is given: this share of the target's size (the diagonal of its
#: bounding box), as the dedicated bakers take theirs from the mesh's bounds. Chosen on Suzanne: at a
#: twentieth the map's mean is 0.78 and 1.8% of its texels are below 0.02 (the eyes' rims and the ears'
#: edges, which are that thin); unlimited, every inward ray of a closed mesh meets its far side and the
#: map is black (mean 0.06). tests/test_thickness_default.py keeps it so.
SIZE_FRACTION = 1 / 20


def default_distance(meshes):
    """A thickness map's distance for ``meshes`` (core.Mesh or several, an atlas's targets): SIZE_FRACTION
    of the largest one's bounding-box diagonal, in world units."""
    import numpy as np

    meshes = meshes if isinstance(meshes, (list, tuple)) else [meshes]
    sizes = [float(np.linalg.norm(m.positions.max(axis=0) - m.positions.min(axis=0))) for m in meshes]
    size = max(sizes) if sizes else 0.0
    return SIZE_FRACTION * size if size > 0 else math.inf


def resolved(request, target):
    """``request`` with its thickness distance decided (:data:`SIZE_FRACTION` of ``target``'s size, or
    max_distance, when not given) where it bakes a thickness map; unchanged otherwise."""
    if "thickness" not in request.all_quantities or request.thickness_distance > 0:
        return request
    if math.isfinite(request.max_distance):
        return request.replace(thickness_distance=request.max_distance)
    targets = getattr(target, "targets", target)  # an atlas: its targets
    return request.replace(thickness_distance=default_distance(list(targets) if isinstance(targets, (list, tuple))
                                                               else targets))


def quantity_settings(s, quantity):
    """The settings of the bake of ``quantity`` alone, from ``s`` (another quantity's of the same bake,
    :class:`core.engine.settings.BakeSettings`): the AO-only settings (ground, back faces) left out of
    a thickness map."""
    if quantity == s.quantity:
        return s
    if quantity == "thickness":
        return dataclasses.replace(s, quantity="thickness", ground=None, ignore_backfaces=False,
                                   max_distance=s.thickness_distance if s.thickness_distance > 0 else s.max_distance)
    return dataclasses.replace(s, quantity=quantity)


__all__ = ["quantity_settings", "default_distance", "resolved", "SIZE_FRACTION"]
