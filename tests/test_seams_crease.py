"""Fix Seams' crease rule at each end of a seam edge: a seam is smooth where both sides have one shading
normal at each of the edge's ends, whatever the normal does along the edge; it is a crease where they
differ at either end. A rule that compared a side's normal at one end with the other side's at the other
end took every seam of a curved, smooth-shaded surface for a crease (and left it unfixed)."""

import numpy as np
import pytest

from core import Mesh
from core.geometry import seams as G


def split_plane(normal_at):
    """The unit plane cut along x = 0.5 into two UV islands (the right half turned by 180 degrees);
    the corner normals are ``normal_at(vertex index, triangle index)``."""
    P = np.array([[0, 0, 0], [.5, 0, 0], [1, 0, 0], [0, 1, 0], [.5, 1, 0], [1, 1, 0]], float)
    F = np.array([[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4]])
    UV = P[F][:, :, :2].copy()
    UV[2:] = np.stack([1.5 - UV[2:, :, 0], 1.0 - UV[2:, :, 1]], -1)
    N = np.array([[normal_at(v, t) for v in tri] for t, tri in enumerate(F)], float)
    return Mesh(P, F, UV, N, name="split")


def tilted(degrees):
    a = np.radians(degrees)
    return [0.0, np.sin(a), np.cos(a)]


@pytest.mark.parametrize("swing", [5.0, 30.0, 60.0])
def test_a_smooth_seam_whose_normal_turns_along_it_is_not_a_crease(swing):
    """The seam runs from vertex 1 (y = 0) to vertex 4 (y = 1); the normal turns by ``swing`` degrees
    along it (a curved surface), the same on both sides at each end: smooth."""
    m = split_plane(lambda v, t: tilted(-swing / 2 if v in (0, 1, 2) else swing / 2))
    L = G.seam_lookups(m, 16)
    assert L.edges == 1 and L.points > 0 and not L.crease.any()


@pytest.mark.parametrize("end", [1, 4])
def test_a_seam_whose_sides_differ_at_one_end_is_a_crease(end):
    """Split normals at one end only (a sharp corner there): a crease, whichever end it is."""
    m = split_plane(lambda v, t: tilted(20.0 if (v == end and t >= 2) else 0.0))
    L = G.seam_lookups(m, 16)
    assert L.edges == 1 and L.crease.all()
