"""The ``.myoface`` face-model file: one person's mesh, texture, muscles, landmarks, provenance.

A ``.myoface`` file is a zip archive (open it with any zip tool) holding:

``face.json``
    ``{"format": "myoface face", "version": 1, "name": ..., "units": "mm",
    "frame": "+y up, +z out of the face, subject's left at +x", "landmarks": {group: [vertex,
    ...]}, "provenance": {...}}``. ``provenance`` says how the face was made (command, source
    files with their sha256, the fit's residuals, ...).
``mesh.obj``
    The neutral skin: vertices (mm, head frame), texture coordinates (one per vertex), triangles.
``texture.png``
    Optional skin texture (RGB, 8 bit), addressed by the mesh's texture coordinates.
``muscles.toml``
    Optional muscle file (:mod:`myoface.muscles.io`) placed on this mesh by vertex numbers; a
    face in the default 468-vertex topology without one gets the default muscles.
"""

from __future__ import annotations

import io
import json
import os
import tempfile
import zipfile
import zlib
from pathlib import Path

import numpy as np

from myoface._io import atomic_output
from myoface.errors import MyofaceFileNotFoundError, MyofaceFormatError, user_message, writing
from myoface.face.image import read_image
from myoface.face.io import load_mesh, save_mesh
from myoface.face.mesh import FaceMesh

SUFFIX = ".myoface"
FORMAT = "myoface face"
VERSION = 1
FRAME = "+y up, +z out of the face, subject's left at +x"


def save_face(
    path: str | os.PathLike,
    face: FaceMesh,
    *,
    muscles_toml: str | None = None,
    provenance: dict | None = None,
) -> Path:
    """Write ``face`` (with its texture and landmarks) and a muscle file as a ``.myoface`` file.

    Written to a temporary name and renamed, so a failure leaves no partial file.
    """
    import imageio.v3 as iio

    path = Path(path)
    meta = {
        "format": FORMAT,
        "version": VERSION,
        "name": face.name,
        "units": "mm",
        "frame": FRAME,
        "landmarks": {k: v.tolist() for k, v in face.landmarks.items()},
        "provenance": provenance or {},
    }
    with writing(path), atomic_output(path) as tmp:  # a full disk names the face file
        with zipfile.ZipFile(tmp, "w", compression=zipfile.ZIP_DEFLATED) as z:
            z.writestr("face.json", json.dumps(meta, indent=1, default=_jsonable) + "\n")
            obj = tmp.with_name(tmp.stem + ".mesh.obj")
            try:
                save_mesh(face, obj)
                z.write(obj, "mesh.obj")
            finally:
                obj.unlink(missing_ok=True)
            if face.texture is not None:
                buf = io.BytesIO()
                iio.imwrite(buf, face.texture, extension=".png")
                z.writestr("texture.png", buf.getvalue())
            if muscles_toml is not None:
                z.writestr("muscles.toml", muscles_toml)
    return path


def _jsonable(x):
    if isinstance(x, np.ndarray):
        return x.tolist()
    if isinstance(x, np.generic):
        return x.item()
    raise TypeError(f"cannot store {type(x).__name__} in face.json")


def read_face(path: str | os.PathLike) -> tuple[FaceMesh, str | None, dict]:
    """Read a ``.myoface`` file: (face with texture and landmarks, muscle file text or None, meta)."""
    path = Path(path)
    if not path.is_file():
        raise MyofaceFileNotFoundError(f"no such face file: {path}")
    try:
        with zipfile.ZipFile(path) as z:
            names = set(z.namelist())
            for need in ("face.json", "mesh.obj"):
                if need not in names:
                    raise MyofaceFormatError(f"{path}: not a myoface face file (no {need})")
            meta = json.loads(z.read("face.json"))
            if not isinstance(meta, dict) or meta.get("format") != FORMAT:
                raise MyofaceFormatError(f"{path}: face.json is not a {FORMAT!r} document")
            version = meta.get("version", 0)
            if isinstance(version, bool) or not isinstance(version, int | float):
                raise MyofaceFormatError(f"{path}: face.json: version must be a number")
            if version > VERSION:
                raise MyofaceFormatError(
                    f"{path}: format version {version} is newer than this myoface "
                    f"reads ({VERSION}); upgrade myoface"
                )
            with tempfile.TemporaryDirectory() as d:
                obj = Path(d) / "mesh.obj"
                obj.write_bytes(z.read("mesh.obj"))
                try:
                    mesh = load_mesh(obj)
                except MyofaceFormatError as exc:
                    raise MyofaceFormatError(f"{path}: mesh.obj: {exc}") from None
            texture = None
            if "texture.png" in names:
                texture = read_image(
                    z.read("texture.png"), "texture image", name=f"{path}: texture.png"
                )
            muscles = z.read("muscles.toml").decode() if "muscles.toml" in names else None
            groups = meta.get("landmarks", {})
            if not isinstance(groups, dict):
                raise MyofaceFormatError(f"{path}: face.json: landmarks must be an object")
            landmarks = {str(k): np.asarray(v, dtype=np.int64) for k, v in groups.items()}
    except zipfile.BadZipFile:
        raise MyofaceFormatError(f"{path}: not a myoface face file (not a zip archive)") from None
    except (
        ValueError,
        KeyError,
        TypeError,
        OverflowError,
        RecursionError,
        EOFError,
        OSError,
        NotImplementedError,
        RuntimeError,
        zlib.error,
    ) as exc:  # json's, numpy's and zipfile's errors on damaged content
        if isinstance(exc, MyofaceFormatError):
            raise
        raise MyofaceFormatError(f"{path}: damaged face file: {user_message(exc, 200)}") from None
    face = FaceMesh(
        mesh.vertices,
        mesh.triangles,
        mesh.uv,
        texture,
        landmarks,
        name=str(meta.get("name", path.stem))[:200],
    )
    return face, muscles, meta
