"""Denoising a baked AO map over the surface, with an honest standard error after it.

What it builds on. The filter is a cross-bilateral (joint non-local) filter in the spirit of the
feature-guided, variance-aware Monte Carlo denoisers, with the per-texel filter selected by an
estimate of its mean squared error:

- Rousselle, Knaus and Zwicker, "Adaptive rendering with non-local means filtering" (SIGGRAPH Asia
  2012) and Rousselle, Manzi and Zwicker, "Robust denoising using feature and color information"
  (Pacific Graphics 2013): a set of candidate filters of increasing strength whose weights use
  features and the per-pixel variance, and a per-pixel choice among them by estimated error.
- Li, Wu and Chuang, "SURE-based optimization for adaptive sampling and reconstruction" (SIGGRAPH
  Asia 2012): choose per pixel the candidate whose estimated MSE is least.
- The bias of each candidate is estimated by double smoothing (the plug-in bias estimate of kernel
  regression, e.g. Hardle, "Applied nonparametric regression", 1990, ch. 5): for a linear smoother
  S, bias(S y) = S f - f, estimated by S (S y) - S y, whose noise is small because it smooths twice.

Where it departs from those image-space filters. A texel's neighbours are the texels near it on the
surface, not in the image: each texel has the surface point and normal at its centre, and the UV
island it lies on (:func:`surface_guide`). A neighbour in the image window counts only when it lies on
the same island; across a UV seam (a mesh edge shared in 3D, split in UV) the texels beyond the
island's border are replaced by the texels of the other side (a *halo*: the other island's chart
unfolded across the seam edge by the similarity that maps the edge onto itself). Weights are

    w_ij = exp(-|p_i - p_j|^2 / (2 h^2 s^2)) * exp(-beta (1 - n_i . n_j))
           * exp(-max(0, (g_i - g_j)^2 / (2 kappa^2 (v_i + v_j)) - flat))

with p the surface point, s^2 = (s_i^-2 + s_j^-2) / 2 from the world length s of each texel, n the
shading normal, g a pilot estimate of the AO (the same filter without the AO term, narrow) and v its
variance: the AO term keeps edges (a contact shadow) where the pilot shows a step larger than its
noise. All three factors are symmetric in i and j.

Error and selection. The raw estimates y_j have independent errors of variance sigma_j^2 (the
bake's standard error; each texel draws its own scrambled sample set). For candidate k,
F_k = sum_j w_ij y_j / W_i has variance V_k = sum_j w_ij^2 sigma_j^2 / W_i^2 (weights held fixed) and
estimated bias B_k = S_k F_k - F_k. Each texel takes the candidate with the least V_k + B_k^2, the
raw value (V = sigma_i^2, B = 0) among them, so a texel whose bias estimate exceeds what filtering
saves in noise is filtered less or not at all, and a texel with sigma_i = 0 (exactly open or fully
occluded: every sample and its neighbourhood agree) keeps its value and its zero error. The reported
standard error is sqrt(V_k + B_k^2) of the chosen candidate.

The same filter serves UDIM tiles together (:func:`udim_guide`, :func:`denoise_udim`: the tiles in
one canvas at their UDIM places) and AO baked at face corners (:func:`denoise_vertices`: the sample
points joined by the mesh's edges in place of an image window).

Cost: one pass of the pilot, one of the candidates, one of the bias, each over half of the window's
image offsets (the weights are symmetric), as numpy operations on bands of rows (the columns of
each band that hold covered texels); no loop over texels. In a bake the guide comes from the bake's
own tiles (:func:`tile_guide`). Measured (docs/denoise.md): 1.15 CPU seconds per megatexel for the
filter, 30-38% of a 64-sample bake at 4096^2 with the guide.
"""

from .guide import GUIDE_TILE, RADIUS, SurfaceGuide, surface_guide, tile_guide
from .filter import (BAND_ROWS, BANDWIDTHS, BIAS_SCALE, NORMAL_SHARPNESS, PILOT_BANDWIDTH, PILOT_RADIUS, RANGE_FLAT,
                     RANGE_SIGMAS, SEGMENT_GAP, DenoiseInfo, denoise)
from .vertices import VERTEX_BANDWIDTHS, denoise_vertices
from .wide import FLATNESS, PILOT_DEBIAS, SHAPES
from .udim import denoise_udim, udim_canvas, udim_guide

__all__ = [
    "GUIDE_TILE", "RADIUS", "SurfaceGuide", "surface_guide", "tile_guide", "BAND_ROWS", "BANDWIDTHS", "BIAS_SCALE",
    "NORMAL_SHARPNESS", "PILOT_BANDWIDTH", "PILOT_RADIUS", "RANGE_FLAT", "RANGE_SIGMAS", "SEGMENT_GAP",
    "DenoiseInfo", "denoise", "VERTEX_BANDWIDTHS", "denoise_vertices", "denoise_udim", "udim_canvas", "udim_guide"
]
