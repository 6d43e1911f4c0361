"""Reading and writing face meshes: the bundled default face, OBJ/PLY (through trimesh), and
Keith Waters' classic geoface files."""

from __future__ import annotations

import json
import os
from importlib import resources
from pathlib import Path

import numpy as np

from myoface._io import atomic_output, read_text
from myoface.errors import (
    MyofaceFileNotFoundError,
    MyofaceFormatError,
    MyofaceValueError,
    user_message,
    writing,
)
from myoface.face.mesh import FaceMesh, check_vertices_mm, triangle_normals

#: Waters' geoface coordinates are taken to be centimetres (the face is then 163 mm tall).
WATERS_UNIT_MM = 10.0


def _data_path(name: str) -> Path:
    return Path(str(resources.files("myoface") / "data" / name))


def load_default_face() -> FaceMesh:
    """The bundled neutral generic face: the MediaPipe canonical face mesh, in millimetres.

    468 vertices, 852 triangles (the tessellation's 898 less the 46 that closed the eyes and the
    mouth), cylindrical texture coordinates, and named landmark groups (MediaPipe indices).
    Apache-2.0; see ``myoface/data/NOTICE.md`` and ``tools/build_default_face.py``.
    """
    face = load_mesh(_data_path("default_face.obj"))
    groups = json.loads(_data_path("default_face_landmarks.json").read_text())["groups"]
    return FaceMesh(
        face.vertices,
        face.triangles,
        face.uv,
        None,
        {k: np.asarray(v) for k, v in groups.items()},
        name="default",
    )


_MIRROR_MAP: np.ndarray | None = None


def default_mirror_map() -> np.ndarray:
    """(468,) for each vertex of the default topology, its left/right mirror partner.

    Found on the bundled default face, which is exactly symmetric in x (midline vertices are
    their own partners).
    """
    global _MIRROR_MAP
    if _MIRROR_MAP is None:
        from scipy.spatial import cKDTree

        v = load_default_face().vertices
        d, idx = cKDTree(v).query(v * np.array([-1.0, 1.0, 1.0]))
        if d.max() > 1e-3 or len(set(idx.tolist())) != len(v):
            raise RuntimeError("the default face is not symmetric; cannot pair its vertices")
        _MIRROR_MAP = idx.astype(np.int64)
    return _MIRROR_MAP.copy()


def is_default_topology(face: FaceMesh) -> bool:
    """Whether ``face`` has the default face's vertices and triangles by number (MediaPipe's)."""
    return face.n_vertices == 468 and np.array_equal(face.triangles, load_default_face().triangles)


def _check_file(path) -> Path:
    path = Path(path)
    if not path.exists():
        raise MyofaceFileNotFoundError(f"no such file: {path}")
    if path.is_dir():
        raise MyofaceValueError(f"expected a file, got a folder: {path}")
    return path


