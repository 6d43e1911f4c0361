"""Personal face models: the generic face conformed to one person's scan or photograph.

From a scan (Terzopoulos & Waters 1993, Section IV): the head is sampled into cylindrical range
and colour maps (:mod:`myoface.face.cylindrical`); the generic mesh is aligned to the person by
the landmarks, projected radially into the maps' (angle, height) domain, pulled onto the
person's features while its edges act as springs that keep its shape, and each node then samples
the range map: its cylindrical coordinates and the sampled radius give its 3-D position, and the
same coordinates are its texture coordinates into the colour map.

From a photograph (beyond the paper): MediaPipe's face mesh gives the 468 points of the default
face's topology; they become the personal mesh (its depth blended with the generic face's), and
the photo its texture.

Because the result keeps the default face's topology (468 vertices, MediaPipe indexing), the
default muscle set, the landmark groups and everything built on them carry over unchanged.
"""

from __future__ import annotations

import io
import json
import os
import warnings
from dataclasses import dataclass, field
from functools import lru_cache
from importlib import resources
from pathlib import Path

import numpy as np

from myoface._io import parse_json, read_text
from myoface.errors import (
    MyofaceError,
    MyofaceFileNotFoundError,
    MyofaceFormatError,
    MyofaceValueError,
    MyofaceWarning,
)
from myoface.face.cylindrical import CYBERWARE_SHAPE, CylindricalMaps, maps_from_mesh
from myoface.face.io import load_default_face
from myoface.face.mesh import FaceMesh, point_mesh_distance
from myoface.facemesh import MAX_FACES, FaceMeshDetector

#: iBUG-68 index ranges of the label names of menpo's LJSON files (and their short forms)
IBUG_LABELS = {
    "jaw": range(0, 17),
    "chin": range(0, 17),
    "left_eyebrow": range(17, 22),
    "leyebrow": range(17, 22),
    "right_eyebrow": range(22, 27),
    "reyebrow": range(22, 27),
    "nose": range(27, 36),
    "left_eye": range(36, 42),
    "leye": range(36, 42),
    "right_eye": range(42, 48),
    "reye": range(42, 48),
    "mouth": range(48, 68),
}
#: iBUG-68 points used to align the generic face and to pull it onto the person: all but the
#: jaw line, which annotators place on the 2-D silhouette and so matches no fixed vertex
INNER_IBUG = np.arange(17, 68)
#: a face's landmarks fit the generic face's after a similarity to within this fraction of the
#: face's size (RMS); more means the points are not a face's (or not in iBUG order)
MAX_FIT_RESIDUAL = 0.12
#: landmarks of a scan lie on its surface: their median distance to it may be at most this (mm)
MAX_LANDMARK_OFF_SURFACE_MM = 5.0
#: weight of a landmark constraint against one edge spring in the 2-D relaxation
LANDMARK_WEIGHT = 50.0


@lru_cache(maxsize=1)
def ibug68_to_mediapipe() -> tuple[tuple[int, ...], ...]:
    """For each iBUG-68 landmark, the default-face vertices whose mean is that point.

    Source: P. Yan, Mediapipe_2_Dlib_Landmarks (2024), see ``data/ibug68_mediapipe.json``.
    """
    text = (resources.files("myoface") / "data" / "ibug68_mediapipe.json").read_text()
    return tuple(tuple(v) for v in json.loads(text)["ibug68_to_mediapipe"])


def ibug_points_of(vertices: np.ndarray) -> np.ndarray:
    """(68, D) iBUG-68 points of a (468, D) array in the default topology."""
    return np.array([np.asarray(vertices)[list(ix)].mean(axis=0) for ix in ibug68_to_mediapipe()])


