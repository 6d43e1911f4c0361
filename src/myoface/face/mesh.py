"""The geometry level: :class:`FaceMesh` and stateless mesh functions.

Conventions (all of myoface): millimetres; a right-handed head frame with +y up, +z out of the
face towards a viewer in front of it, and the subject's left at +x. "l"/"r" in names are the
*subject's* left/right.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cached_property

import numba
import numpy as np

from myoface.errors import MyofaceFormatError, MyofaceValueError

#: the largest magnitude (mm) of a coordinate of a mesh that the mesh readers accept: 1 km. A
#: head is about 0.2 m across, and a scanner's frame puts it a few metres from its origin at
#: most; far beyond that, the sums and squares of positions (centroids, k-d trees, normals)
#: lose the face's every digit or overflow (a vertex at 1e308 crashed scipy's k-d tree)
MAX_COORDINATE_MM = 1e6


def check_vertices_mm(vertices, source: str) -> np.ndarray:
    """``vertices`` (V, 3) as float64 positions in mm, once every coordinate is known to be
    finite and within :data:`MAX_COORDINATE_MM`; else a :class:`MyofaceFormatError` naming
    ``source`` (e.g. the file) and the first vertex outside (1-based, as in an OBJ file)."""
    with np.errstate(over="ignore", invalid="ignore"):
        v = np.asarray(vertices, dtype=np.float64)
        bad = ~(np.abs(v) <= MAX_COORDINATE_MM)  # NaN and infinities too
    if v.ndim == 2 and bad.any():
        i, j = (int(k) for k in np.argwhere(bad)[0])
        value = v[i, j]
        where = "is not a finite number" if not np.isfinite(value) else f"is {value:.3g} mm"
        raise MyofaceFormatError(
            f"{source}: vertex {i + 1}'s {'xyz'[j] if j < 3 else j} coordinate {where}; a face "
            f"mesh's coordinates are within {MAX_COORDINATE_MM:.0f} mm (1 km) of its origin. "
            "Is it in millimetres?"
        )
    return v


def triangle_normals(
    vertices: np.ndarray, triangles: np.ndarray, *, unit: bool = True
) -> np.ndarray:
    """Normals of triangles (F,3) over vertices (V,3) mm; unit length, or area-weighted (2 x area)."""
    e = vertices[triangles]
    n = np.cross(e[:, 1] - e[:, 0], e[:, 2] - e[:, 0])
    if unit:
        n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    return n


def vertex_normals(vertices: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area-weighted unit vertex normals, (V,3). Vertices in no triangle get (0, 0, 1)."""
    fn = triangle_normals(vertices, triangles, unit=False)
    vn = np.zeros_like(vertices, dtype=np.float64)
    for k in range(3):
        np.add.at(vn, triangles[:, k], fn)
    norm = np.linalg.norm(vn, axis=1, keepdims=True)
    vn = np.where(norm > 0, vn / np.maximum(norm, 1e-300), np.array([0.0, 0.0, 1.0]))
    return vn


def unique_edges(triangles: np.ndarray) -> np.ndarray:
    """Undirected edges (E,2), each once, sorted so that ``e[:,0] < e[:,1]``."""
    e = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    e = np.sort(e, axis=1)
    return np.unique(e, axis=0)


def boundary_loops(triangles: np.ndarray) -> list[np.ndarray]:
    """Closed boundary loops of an oriented manifold triangle mesh, longest first.

    Each loop is an array of vertex indices in boundary order. A mesh with the default face's
    topology has four: the outer rim, two eyes and the mouth.
    """
    directed = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    key = set(map(tuple, directed.tolist()))
    nxt: dict[int, int] = {}
    for a, b in directed.tolist():
        if (b, a) not in key:  # a boundary half-edge
            nxt[a] = b
    loops, seen = [], set()
    for start in list(nxt):
        if start in seen:
            continue
        loop, v = [], start
        while v not in seen and v in nxt:
            seen.add(v)
            loop.append(v)
            v = nxt[v]
        loops.append(np.array(loop, dtype=np.int64))
    loops.sort(key=len, reverse=True)
    return loops