def _read_obj(path: Path, split_uv_seams: bool = False, scale_mm: float = 1.0) -> FaceMesh:
    """A small OBJ reader keeping vertex order and per-vertex uv (``f v/vt``) as written;
    positions multiplied by ``scale_mm``, and checked (:func:`check_vertices_mm`).

    A vertex with several texture coordinates (on a seam of the texture atlas) keeps the last
    one, unless ``split_uv_seams``: then every distinct (vertex, uv) pair becomes a vertex of its
    own (same position), so that the texture maps without cracks; the mesh then has boundaries
    along the seams.
    """
    verts, uvs, faces, face_uv = [], [], [], []
    try:
        text = path.read_text(errors="strict")
    except UnicodeDecodeError as exc:
        raise MyofaceFormatError(f"{path} is not a text OBJ file") from exc
    for ln, line in enumerate(text.splitlines(), 1):
        parts = line.split()
        if not parts or parts[0].startswith("#"):
            continue
        try:
            if parts[0] == "v":
                verts.append([float(x) for x in parts[1:4]])
                if len(verts[-1]) != 3:
                    raise ValueError("a vertex needs x, y and z")
            elif parts[0] == "vt":
                uvs.append([float(x) for x in parts[1:3]])
                if len(uvs[-1]) != 2:
                    raise ValueError("a texture coordinate needs u and v")
            elif parts[0] == "f":
                idx = [p.split("/") for p in parts[1:]]
                vi = [int(p[0]) for p in idx]
                ti = [int(p[1]) if len(p) > 1 and p[1] else 0 for p in idx]
                for k in range(1, len(vi) - 1):  # fan-triangulate polygons
                    faces.append([vi[0], vi[k], vi[k + 1]])
                    face_uv.append([ti[0], ti[k], ti[k + 1]])
        except (ValueError, IndexError) as exc:
            raise MyofaceFormatError(f"{path}:{ln}: cannot parse {line.strip()!r}") from exc
    if not verts or not faces:
        raise MyofaceFormatError(f"{path} has no vertices or no faces")
    v = _checked(np.asarray(verts, float), path, scale_mm)
    f = np.asarray(faces, np.int64)
    f = np.where(f < 0, f + len(v) + 1, f) - 1  # OBJ is 1-based; negatives count from the end
    if f.min() < 0 or f.max() >= len(v):
        raise MyofaceFormatError(
            f"{path}: a face refers to a vertex outside 1..{len(v)} (the file has {len(v)})"
        )
    uv = None
    fu = np.asarray(face_uv, np.int64)
    if uvs and fu.max() > len(uvs):
        raise MyofaceFormatError(
            f"{path}: a face refers to a texture coordinate outside 1..{len(uvs)} (the file "
            f"has {len(uvs)})"
        )
    if uvs and (fu > 0).all() and split_uv_seams:
        pairs, inv = np.unique(np.stack([f.ravel(), fu.ravel()], 1), axis=0, return_inverse=True)
        uva = np.asarray(uvs, float)
        return FaceMesh(v[pairs[:, 0]], inv.reshape(-1, 3), uva[pairs[:, 1] - 1], name=path.stem)
    if uvs and (fu > 0).all():
        uva = np.asarray(uvs, float)
        uv = np.zeros((len(v), 2))
        uv[f.reshape(-1)] = uva[fu.reshape(-1) - 1]
    return FaceMesh(v, f, uv, name=path.stem)


def load_mesh(
    path: str | os.PathLike, *, scale_mm: float = 1.0, split_uv_seams: bool = False
) -> FaceMesh:
    """Read a triangle mesh (OBJ, PLY, STL, OFF, GLB, ... through trimesh) as a FaceMesh.

    OBJ files are read directly (vertex order and per-vertex uv kept exactly, or split at the
    texture's seams with ``split_uv_seams``, see :func:`_read_obj`). Positions are multiplied by
    ``scale_mm`` (use 10 for a mesh in centimetres, 1000 for metres).
    """
    path = _check_file(path)
    if path.suffix.lower() == ".obj":
        return _read_obj(path, split_uv_seams, scale_mm)
    import trimesh

    try:
        m = trimesh.load(str(path), force="mesh", process=False)
    except Exception as exc:  # trimesh raises many types for unreadable input
        raise MyofaceFormatError(f"cannot read {path} as a mesh: {user_message(exc)}") from exc
    if not isinstance(m, trimesh.Trimesh) or len(m.faces) == 0:
        raise MyofaceFormatError(f"{path} holds no triangle mesh")
    uv = getattr(m.visual, "uv", None)
    v = _checked(np.asarray(m.vertices, dtype=np.float64), path, scale_mm)
    return FaceMesh(v, np.asarray(m.faces), uv, name=path.stem)


def _checked(vertices: np.ndarray, path: Path, scale_mm: float) -> np.ndarray:
    """The vertices of the file ``path`` in mm (times ``scale_mm``), checked."""
    with np.errstate(over="ignore", invalid="ignore"):
        v = vertices * scale_mm if scale_mm != 1.0 else vertices
    if v.ndim != 2 or v.shape[1:] != (3,):
        raise MyofaceFormatError(f"{path}: vertices must have 3 coordinates each")
    source = str(path) if scale_mm == 1.0 else f"{path} (at {scale_mm:g} mm per unit)"
    return check_vertices_mm(v, source)