def read_landmarks(path: str | os.PathLike) -> np.ndarray:
    """Read 68 3-D landmarks (iBUG-68 order, mm) from a file.

    Accepted: menpo's ``.ljson`` (label groups jaw/chin, left/right eyebrow, nose, left/right eye,
    mouth are put in iBUG order; otherwise the points must already be in it), a ``.json`` list of
    68 [x, y, z] (or ``{"points": [...]}``), ``.npy``, or a text file of 68 rows ``x y z``.
    """
    p = Path(path)
    if not p.is_file():
        raise MyofaceFileNotFoundError(f"no such landmark file: {p}")

    try:
        if p.suffix.lower() == ".npy":
            pts = np.load(p, allow_pickle=False)
        elif p.suffix.lower() in (".json", ".ljson"):
            doc = parse_json(read_text(p, "landmark file (JSON)"), str(p))
            pts = _points_from_json(doc)
        else:
            text = read_text(p, "landmark file (text)")
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")  # "no data": the shape check below says it
                pts = np.loadtxt(
                    io.StringIO(text),
                    delimiter="," if p.suffix.lower() == ".csv" else None,
                    ndmin=2,
                )
        pts = np.asarray(pts, dtype=np.float64)
    except MyofaceError:
        raise
    except (
        OSError,
        ValueError,
        TypeError,
        KeyError,
        IndexError,
        AttributeError,
        EOFError,
        SyntaxError,
        OverflowError,
        RecursionError,
    ) as exc:  # numpy's and json's readers raise all of these on bad bytes
        msg = " ".join(str(exc).split())[:200]
        raise MyofaceFormatError(f"cannot read landmarks from {p}: {msg}") from None
    if pts.shape != (68, 3) or not np.isfinite(pts).all():
        raise MyofaceFormatError(
            f"{p}: expected 68 finite 3-D points (iBUG-68 order); got shape {pts.shape}"
        )
    return pts


def _points_from_json(doc) -> np.ndarray:
    if isinstance(doc, list):
        return np.asarray(doc, dtype=np.float64)
    if "points" in doc:
        return np.asarray(doc["points"], dtype=np.float64)
    groups = doc.get("groups", {})
    if not groups:
        raise KeyError("no 'points' and no 'groups'")
    g = groups.get("LJSON", next(iter(groups.values())))
    pts = np.asarray(g["landmarks"]["points"], dtype=np.float64)
    labels = g.get("labels", [])
    if len(pts) != 68 or not labels:
        return pts
    out = np.full((68, pts.shape[1]), np.nan)
    for lab in labels:
        rng = IBUG_LABELS.get(str(lab["label"]).lower())
        if rng is None or len(rng) != len(lab["mask"]):
            return pts  # unknown labelling: take the points in their order
        out[list(rng)] = pts[lab["mask"]]
    return out


# --------------------------------------------------------------------------- alignment


def fit_similarity_3d(src: np.ndarray, dst: np.ndarray, scale: bool = True):
    """Least-squares ``dst ~ s R src + t`` (Umeyama 1991). Returns (s, R (3,3), t (3,));
    ``scale=False``: the rigid fit (``s`` = 1)."""
    src, dst = np.asarray(src, float), np.asarray(dst, float)
    ms, md = src.mean(0), dst.mean(0)
    a, b = src - ms, dst - md
    u, sig, vt = np.linalg.svd(b.T @ a)
    d = np.sign(np.linalg.det(u @ vt))
    dmat = np.diag([1.0, 1.0, d])
    r = u @ dmat @ vt
    s = float(np.trace(np.diag(sig) @ dmat) / (a**2).sum()) if scale else 1.0
    return s, r, md - s * r @ ms


@dataclass
class Alignment:
    """How a person's scan sits against the generic face.

    ``X_head = rotation.T @ (X_scan - translation_mm)`` takes scan coordinates to the head frame,
    where the generic face scaled by ``scale`` fits the person's landmarks.
    """

    scale: float
    rotation: np.ndarray
    translation_mm: np.ndarray
    residual_mm: float  # RMS landmark distance after the fit
    face_size_mm: float

    def to_head(self, points: np.ndarray) -> np.ndarray:
        return (np.asarray(points, float) - self.translation_mm) @ self.rotation


def align_to_generic(landmarks_mm: np.ndarray, generic: FaceMesh) -> Alignment:
    """Fit the generic face's iBUG points to a person's (68, 3) landmarks by a similarity."""
    lm = np.asarray(landmarks_mm, float)
    g = ibug_points_of(generic.vertices)
    s, r, t = fit_similarity_3d(g[INNER_IBUG], lm[INNER_IBUG])
    fit = s * g[INNER_IBUG] @ r.T + t
    res = float(np.sqrt(((fit - lm[INNER_IBUG]) ** 2).sum(1).mean()))
    size = float(np.sqrt(((lm[INNER_IBUG] - lm[INNER_IBUG].mean(0)) ** 2).sum(1).mean()))
    if not size > 0:
        raise MyofaceValueError("the landmarks all lie at one point")
    if res > MAX_FIT_RESIDUAL * size or s <= 0:
        raise MyofaceValueError(
            f"the landmarks do not fit a face: after the best similarity they are "
            f"{res:.1f} mm (RMS) from the generic face's, {res / size:.0%} of the face's size "
            f"(at most {MAX_FIT_RESIDUAL:.0%} for a face). Are they 68 iBUG points in iBUG order?"
        )
    return Alignment(s, r, t, res, size)