@dataclass(eq=False)
class FaceMesh:
    """A skin surface: a triangle mesh with optional texture and named landmarks.

    Parameters
    ----------
    vertices : (V, 3) float ndarray
        Positions in millimetres, head frame (+y up, +z out of the face, subject's left at +x).
    triangles : (F, 3) int ndarray
        Vertex indices, counter-clockwise seen from outside (normals point out of the head).
    uv : (V, 2) float ndarray, optional
        Texture coordinates in [0, 1] (v = 0 at the bottom of the texture image).
    texture : (H, W, 3) uint8 ndarray, optional
        Skin texture image (row 0 at the top).
    landmarks : dict of str to int ndarray
        Named vertex-index groups (e.g. ``"eyebrow_l"``), see ``default_face_landmarks.json``.
    name : str
        Where the mesh came from, for messages and provenance.
    """

    vertices: np.ndarray
    triangles: np.ndarray
    uv: np.ndarray | None = None
    texture: np.ndarray | None = None
    landmarks: dict[str, np.ndarray] = field(default_factory=dict)
    name: str = "face"

    def __post_init__(self):
        v = np.asarray(self.vertices, dtype=np.float64)
        t = np.asarray(self.triangles)
        if v.ndim != 2 or v.shape[1] != 3 or len(v) < 3:
            raise MyofaceValueError(f"vertices must have shape (V, 3) with V >= 3; got {v.shape}")
        if not np.isfinite(v).all():
            raise MyofaceValueError("vertices must be finite; got NaN or Inf")
        if t.ndim != 2 or t.shape[1] != 3 or len(t) == 0:
            raise MyofaceValueError(f"triangles must have shape (F, 3) with F >= 1; got {t.shape}")
        if not np.issubdtype(t.dtype, np.integer):
            raise MyofaceValueError(f"triangles must be integer indices; got dtype {t.dtype}")
        if t.min() < 0 or t.max() >= len(v):
            raise MyofaceValueError(
                f"triangle indices must be in [0, {len(v) - 1}]; got range [{t.min()}, {t.max()}]"
            )
        self.vertices = v
        self.triangles = t.astype(np.int64)
        if self.uv is not None:
            uv = np.asarray(self.uv, dtype=np.float64)
            if uv.shape != (len(v), 2):
                raise MyofaceValueError(f"uv must have shape ({len(v)}, 2); got {uv.shape}")
            self.uv = uv
        if self.texture is not None:
            tex = np.asarray(self.texture)
            if tex.ndim != 3 or tex.shape[2] != 3 or tex.dtype != np.uint8:
                raise MyofaceValueError(
                    f"texture must be an (H, W, 3) uint8 image; got {tex.shape} {tex.dtype}"
                )
            self.texture = tex
        lm = {}
        for k, idx in self.landmarks.items():
            idx = np.asarray(idx, dtype=np.int64).reshape(-1)
            if len(idx) and (idx.min() < 0 or idx.max() >= len(v)):
                raise MyofaceValueError(
                    f"landmark group {k!r} has indices outside [0, {len(v) - 1}]"
                )
            lm[k] = idx
        self.landmarks = lm

    @property
    def n_vertices(self) -> int:
        return len(self.vertices)

    @property
    def n_triangles(self) -> int:
        return len(self.triangles)

    @cached_property
    def vertex_normals(self) -> np.ndarray:
        """(V, 3) unit, area-weighted outward vertex normals."""
        return vertex_normals(self.vertices, self.triangles)

    @cached_property
    def edges(self) -> np.ndarray:
        """(E, 2) unique undirected edges."""
        return unique_edges(self.triangles)

    @cached_property
    def boundary_loops(self) -> list[np.ndarray]:
        """Boundary loops, longest (the outer rim) first."""
        return boundary_loops(self.triangles)

    def landmark(self, name: str) -> np.ndarray:
        """Vertex indices of landmark group ``name``; a clear error lists the known groups."""
        try:
            return self.landmarks[name]
        except KeyError:
            known = ", ".join(sorted(self.landmarks)) or "(none)"
            raise MyofaceValueError(
                f"unknown landmark group {name!r}; this face has: {known}"
            ) from None

    def mirrored(self, mirror: np.ndarray) -> FaceMesh:
        """The mesh reflected in x (x -> -x) and renumbered by ``mirror`` (a vertex permutation
        pairing each vertex with its mirror partner), so that vertex i of the result lies where
        the reflection of vertex ``mirror[i]`` does. On a face with a left/right symmetric
        topology, whatever is placed on the result's left side by vertex numbers lands, reflected
        back, on this face's right side.
        """
        m = np.asarray(mirror, dtype=np.int64)
        if m.shape != (self.n_vertices,) or not np.array_equal(np.sort(m), np.arange(len(m))):
            raise MyofaceValueError("mirror must be a permutation of the vertex indices")
        v = self.vertices[m] * np.array([-1.0, 1.0, 1.0])
        return FaceMesh(v, m[self.triangles][:, [0, 2, 1]], None, None, self.landmarks, self.name)

    def with_vertices(self, vertices: np.ndarray) -> FaceMesh:
        """The same mesh (topology, uv, texture, landmarks) with new vertex positions."""
        return FaceMesh(vertices, self.triangles, self.uv, self.texture, self.landmarks, self.name)


