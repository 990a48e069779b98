"""Triangle meshes as the baker takes them: validated numpy arrays in world space.

Everything that can be wrong with the arrays is found here, before any heavy work, and reported with
the mesh's name and the exact problem (see :mod:`core.base.errors`).
"""

import copy

import numpy as np

from ..base.errors import MeshError, MeshTypeError, SettingsError

#: Largest |u| or |v| accepted. UV maps live in [0, 1] (UDIM tiles reach u = 10, v = 100); values far
#: beyond come from broken importers or scripts, and texel coordinates of 1e17 lose all precision.
MAX_UV = float(1 << 16)
#: Triangles worked at a time where a whole-mesh temporary would scale with the mesh (its corners:
#: 72 bytes a triangle); the results are the same bits as in one go (every operation is per triangle).
SLICE = 1 << 18


def _real_array(a, what, name):
    try:
        arr = np.asarray(a)
    except Exception as e:  # ragged lists and the like
        raise MeshTypeError(f"mesh {name!r}: {what} cannot be read as an array ({e})") from None
    if arr.dtype == object or not (np.issubdtype(arr.dtype, np.floating) or np.issubdtype(arr.dtype, np.integer)) \
            or arr.dtype == np.bool_:
        raise MeshTypeError(f"mesh {name!r}: {what} must hold real numbers, got dtype {arr.dtype}")
    return arr


def _check_shape(arr, shape, what, name):
    if arr.ndim != len(shape) or any(s is not None and a != s for a, s in zip(arr.shape, shape)):
        want = "(" + ", ".join("N" if s is None else str(s) for s in shape) + ")"
        raise MeshError(f"mesh {name!r}: {what} must have shape {want}, got {arr.shape}")


def _check_finite(arr, what, name):
    bad = ~np.isfinite(arr)
    if bad.any():
        first = np.argwhere(bad)[0]
        kind = "NaN" if np.isnan(arr[tuple(first)]) else "infinity"
        raise MeshError(f"mesh {name!r}: {what} contain {int(bad.sum())} non-finite values "
                        f"({kind} first at index {tuple(int(i) for i in first)})")


def corner_positions(positions, triangles):
    """positions[triangles] (T, 3, 3), by np.take: numpy's fancy indexing of a (V, 3) array by a
    (T, 3) index array is 3 to 6 times slower (0.3-0.5 s for a million triangles)."""
    # Indices are checked where a Mesh is made; numpy's default mode checks each one again.
    return np.take(positions, triangles.reshape(-1), axis=0, mode="clip").reshape(len(triangles), 3, positions.shape[1])


def cross(a, b):
    """a x b of vectors given as their three component arrays (sequences of 3 arrays): the three
    component arrays of the product, the same floating-point operations as np.cross. Components,
    not (n, 3) arrays: numpy's loops over an inner axis of 3 cost several times the same work on
    whole columns."""
    out = []
    for i, j, k in ((0, 1, 2), (1, 2, 0), (2, 0, 1)):
        v = a[j] * b[k]
        v -= a[k] * b[j]
        out.append(v)
    return out


def norms(x, y, z):
    """The lengths of vectors given as their three component arrays: np.linalg.norm's operations
    ((x x + y y) + z z, then the square root) on whole columns, the same bits in a fraction of the
    time it takes over the last axis of an (n, 3) array."""
    out = x * x
    out += y * y
    out += z * z
    return np.sqrt(out, out=out)


def face_geometry(corners):
    """(areas (T,), unit face normals (T, 3), zero for degenerate triangles) of corners (T, 3, 3).

    Component by component: numpy's loops over an inner axis of 3 (a (T, 3) slice of the corners, a
    (T, 1) factor broadcast over 3 columns) cost several times the same work on whole columns (a
    million triangles: 107 -> 46 ms). The same operations in the same order as before, so the same
    bits.
    """
    c = cross([corners[:, 1, k] - corners[:, 0, k] for k in range(3)],
              [corners[:, 2, k] - corners[:, 0, k] for k in range(3)])
    length = norms(*c)
    ok = length > 0
    d = np.where(ok, length, 1.0)
    out = np.empty((len(corners), 3), length.dtype)
    for i in range(3):
        np.divide(c[i], d, out=out[:, i])
    out[~ok] = 0.0
    return 0.5 * length, out


def _unit_corner_normals(n, face_normals):
    """Corner normals (T, 3, 3) float64 scaled to unit length, the face normal where one is zero: the
    operations of np.linalg.norm and np.where over the last axis, column by column (same bits)."""
    flat = n.reshape(-1, 3)
    length = norms(flat[:, 0], flat[:, 1], flat[:, 2])
    ok = length > 0
    d = np.where(ok, length, 1.0)
    out = np.empty(n.shape, np.float64)  # C order: ``of`` must be a view of it
    of = out.reshape(-1, 3)
    fn = repeat_corners(face_normals).reshape(-1, 3)
    for c in range(3):
        np.divide(flat[:, c], d, out=of[:, c])
        np.copyto(of[:, c], fn[:, c], where=~ok)
    return out