def orient_mesh(mesh: FaceMesh, alignment: Alignment) -> FaceMesh:
    """``mesh`` moved into the head frame of ``alignment`` (same topology, uv, texture)."""
    return FaceMesh(
        alignment.to_head(mesh.vertices),
        mesh.triangles,
        mesh.uv,
        mesh.texture,
        mesh.landmarks,
        mesh.name,
    )


# --------------------------------------------------------------------------- conformation


def _edge_operator(n: int, edges: np.ndarray):
    from scipy import sparse

    m = len(edges)
    rows = np.repeat(np.arange(m), 2)
    cols = edges.ravel()
    vals = np.tile([1.0, -1.0], m)
    return sparse.csr_matrix((vals, (rows, cols)), shape=(m, n))


def relax_2d(
    start: np.ndarray,
    edges: np.ndarray,
    groups: list,
    targets: np.ndarray,
    weight: float = LANDMARK_WEIGHT,
) -> np.ndarray:
    """Pull a 2-D spring mesh onto feature targets, its edges resisting change.

    Minimises ``sum_edges |(p_i - p_j) - (q_i - q_j)|^2 + weight sum_k |mean(p[groups[k]]) -
    targets[k]|^2`` over node positions p (N, 2), starting shape q = ``start``: the edges are
    springs whose rest vectors are the generic mesh's, the features stiff springs to their targets.
    """
    from scipy import sparse
    from scipy.sparse.linalg import spsolve

    q = np.asarray(start, float)
    n = len(q)
    d = _edge_operator(n, edges)
    rows, cols, vals = [], [], []
    for k, g in enumerate(groups):
        for i in g:
            rows.append(k)
            cols.append(i)
            vals.append(1.0 / len(g))
    c = sparse.csr_matrix((vals, (rows, cols)), shape=(len(groups), n))
    a = (d.T @ d + weight * (c.T @ c)).tocsc()
    out = np.empty_like(q)
    for k in range(q.shape[1]):
        b = d.T @ (d @ q[:, k]) + weight * (c.T @ targets[:, k])
        out[:, k] = spsolve(a, b)
    return out


@dataclass
class Conformation:
    """A personal face mesh and how it was made (see :func:`conform_to_maps`)."""

    face: FaceMesh
    maps: CylindricalMaps
    theta_y: np.ndarray  # (V, 2) the nodes' angles (rad) and heights (mm) in the maps
    landmark_error_mm: np.ndarray  # (68,) distance of each iBUG point of the mesh to the target
    info: dict = field(default_factory=dict)
    scan: FaceMesh | None = None  # the scan moved into the head frame (scan route only)