@numba.njit(cache=True)
def _closest_on_triangle(p, a, b, c):
    """Closest point to p on triangle abc (Ericson, Real-Time Collision Detection, 5.1.5)."""
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = ab @ ap, ac @ ap
    if d1 <= 0 and d2 <= 0:
        return a
    bp = p - b
    d3, d4 = ab @ bp, ac @ bp
    if d3 >= 0 and d4 <= d3:
        return b
    vc = d1 * d4 - d3 * d2
    if vc <= 0 and d1 >= 0 and d3 <= 0:
        return a + d1 / (d1 - d3) * ab
    cp = p - c
    d5, d6 = ab @ cp, ac @ cp
    if d6 >= 0 and d5 <= d6:
        return c
    vb = d5 * d2 - d1 * d6
    if vb <= 0 and d2 >= 0 and d6 <= 0:
        return a + d2 / (d2 - d6) * ac
    va = d3 * d6 - d5 * d4
    if va <= 0 and (d4 - d3) >= 0 and (d5 - d6) >= 0:
        return b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b)
    denom = 1.0 / (va + vb + vc)
    return a + ab * (vb * denom) + ac * (vc * denom)


@numba.njit(cache=True)
def _point_mesh_distance(points, verts, tris, cand):
    out = np.empty(points.shape[0])
    for i in range(points.shape[0]):
        best = np.inf
        for k in range(cand.shape[1]):
            f = cand[i, k]
            q = _closest_on_triangle(
                points[i], verts[tris[f, 0]], verts[tris[f, 1]], verts[tris[f, 2]]
            )
            d = np.sqrt(((points[i] - q) ** 2).sum())
            best = min(best, d)
        out[i] = best
    return out


def point_mesh_distance(
    points: np.ndarray, vertices: np.ndarray, triangles: np.ndarray, n_candidates: int = 32
) -> np.ndarray:
    """Distance (mm) from each of ``points`` (N, 3) to the surface of a triangle mesh.

    Exact over the ``n_candidates`` triangles whose centroids are nearest each point (a k-d tree
    picks them); on meshes whose triangles are small against the distances asked, that is the
    nearest triangle.
    """
    from scipy.spatial import cKDTree

    p = np.ascontiguousarray(points, dtype=np.float64)
    v = np.ascontiguousarray(vertices, dtype=np.float64)
    t = np.ascontiguousarray(triangles, dtype=np.int64)
    k = min(n_candidates, len(t))
    _, cand = cKDTree(v[t].mean(axis=1)).query(p, k=k)
    cand = np.asarray(cand, dtype=np.int64).reshape(len(p), k)
    return _point_mesh_distance(p, v, t, cand)
