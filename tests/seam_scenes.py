"""Exact scenes with UV seams, for Fix Seams: the unit plane cut into charts laid out apart (or side
by side) in the image, turned and mirrored, with the exact AO of every texel (core.montecarlo.analytic); and a
slow, obvious bilinear lookup (Blender's Linear interpolation written out texel by texel) to check
the seam lookups against."""

import math

import numpy as np

from core import Mesh
from core.montecarlo.analytic import plane_beside_box_ao, polygon_form_factor, regular_polygon, texel_mean
from scenes import box

#: Chart placements: the map from the chart's own square (u, v) in [0, 1]^2 to its square in the
#: image, and the same map on an (n, n) array indexed [row = v, column = u].
TURNS = {
    "id": (lambda u, v: (u, v), lambda a: a),
    "rot180": (lambda u, v: (1 - u, 1 - v), lambda a: a[::-1, ::-1]),
    "mirror": (lambda u, v: (1 - u, v), lambda a: a[:, ::-1]),
    "rot90": (lambda u, v: (1 - v, u), lambda a: np.rot90(a, -1)),
}
LID = regular_polygon(0.3, 0.25, 64, centre=(0.45, 0.55))
BOX = ((0.3, 0.3, 0.0), (0.7, 0.6, 0.25))


def lid(verts=LID):
    return Mesh(verts, np.array([[0, i, i + 1] for i in range(1, len(verts) - 1)]), name="lid")


def charts(width=64, grid=2, cell=28, gap=4, turns=("id", "rot180", "mirror", "rot90"), occluder="lid"):
    """The unit plane (z = 0, facing +z) cut into grid x grid square charts, chart (i, j) covering
    x in [j, j + 1] / grid, y in [i, i + 1] / grid, placed in a ``width``^2 image as a ``cell``^2
    texel square at (gap / 2 + j (cell + gap), gap / 2 + i (cell + gap)) texels, turned as ``turns``
    says (in turn): every chart edge inside the plane is a UV seam. gap = 0 and cell = width / grid:
    the charts touch in the image, as in a tight atlas.

    Returns (target Mesh, [occluder], exact texel AO (width, width), covered (width, width) bool).
    ``occluder``: 'lid' (a 64-gon hovering over the plane) or 'box' (a box resting on it).
    """
    P, F, UV = [], [], []
    truth = np.zeros((width, width))
    covered = np.zeros((width, width), bool)
    for i in range(grid):
        for j in range(grid):
            to_uv, to_array = TURNS[turns[(i * grid + j) % len(turns)]]
            x0, y0, x1, y1 = j / grid, i / grid, (j + 1) / grid, (i + 1) / grid
            ox, oy = gap // 2 + j * (cell + gap), gap // 2 + i * (cell + gap)
            quad = [(x0, y0), (x1, y0), (x1, y1), (x0, y1)]
            base = len(P)
            P.extend((x, y, 0.0) for x, y in quad)
            for tri in ((0, 1, 2), (0, 2, 3)):
                F.append([base + t for t in tri])
                corners = []
                for t in tri:
                    u, v = to_uv((quad[t][0] - x0) * grid, (quad[t][1] - y0) * grid)
                    corners.append(((ox + u * cell) / width, (oy + v * cell) / width))
                UV.append(corners)
            bounds = (x0, y0, x1, y1)
            if occluder == "lid":
                exact = texel_mean(lambda p: 1.0 - polygon_form_factor(p, LID), cell, cell, bounds=bounds)
            else:
                exact = plane_beside_box_ao(*BOX, cell, cell, bounds=bounds)
            truth[oy:oy + cell, ox:ox + cell] = to_array(exact)
            covered[oy:oy + cell, ox:ox + cell] = True
    target = Mesh(np.array(P, float), np.array(F), np.array(UV, float), name="charts")
    return target, [lid() if occluder == "lid" else box(*BOX)], truth, covered


def bilinear_lookup(image, u, v, wrap="repeat"):
    """Blender's Linear lookup of ``image`` (H, W; row 0 at v = 0) at (u, v), texel by texel as
    Cycles' interp_linear writes it: x = u W - 0.5, the texels floor(x) and floor(x) + 1 (wrapped or
    clamped at the border), weights from the fraction."""
    h, w = image.shape
    x, y = u * w - 0.5, v * h - 0.5
    ix, iy = math.floor(x), math.floor(y)
    tx, ty = x - ix, y - iy

    def at(r, c):
        if wrap == "repeat":
            r, c = r % h, c % w
        else:
            r, c = min(max(r, 0), h - 1), min(max(c, 0), w - 1)
        return float(image[r, c])

    return ((1 - ty) * (1 - tx) * at(iy, ix) + (1 - ty) * tx * at(iy, ix + 1)
            + ty * (1 - tx) * at(iy + 1, ix) + ty * tx * at(iy + 1, ix + 1))