def conform_to_maps(
    maps: CylindricalMaps,
    landmarks_mm: np.ndarray,
    generic: FaceMesh,
    *,
    use: np.ndarray | None = None,
    name: str = "person",
    max_hole_cells: int = 64,
) -> Conformation:
    """Conform the generic mesh to a person's maps (T&W 1993 §IV).

    Parameters
    ----------
    maps : the person's range and colour maps (head frame).
    landmarks_mm : (68, 3) the person's iBUG-68 landmarks in the maps' frame (mm).
    generic : the generic face (default topology).
    use : iBUG indices that pull the mesh (default :data:`INNER_IBUG`); the others are only
        measured (a hold-out).
    max_hole_cells : holes in the range map up to this size are filled; a node landing in a
        larger hole is an error.

    The mesh is returned in the head frame of the landmarks' fit (:class:`Alignment`), with
    texture coordinates into the maps' colour map.
    """
    lm = np.asarray(landmarks_mm, float)
    use = INNER_IBUG if use is None else np.asarray(use)
    al = align_to_generic(lm, generic)
    placed = al.scale * generic.vertices @ al.rotation.T + al.translation_mm
    filled = maps.filled(max_hole_cells)
    cyl = filled.to_cylindrical(placed)
    r0 = float(np.median(cyl[:, 2]))  # angles are scaled to arc length at this radius (mm)
    q = np.column_stack([cyl[:, 0] * r0, cyl[:, 1]])
    tgt_cyl = filled.to_cylindrical(lm)
    groups = [list(ibug68_to_mediapipe()[k]) for k in use]
    targets = np.column_stack([tgt_cyl[use, 0] * r0, tgt_cyl[use, 1]])
    p = relax_2d(q, generic.edges, groups, targets)
    theta, y = p[:, 0] / r0, p[:, 1]
    r = filled.sample_radius(theta, y)
    bad = ~np.isfinite(r)
    if bad.any():
        frac = bad.mean()
        raise MyofaceValueError(
            f"the range map has holes under the face: {bad.sum()} of {len(r)} mesh nodes "
            f"({frac:.0%}) land where the scan has no surface (holes larger than "
            f"{max_hole_cells} cells are not filled). Rescan or fill the holes, and check that "
            "the landmarks are in the maps' frame."
        )
    verts = filled.to_cartesian(theta, y, r)
    err = np.linalg.norm(ibug_points_of(verts) - lm, axis=1)
    face = FaceMesh(
        al.to_head(verts),  # the maps' frame -> the head frame (identity for oriented maps)
        generic.triangles,
        filled.uv_of(theta, y),
        filled.rgb,
        generic.landmarks,
        name=name,
    )
    info = {
        "scale": al.scale,
        "alignment_residual_mm": al.residual_mm,
        "landmarks_used": [int(k) for k in use],
        "filled_hole_cells": int(maps.holes.sum() - filled.holes.sum()),
    }
    return Conformation(face, filled, np.column_stack([theta, y]), err, info)


def surface_errors(face: FaceMesh, scan: FaceMesh) -> dict:
    """Distances (mm) from the personal mesh's vertices to the scanned surface, and back from
    the scan's vertices in the face region (within the mesh's cylindrical footprint) to it."""
    d_fwd = point_mesh_distance(face.vertices, scan.vertices, scan.triangles)
    lo, hi = face.vertices.min(0), face.vertices.max(0)
    front = scan.vertices[:, 2] > np.percentile(face.vertices[:, 2], 5)
    inside = (
        (scan.vertices[:, 0] > lo[0])
        & (scan.vertices[:, 0] < hi[0])
        & (scan.vertices[:, 1] > lo[1])
        & (scan.vertices[:, 1] < hi[1])
        & front
    )
    d_back = point_mesh_distance(scan.vertices[inside], face.vertices, face.triangles)
    return {
        "mesh_to_scan_mean_mm": float(d_fwd.mean()),
        "mesh_to_scan_max_mm": float(d_fwd.max()),
        "scan_to_mesh_mean_mm": float(d_back.mean()) if len(d_back) else float("nan"),
        "scan_to_mesh_p95_mm": float(np.percentile(d_back, 95)) if len(d_back) else float("nan"),
    }


def face_from_scan(
    scan: FaceMesh,
    landmarks_mm: np.ndarray,
    *,
    generic: FaceMesh | None = None,
    shape: tuple[int, int] = CYBERWARE_SHAPE,
    name: str | None = None,
) -> Conformation:
    """The whole scan route: orient the scan by its landmarks, make its maps, conform.

    ``scan`` is a (textured) head mesh in millimetres with +y roughly up; ``landmarks_mm`` its
    (68, 3) iBUG-68 points in the same coordinates. The result is in the head frame.
    """
    generic = load_default_face() if generic is None else generic
    lm_in = np.asarray(landmarks_mm, float)[INNER_IBUG]
    off = float(np.median(point_mesh_distance(lm_in, scan.vertices, scan.triangles)))
    if off > MAX_LANDMARK_OFF_SURFACE_MM:
        raise MyofaceValueError(
            f"the landmarks are not on this mesh: their median distance to its surface is "
            f"{off:.1f} mm (at most {MAX_LANDMARK_OFF_SURFACE_MM} mm). Is the mesh a head, in the "
            "landmarks' coordinates and units (--scale-mm)?"
        )
    head, maps, al = head_maps(scan, landmarks_mm, generic, shape)
    lm = al.to_head(landmarks_mm)
    _check_head(maps, lm)
    conf = conform_to_maps(maps, lm, generic, name=name or scan.name)
    conf.info["scan_rotation"] = al.rotation.tolist()
    conf.info["scan_translation_mm"] = al.translation_mm.tolist()
    conf.scan = head
    return conf


