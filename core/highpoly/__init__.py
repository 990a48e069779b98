"""Selected to active: the AO of high-poly meshes baked into the UVs of a low-poly one, by Cycles' rules.

A stage between surface sampling (:mod:`core.geometry.surface`) and direction sampling: each sample point of a
texel on the low-poly surface is moved to the high-poly surface the way Blender's bake does it
(``source/blender/render/intern/bake.cc``: ``RE_bake_pixels_populate_from_objects``,
``calc_point_from_barycentric_extrusion``, ``calc_point_from_barycentric_cage``,
``cast_ray_highpoly``), and AO is evaluated there (``intern/cycles/kernel/integrator/
init_from_bake.h``, ``shade_surface.h``: ``integrate_surface_ao``). The rules, exactly:

1. **The matching ray.** For a point p of the low-poly's triangle at barycentrics (u, v), with n the
   low-poly's normal there (the normalised interpolation of its corner normals on smooth faces, the
   face normal on flat ones):

   - *extrusion* (no cage): origin ``p + e n``, direction ``-n``, e the extrusion distance (given,
     or measured: see below): the ray starts outside the low surface and points back into it, along
     the normal only (a high surface farther out than ``e`` is never found);
   - *cage*: origin the cage's point of the same triangle at the same barycentrics, direction from
     it towards p (normalised; it does not stop at p). A cage point on p gives no direction: a miss.
     The extrusion is not used with a cage.

2. **The hit.** The nearest intersection with any high-poly mesh at distance ``t >= 0`` from the
   origin (front or back faces alike), if ``t <= max_ray_distance`` (measured from the extruded or
   cage point, not from p; 0 = no limit). Several high-poly meshes are one scene: the nearest hit
   among all of them wins.

3. **A miss.** A sample point whose ray finds nothing has no value: its samples are not traced and
   not counted. A texel's value is the mean over its points that found the high-poly surface (the
   part of the texel that matched); a texel none of whose points matched is left uncovered (``mask``
   False, ``miss`` True in the result), like the texels Cycles leaves unbaked, and the margin fills
   those within reach of covered texels (the rest stay 0). Misses are counted (``missed``).

4. **AO at the hit point** q: cosine-weighted (or uniform) directions about the high-poly's own
   shading normal there, the normalised interpolation of its corner normals (the face normal on flat
   faces), in the high-poly's own orientation, whatever side the matching ray came from (Cycles
   shades the hit as if seen from along that normal: a high-poly with flipped normals gets the AO of
   its other side). Rays leave from q pushed off along the high-poly's geometric normal on the
   shading normal's side; directions below the geometric surface count as occluded, as everywhere
   in the baker (:mod:`core.pipeline.run`).

5. **Occluders**: the high-poly meshes and the ``occluders`` given (Cycles: every other visible
   object of the view layer); never the low-poly target or the cage, even when passed among the
   occluders. Another object's face lying on the high-poly surface occludes the points it touches
   (contact, as :class:`core.tracing.tracer.Tracer` explains for the target).

The extrusion trap, and the automatic extrusion. With a too small extrusion (Cycles' default 0), a
point under a place where the high-poly bulges out of the low-poly starts its matching ray inside
the high-poly, and the ray meets the high-poly's far side from behind: the texel bakes the inside of
the high-poly (bright or dark blobs), and no ray "missed". With a too large one, in concave places a
ray starts beyond another part of the high-poly (the far wall of a slot) and matches that. The
default extrusion (None or 'auto') is measured from the meshes by :func:`auto_extrusion`: walking out
along the low-poly's normal from points spread over it, a surface met from behind is one the point
lies under (the extrusion must pass it), the first met from the front is another part across a gap
(the extrusion must stay short of it); the extrusion is the smallest that serves nearly every point.
``report['extrusion']`` says what was used. Whatever the extrusion, the bake counts the matching
rays that meet the high-poly from behind (its face normal along the ray) and, above
:data:`BEHIND_WARNING` of them, puts a warning naming the objects and what fits in
``report['warnings']``. A cage is used as given.

Differences from Cycles, by design: Cycles casts one matching ray per texel, at its centre, and then
jitters its AO samples over the high-poly triangle that ray hit; here every sample point has its own
position in the texel and its own matching ray, so a texel is the mean over the high-poly surface
its whole square maps to (the two agree in expectation where the AO field is smooth, not texel by
texel on detail finer than a texel). The matching rays are traced once per sample *point*, and
each point takes a block of :data:`DIRECTIONS_PER_POINT` directions (consecutive samples of the
texel's pattern: a stratified set), so they cost a fraction of the AO rays. The extrusion and the
max ray distance are world distances along the world-space normal; Cycles adds the extrusion in the
low-poly's object space (the same for a uniformly scaled object, whose scale the caller multiplies
in: :mod:`mc_ao.baking` does). Texels: mc_ao covers every texel a UV triangle touches, Cycles those
whose centre a triangle covers. Material normal maps and transparency of the high-poly are not seen.

The standard error (``stderr``). A texel's error has two parts: its directions, and the positions of
its P = samples / g sample points (the variance of the AO over the part of the high-poly surface the
texel maps to, over P). With replicates (``replicates`` >= 2, the default; the add-on's with an error
map or adaptive sampling) each replicate draws its own points, positions and directions, from its own
keys (:meth:`core.engine.patterns.TexelPattern.keys`), and ``stderr`` is the spread of the replicates
(:class:`core.engine.estimators.ErrorModel`, ``grouped``: for every source, since a point's block of
directions shares its position and the samples are not independent): both parts, pooled over the
texel's window like every error map. A replicate whose points all missed gives its texel no degrees
of freedom (it takes its neighbours' pooled error). Adaptive rounds stop on that interval; the
misses' texels take no round after the first. With one replicate ``stderr`` is the samples' spread,
the directions' part alone: where the AO changes within a texel (detail finer than a texel) the error
is larger than it says. tests/test_highpoly.py checks both against the exact values. The pooling
assumes the error varies smoothly over the image; it does not where the high-poly's AO jumps inside
single texels (a box resting on the high-poly, its footprint's edge cutting texels at 64 spp: there
the position part dominates and the pooled ``stderr`` is about 1.7 times too small, and 2-3 times
too large on the texels around them; measured, not tested).

Everything here runs in the bake's normalised frame (:func:`core.pipeline.prologue.normalized_scene`): the
extrusion and the distance scale with it. A sample point draws its position from its index in the
texel's pattern and its directions from the indices of its block, so bakes stay bit-identical for
any thread count, tile size and chunk size.
"""