def repeat_corners(face_values):
    """(T, 3) per-face values as (T, 3, 3) per corner (np.repeat along a new axis, faster)."""
    out = np.empty((len(face_values), 3, face_values.shape[1]), face_values.dtype)
    out[:] = face_values[:, None, :]
    return out


def _own(arr, dtype):
    """``arr`` as a C-ordered array of ``dtype``: the caller's own array where it already is one (no
    copy: a mesh of ten million triangles is hundreds of megabytes), else a converted copy."""
    if arr.dtype == dtype and arr.flags.c_contiguous:
        return arr
    return arr.astype(dtype, order="C")


def mesh_list(meshes, what="occluders"):
    """``meshes`` (any iterable of Mesh, or None) as a list; SettingsError saying what to pass for
    anything else, a single Mesh included (a list of one: ``[mesh]``)."""
    if meshes is None:
        return []
    if isinstance(meshes, Mesh):
        raise SettingsError(f"{what} must be a list of core.Mesh objects, got the single mesh {meshes.name!r}: "
                            f"pass it in a list, {what}=[mesh]")
    try:
        out = list(meshes)
    except TypeError:
        raise SettingsError(f"{what} must be a list of core.Mesh objects, got {type(meshes).__name__}") from None
    for mesh in out:
        if not isinstance(mesh, Mesh):
            raise SettingsError(f"{what} must be core.Mesh objects, got {type(mesh).__name__}")
    return out