def head_maps(
    scan: FaceMesh,
    landmarks_mm: np.ndarray,
    generic: FaceMesh,
    shape: tuple[int, int] = CYBERWARE_SHAPE,
) -> tuple[FaceMesh, CylindricalMaps, Alignment]:
    """Move a scan into the head frame by its landmarks and make its maps there.

    The axis stands on the midline (x = 0) at the depth of the generic face's sides (its
    vertices 234 and 454, in front of the ears), scaled to the person.
    """
    al = align_to_generic(landmarks_mm, generic)
    head = orient_mesh(scan, al)
    axis_z = al.scale * float(generic.vertices[[234, 454], 2].mean())
    maps = maps_from_mesh(head, shape, axis_x_mm=0.0, axis_z_mm=axis_z)
    maps.landmarks_mm = al.to_head(landmarks_mm)
    return head, maps, al


def _check_head(maps: CylindricalMaps, lm_head: np.ndarray) -> None:
    """A head seen from its axis: the rays towards the face must meet the surface."""
    tc = maps.to_cylindrical(lm_head[INNER_IBUG])
    row, col = maps.to_cells(tc[:, 0], tc[:, 1])
    h, w = maps.shape
    r0, r1 = int(max(row.min(), 0)), int(min(row.max(), h - 1)) + 1
    c0, c1 = int(col.min()), int(col.max()) + 1
    if r1 <= r0 or c1 <= c0:
        raise MyofaceValueError("the landmarks fall outside the scan's maps")
    region = maps.holes[r0:r1, np.arange(c0, c1) % w]
    if region.mean() > 0.5:
        raise MyofaceValueError(
            f"this mesh is not a head around its vertical axis: {region.mean():.0%} of the rays "
            "towards the face (between the landmarks) meet no surface"
        )


# --------------------------------------------------------------------------- found landmarks

#: resolution (H, W) of the colour map the landmark detector looks at: about 0.6 mm per cell on
#: a head, so that the face spans a few hundred pixels
DETECTION_SHAPE = (512, 1024)


def find_landmarks(scan: FaceMesh) -> np.ndarray:
    """The (68, 3) iBUG-68 landmarks of a textured head mesh, found automatically.

    Jaw-line points (0-16) that fall where the scan has no surface are NaN; the others are
    always finite.

    The scan's colour map, seen from its vertical axis, looks like a photograph of the face;
    MediaPipe's face mesh (the ``mediapipe`` extra) finds the default topology's 468 points in
    it, their angles and heights plus the range map give them in 3-D, and the iBUG points are
    their means (:func:`ibug_points_of`).
    """
    if scan.texture is None or scan.uv is None:
        raise MyofaceValueError(
            "cannot find facial features on an untextured mesh: give its texture, or give "
            "landmarks (68 iBUG points)"
        )
    return find_landmarks_in_maps(maps_from_mesh(scan, DETECTION_SHAPE))


def find_landmarks_in_maps(maps: CylindricalMaps) -> np.ndarray:
    """(68, 3) iBUG-68 landmarks found in cylindrical maps (see :func:`find_landmarks`)."""
    k = max(1, int(np.ceil(DETECTION_SHAPE[0] / maps.shape[0])))
    img = np.repeat(np.repeat(maps.rgb, k, 0), k, 1)
    with FaceMeshDetector(video=False) as det:
        pts = det.detect(img)
    if pts is None:
        raise MyofaceValueError(
            "no face found in the scan's colour map (is it a textured head, upright, +y up?); "
            "give landmarks (68 iBUG points) instead"
        )
    pts = pts / k
    theta, y = maps.from_cells(pts[:, 1] - 0.5, pts[:, 0] - 0.5)
    r = maps.filled().sample_radius(theta, y)
    p3 = maps.to_cartesian(theta, y, r)
    lm = ibug_points_of(p3)  # jaw points found over holes (under the chin) stay NaN
    if not np.isfinite(lm[INNER_IBUG]).all():
        raise MyofaceValueError("the face found in the scan's colour map lies over holes in it")
    return lm