def save_mesh(face: FaceMesh, path: str | os.PathLike) -> None:
    """Write ``face`` as OBJ (with uv if present) or, by suffix, any format trimesh writes."""
    path = Path(path)
    with writing(path), atomic_output(path) as tmp:  # a full disk names the mesh file
        if path.suffix.lower() == ".obj":
            lines = [f"# {face.name}, millimetres"]
            lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in face.vertices]
            if face.uv is not None:
                lines += [f"vt {a:.6f} {b:.6f}" for a, b in face.uv]
                lines += [
                    f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}"
                    for a, b, c in face.triangles
                ]
            else:
                lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in face.triangles]
            tmp.write_text("\n".join(lines) + "\n")
        else:
            import trimesh

            trimesh.Trimesh(face.vertices, face.triangles, process=False).export(str(tmp))


def read_waters_geoface(folder: str | os.PathLike) -> FaceMesh:
    """Read Keith Waters' geoface mesh (``faceline.dat`` + ``index.dat``) as a full face.

    ``faceline.dat``: a count, then one half face (x <= 0) of vertices. ``index.dat``: a count,
    then rows of four 1-based indices (a quad), or ``1000 p2 p3 p4`` (a triangle). The half is
    mirrored in x (midline vertices, x = 0, are shared), quads are split into two triangles, and
    the winding is made outward. Coordinates are scaled by :data:`WATERS_UNIT_MM`.

    References: Parke & Waters, *Computer Facial Animation*, Appendix (geoface).
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise MyofaceFileNotFoundError(f"no such geoface folder: {folder}")
    fl, ix = _check_file(folder / "faceline.dat"), _check_file(folder / "index.dat")

    try:
        vt = read_text(fl, "Waters faceline.dat").split()
        nv = int(vt[0])
        half = np.asarray(vt[1 : 1 + 3 * nv], float).reshape(nv, 3)
        it = read_text(ix, "Waters index.dat").split()
        npoly = int(it[0])
        rows = np.asarray(it[1 : 1 + 4 * npoly], np.int64).reshape(npoly, 4)
    except (ValueError, IndexError) as exc:
        raise MyofaceFormatError(
            f"cannot parse geoface files in {folder}: {user_message(exc)}"
        ) from None
    tris = []
    for r in rows:
        if r[0] == 1000:
            tris.append([r[1], r[2], r[3]])
        else:
            tris += [[r[0], r[1], r[2]], [r[0], r[2], r[3]]]
    with np.errstate(over="ignore"):
        half = check_vertices_mm(half * WATERS_UNIT_MM, str(fl)) / WATERS_UNIT_MM
    tris = np.asarray(tris, np.int64) - 1
    if len(tris) == 0 or tris.min() < 0 or tris.max() >= nv:
        raise MyofaceFormatError(f"{ix} refers to vertices outside 1..{nv}")
    on_mid = np.abs(half[:, 0]) < 1e-9
    mirror_idx = np.arange(nv)
    n_extra = int((~on_mid).sum())
    mirror_idx[~on_mid] = nv + np.arange(n_extra)
    mirrored = half[~on_mid] * np.array([-1.0, 1.0, 1.0])
    verts = np.concatenate([half, mirrored]) * WATERS_UNIT_MM
    tris_m = mirror_idx[tris][:, ::-1]  # mirroring flips the winding
    allt = np.concatenate([tris, tris_m])
    # drop degenerate triangles (repeated indices in the source data)
    ok = (allt[:, 0] != allt[:, 1]) & (allt[:, 1] != allt[:, 2]) & (allt[:, 0] != allt[:, 2])
    allt = allt[ok]
    n = triangle_normals(verts, allt)
    if n[:, 2].mean() < 0:
        allt = allt[:, ::-1]
    return FaceMesh(verts, allt, name="waters-geoface")