class Mesh:
    """A triangle mesh in world space.

    Parameters
    ----------
    positions : (V, 3) real array of vertex positions.
    triangles : (T, 3) integer array of vertex indices.
    uvs : (T, 3, 2) real array, the UV of each triangle corner, or None (occluders need none).
    normals : (T, 3, 3) real array, the shading normal of each triangle corner, or None for face
        normals (flat shading). Corner normals need not be unit length; zero-length ones fall back
        to the face normal.
    name : used in every error message about this mesh.

    Attributes
    ----------
    positions : (V, 3) float64; triangles : (T, 3) int64; uvs : (T, 3, 2) float64 or None. Arrays
    given as C-ordered float64 (int64 for the triangles) are kept, not copied: the mesh shares
    them with the caller, who must not change them while the mesh is in use.

    areas : (T,) float64, face_normals : (T, 3) float64 unit geometric normals, from the winding
    (v1 - v0) x (v2 - v0), zero for degenerate triangles; normals : (T, 3, 3) float64 unit corner
    normals. All three are computed when first asked for and kept (:meth:`drop_face_geometry` lets
    them go; they come back with the same bits); :meth:`face_geometry_of` and :meth:`corner_normals`
    give them for some triangles without computing them for all.
    """

    def __init__(self, positions, triangles, uvs=None, normals=None, name="mesh"):
        self.name = str(name)
        p = _real_array(positions, "positions", self.name)
        _check_shape(p, (None, 3), "positions", self.name)
        t = np.asarray(triangles) if not isinstance(triangles, np.ndarray) else triangles
        if t.dtype == object or not np.issubdtype(t.dtype, np.integer) or t.dtype == np.bool_:
            if t.size == 0 and t.dtype != object:
                t = t.astype(np.int64)
            else:
                raise MeshTypeError(f"mesh {self.name!r}: triangles must be integer vertex indices, "
                                    f"got dtype {t.dtype}")
        _check_shape(t, (None, 3), "triangles", self.name)
        if len(t) == 0:
            raise MeshError(f"mesh {self.name!r} is empty: it has no triangles")
        if len(p) == 0:
            raise MeshError(f"mesh {self.name!r} is empty: it has no vertices")
        _check_finite(p, "positions", self.name)
        lo, hi = int(t.min()), int(t.max())
        if lo < 0 or hi >= len(p):
            bad = int(((t < 0) | (t >= len(p))).any(axis=1).sum())
            raise MeshError(f"mesh {self.name!r}: {bad} triangles index vertices out of range "
                            f"(indices span {lo}..{hi}, the mesh has {len(p)} vertices)")
        # C order, whatever the input's (numpy's advanced indexing, e.g. corners reordered with a list,
        # may return another layout; astype keeps it): the core reshapes these arrays into views.
        self.positions = _own(p, np.float64)
        self.triangles = _own(t, np.int64)
        T = len(t)

        self.uvs = None
        if uvs is not None:
            uv = _real_array(uvs, "uvs", self.name)
            if uv.shape == (len(p), 2):
                raise MeshError(
                    f"mesh {self.name!r}: uvs has one UV per vertex, shape {uv.shape}; a Mesh takes one UV per "
                    f"triangle corner, shape ({T}, 3, 2): pass uvs[triangles] (the per-vertex UVs gathered "
                    "at each triangle's corners)")
            _check_shape(uv, (T, 3, 2), "uvs (one UV per triangle corner)", self.name)
            _check_finite(uv, "uvs", self.name)
            if float(uv.max()) > MAX_UV or float(uv.min()) < -MAX_UV:
                far = np.abs(uv) > MAX_UV
                tri = int(np.argwhere(far)[0][0])
                raise MeshError(
                    f"mesh {self.name!r}: {int(far.any(axis=(1, 2)).sum())} triangles have UV coordinates "
                    f"beyond +-{MAX_UV:g} (largest {float(np.abs(uv).max()):.3g}, first at triangle {tri}); "
                    "a UV map lies in [0, 1]: unwrap again or fix the UV map"
                )
            self.uvs = _own(uv, np.float64)

        self._areas = self._face_normals = self._normals = None
        #: The corner normals as given (None: flat shading); a transformed copy's source mesh.
        self._corner_input, self._source = None, None
        if normals is None:
            self.has_corner_normals = False
        else:
            n = _real_array(normals, "normals", self.name)
            _check_shape(n, (T, 3, 3), "normals (one normal per triangle corner)", self.name)
            _check_finite(n, "normals", self.name)
            self._corner_input = _own(n, np.float64)
            self.has_corner_normals = True

    # -- face geometry and normals, on demand -----------------------------------------------------------

    def face_geometry_of(self, tri=None):
        """(areas, unit face normals) of triangles ``tri`` (all when None): :func:`face_geometry`
        row by row, the same bits whichever triangles are asked for."""
        if tri is None:
            if self._face_normals is None:
                self._areas, self._face_normals = self._face_geometry(None)
            return self._areas, self._face_normals
        if self._face_normals is not None:
            return self._areas[tri], self._face_normals[tri]
        return self._face_geometry(tri)

    def _face_geometry(self, tri):
        t = self.triangles if tri is None else self.triangles[tri]
        if len(t) <= SLICE:
            return face_geometry(corner_positions(self.positions, t))
        areas, normals = np.empty(len(t)), np.empty((len(t), 3))
        for lo in range(0, len(t), SLICE):  # a slice's corners at a time (72 bytes a triangle)
            areas[lo:lo + SLICE], normals[lo:lo + SLICE] = face_geometry(corner_positions(self.positions,
                                                                                          t[lo:lo + SLICE]))
        return areas, normals

    @property
    def areas(self):
        return self.face_geometry_of()[0]

    @property
    def face_normals(self):
        return self.face_geometry_of()[1]

    @property
    def normals(self):
        if self._normals is None:
            self._normals = self.corner_normals()
        return self._normals

    @normals.setter
    def normals(self, value):
        self._normals = value

    def corner_normals(self, tri=None):
        """Unit corner normals (n, 3, 3) of triangles ``tri`` (all when None; kept ones when
        :attr:`normals` was asked for): the same bits for any selection."""
        if self._normals is not None:
            return self._normals if tri is None else self._normals[tri]
        if not self.has_corner_normals:
            return repeat_corners(self.face_geometry_of(tri)[1])
        fn = self.face_geometry_of(tri)[1]
        if self._source is not None:
            # A transformed copy: its source's unit normals, and its own face normal at corners
            # that fell back to a zero one (column by column: see face_geometry).
            n = self._source.corner_normals(tri)
            nz = (n != 0).reshape(-1, 3)
            lost = ~(nz[:, 0] | nz[:, 1] | nz[:, 2]).reshape(len(n), 3)
            return np.where(lost[..., None], fn[:, None, :], n) if lost.any() else n
        raw = self._corner_input if tri is None else self._corner_input[tri]
        return _unit_corner_normals(raw, fn)

    def given_normals(self):
        """What the mesh's corner normals can be made again from (:class:`Mesh`'s ``normals``
        argument): the array given, or the unit normals of a transformed copy; None when flat."""
        if not self.has_corner_normals:
            return None
        return self._corner_input if self._corner_input is not None else self.normals

    def drop_face_geometry(self):
        """Let go of the areas, face normals and corner normals computed so far (hundreds of bytes a
        triangle); asked for again, they are computed again, with the same bits."""
        self._areas = self._face_normals = self._normals = None

    def transformed(self, centre, scale):
        """A copy with positions (p - centre) / scale: the same surface in another unit and origin.

        Face normals and areas are those of the new positions (they keep their precision when the
        original coordinates were tiny or huge); corner normals and UVs are unchanged. No
        validation is repeated.
        """
        out = copy.copy(self)
        out.positions = (self.positions - np.asarray(centre, dtype=np.float64)) / float(scale)
        out._areas = out._face_normals = out._normals = None
        if self.has_corner_normals:
            out._source, out._corner_input = self, None
        return out

    def same_geometry(self, other):
        """Whether ``other`` has exactly the same vertex positions and triangles (the same surface)."""
        return (self is other or (self.positions.shape == other.positions.shape
                                  and self.triangles.shape == other.triangles.shape
                                  and np.array_equal(self.triangles, other.triangles)
                                  and np.array_equal(self.positions, other.positions)))

    @property
    def triangle_count(self):
        return len(self.triangles)

    def __repr__(self):
        return f"Mesh({self.name!r}, {len(self.positions)} vertices, {len(self.triangles)} triangles)"