# --------------------------------------------------------------------------- photographs

#: share of the generic face's depth mixed into the depth MediaPipe infers from one photo
PHOTO_DEPTH_BLEND = 0.5
#: the most faces looked for in one photo (:func:`photo_faces`)
MAX_PHOTO_FACES = MAX_FACES
#: a photo's longest side (pixels) as it is used: a larger one is scaled down to it, for the
#: detection (MediaPipe's face mesh looks at the face through a 192 x 192 crop, whatever the
#: photo's size) and for the texture (a face across a third of such a photo keeps 1300 px of
#: texture, more than a render of it shows). Measured on a 12000 x 6750 photo: the whole
#: command took 4.4 GB of memory before (the photo in float64, a 12000-px texture), 0.35 GB
#: from a JPEG (decoded at a reduced scale) and 1.0 GB from a PNG (decoded whole) now
PHOTO_MAX_SIDE = 4096
#: MediaPipe's face mesh leaves its inner lip contours apart on closed lips (1.0-1.2 mm at the
#: generic face's size along the whole mouth of the sample video's closed, resting lips), which
#: a face made from the photo renders as parted lips with the mouth's dark inside between them.
#: A mean gap below this (mm) is taken for closed lips and closed (:func:`close_lips`); a
#: mouth open in the photo (the teeth or the mouth's inside showing) is left as it is.
CLOSED_LIPS_MM = 2.0


def close_lips(vertices: np.ndarray, uv: np.ndarray, landmarks: dict, max_gap_mm: float):
    """Close the mouth of a face in the default topology whose inner lip contours are less
    than ``max_gap_mm`` apart on average (mm; vertices (V, 3) head frame, y up): each upper
    inner-lip vertex and the lower one facing it (``lip_upper_inner`` / ``lip_lower_inner``,
    corners shared) are moved to their midpoint, and their texture coordinates ``uv`` (V, 2)
    too (the photo's lip line between them is left out). Returns (vertices, uv, mean gap mm,
    closed?); new arrays, the inputs unchanged."""
    v = np.array(vertices, dtype=np.float64)
    t = np.array(uv, dtype=np.float64)
    up = np.asarray(landmarks.get("lip_upper_inner", ()), dtype=np.int64)
    lo = np.asarray(landmarks.get("lip_lower_inner", ()), dtype=np.int64)
    pairs = [(a, b) for a, b in zip(up, lo, strict=False) if a != b]
    if not pairs or len(up) != len(lo):
        return v, t, float("nan"), False
    a, b = np.array(pairs).T
    gap = float((v[a, 1] - v[b, 1]).mean())
    if not gap < max_gap_mm:
        return v, t, gap, False
    mid, mid_uv = 0.5 * (v[a] + v[b]), 0.5 * (t[a] + t[b])
    v[a], v[b], t[a], t[b] = mid, mid, mid_uv, mid_uv
    return v, t, gap, True


def photo_faces(image: np.ndarray, max_faces: int = MAX_PHOTO_FACES) -> list[np.ndarray]:
    """The faces MediaPipe's face mesh finds in the RGB photo ``image``: (468, 3) points
    each (x, y in pixels), numbered left to right (by their points' mean x); at most
    ``max_faces``."""
    with FaceMeshDetector(video=False, max_faces=max_faces) as det:
        faces = det.detect_all(image)
    return sorted(faces, key=lambda p: float(p[:, 0].mean()))


def choose_face(faces: list[np.ndarray], face_index: int | None = None) -> int:
    """Which of ``faces`` (numbered left to right, :func:`photo_faces`) a face is made of:
    ``face_index``, or when it is None the largest (the widest span of points); a
    :class:`MyofaceWarning` says which when there are several and none was asked for."""
    n = len(faces)
    if n == 0:
        raise MyofaceValueError("no face found in the photo")
    if face_index is not None:
        if not (isinstance(face_index, int | np.integer) and 0 <= face_index < n):
            what = "one face (0)" if n == 1 else f"{n} faces (0 to {n - 1}, left to right)"
            raise MyofaceValueError(f"the photo has {what}; no face {face_index}")
        return int(face_index)
    k = int(np.argmax([float(np.ptp(p[:, 0])) for p in faces]))
    if n > 1:
        warnings.warn(
            f"{n} faces in the photo; made of face {k}, the largest (numbered from 0, left to "
            "right; --face-index N, or face_index=N, chooses one)",
            MyofaceWarning,
            stacklevel=3,
        )
    return k


def face_from_photo(
    image: np.ndarray,
    *,
    generic: FaceMesh | None = None,
    name: str = "person",
    depth_blend: float = PHOTO_DEPTH_BLEND,
    face_index: int | None = None,
) -> tuple[FaceMesh, dict]:
    """A personal face from one frontal photograph (RGB uint8 (H, W, 3)).

    MediaPipe's face mesh (the ``mediapipe`` extra) gives the 468 points of the default
    topology; a similarity takes them onto the generic face (one photo has no absolute scale, so
    the face gets the generic face's size), the depth is blended with the generic face's
    (``depth_blend`` of it; monocular depth is the weakest coordinate), and the photo becomes the
    texture, each vertex's texture coordinate being where it was found in it. Lips that
    MediaPipe leaves a little apart (less than :data:`CLOSED_LIPS_MM`) are closed
    (:func:`close_lips`; ``info["lips_closed"]``).

    A photo of several faces (up to :data:`MAX_PHOTO_FACES` are found): faces are numbered
    from 0, left to right, and ``face_index`` chooses one; by default the largest, with a
    warning (:func:`choose_face`). A photo larger than :data:`PHOTO_MAX_SIDE` pixels a side
    is scaled down to it first (the texture needs no more; memory stays modest).
    ``info`` says ``n_faces`` and ``face_index``.
    """
    img = np.asarray(image)
    if img.ndim != 3 or img.shape[2] not in (3, 4) or img.dtype != np.uint8:
        raise MyofaceValueError(f"a photo must be an (H, W, 3) uint8 image; got {img.shape}")
    if img.shape[0] < 1 or img.shape[1] < 1:
        raise MyofaceValueError(f"a photo must have pixels; got shape {img.shape}")
    img = _bounded(np.ascontiguousarray(img[:, :, :3]), PHOTO_MAX_SIDE)
    if not 0 <= depth_blend <= 1:
        raise MyofaceValueError(f"depth_blend must be in [0, 1]; got {depth_blend}")
    generic = load_default_face() if generic is None else generic
    faces = photo_faces(img)
    chosen = choose_face(faces, face_index)
    pts = faces[chosen]
    h, w = img.shape[:2]
    found = np.column_stack([pts[:, 0], -pts[:, 1], -pts[:, 2]])  # right-handed, +z to camera
    s, r, t = fit_similarity_3d(generic.vertices, found)
    head = (found - t) @ r / s
    head[:, 2] = (1 - depth_blend) * head[:, 2] + depth_blend * generic.vertices[:, 2]
    res = float(np.sqrt(((head - generic.vertices) ** 2).sum(1).mean()))
    uv = np.column_stack([pts[:, 0] / w, 1 - pts[:, 1] / h])
    head, uv, gap, closed = close_lips(head, uv, generic.landmarks, CLOSED_LIPS_MM)
    face = FaceMesh(head, generic.triangles, uv, img, generic.landmarks, name=name)
    yaw = float(np.degrees(np.arctan2(r[0, 2], r[2, 2])))
    info = {
        "face_width_px": float(np.ptp(pts[:, 0])),
        "pixels_per_mm": float(s),
        "head_yaw_deg": yaw,
        "fit_rms_to_generic_mm": res,
        "depth_blend": depth_blend,
        "lip_gap_mm": gap,
        "lips_closed": closed,
        "n_faces": len(faces),
        "face_index": chosen,
    }
    return face, info


def _bounded(img: np.ndarray, max_side: int) -> np.ndarray:
    """``img`` (H, W, 3) uint8, scaled down (Lanczos, aspect kept) when a side is longer
    than ``max_side`` pixels."""
    h, w = img.shape[:2]
    if max(h, w) <= max_side:
        return img
    from PIL import Image

    k = max_side / max(h, w)
    size = (max(1, round(w * k)), max(1, round(h * k)))
    return np.asarray(Image.fromarray(img).resize(size, Image.Resampling.LANCZOS))
