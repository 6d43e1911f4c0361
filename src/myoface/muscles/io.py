"""Muscle files: the TOML muscle format (the default set is one), and Waters' ``muscle.dat``.

The TOML format
---------------
A muscle file places muscles on a particular mesh, by vertex index and depth, so the same file
serves every mesh with that topology (the default set works on any face in MediaPipe's 468-vertex
topology, e.g. a personal face made from a photo)::

    [meta]
    name = "..."

    [[muscle]]
    id = "zygomaticus_major"        # anatomical id
    sides = "lr"                    # "lr": defined on the subject's left (+x) and mirrored to
                                    #       the right as <id>_l / <id>_r;  "mid": one muscle <id>
    type = "linear"                 # linear | sheet | sphincter | waters
    origin = { vertex = 345, depth_mm = 12.0 }
    insertion = { vertex = 291, depth_mm = 6.0 }
    radius_mm = 18.0
    max_shortening_mm = 12.0
    region = "all"                  # all | upper | lower (side of the mouth slit it acts on)

A point is ``{ vertex = i }`` (a vertex of the mesh), ``{ landmark = "name" }`` (the mean of a
landmark group of the face, or of several: ``landmark = ["a", "b"]``), or ``{ xyz_mm = [x, y, z] }``; optional ``offset_mm = [dx, dy, dz]``
(head frame) and ``depth_mm`` (into the face, along the inward surface normal at the vertex).
Types and their keys:

- ``linear``: origin, insertion, radius_mm, max_shortening_mm (T&W 1993, eq. (5)-(6)).
- ``sheet``: origin (the top of the strip, in bone), insertion (centre of the insertion line),
  width_mm, below_mm, max_shortening_mm.
- ``sphincter``: center, semi_axes_mm = [a, b], falloff, max_contraction_mm, protrusion_mm,
  optional axis_u (default [1, 0, 0]) and normal (default: the mean surface normal at center).
- ``waters``: skin, bone, fall_start_mm, fall_end_mm, zone_deg, clamp.
- ``lid``: eye (the landmark group of the eye opening), action (``raise``: levator palpebrae
  superioris; ``close``: orbicularis oculi pars palpebralis), origin, insertion, optional
  angle_deg (see :mod:`myoface.muscles.lids`): moves the eyelid skin, not the tissue.
- ``pterygoid``: origin, insertion (its condyle), reference (where the travel is given, e.g.
  the chin), max_travel_mm, optional pivot (the other condyle): turns the mandible, the bone
  layer, sideways (:class:`~myoface.muscles.types.PterygoidMuscle`).

An optional ``[jaw]`` table: ``hinge`` (a point), ``axis`` (default [1, 0, 0]),
``max_angle_rad``, optionally a translation phase (see :mod:`myoface.muscles.jaw`):
``slide_mm`` (the condyles' translation at full opening, head frame, default [0, 0, 0]),
``hinge_angle_rad`` (the hinge phase's rate, default ``max_angle_rad``) and
``translation_from`` (where the translation starts, default 0), and the harmonic weight constraints ``lower`` / ``upper`` (lists of landmark
group names or vertex indices held at 1 / 0), ``lower_below`` / ``upper_above`` (points: every
vertex below / above that point's height is held at 1 / 0). Vertices listed as both are left free.

A linear muscle may take ``lower_share`` (in [0, 1], default 1): the share of its field the lower
lip and chin take (:class:`~myoface.muscles.types.LinearMuscle`). An optional ``[bound_skin]``
table: ``vertices`` (skin vertex indices) and ``fat = [alpha, beta, strain_c]``: the tissue's fat
layer under those vertices takes that stiffness (:class:`~myoface.muscles.muscleset.BoundSkin`).
"""

from __future__ import annotations

import os
import tomllib
from functools import lru_cache
from importlib import resources
from pathlib import Path

import numpy as np

from myoface._io import parse_toml, read_text
from myoface.errors import MyofaceFileNotFoundError, MyofaceFormatError, MyofaceValueError
from myoface.face import default_mirror_map, load_default_face
from myoface.face.io import WATERS_UNIT_MM
from myoface.face.mesh import FaceMesh
from myoface.muscles.jaw import Jaw, harmonic_weights
from myoface.muscles.lids import LidMuscle
from myoface.muscles.muscleset import BoundSkin, MuscleSet
from myoface.muscles.types import (
    LinearMuscle,
    PterygoidMuscle,
    SheetMuscle,
    SphincterMuscle,
    WatersMuscle,
)

DEFAULT_MUSCLES_FILE = "default_muscles.toml"
TYPES = ("linear", "sheet", "sphincter", "waters", "lid", "pterygoid")
SIDES = ("lr", "mid")
_COMMON_KEYS = {"id", "sides", "type", "region", "note"}
_KEYS = {
    "linear": {"origin", "insertion", "radius_mm", "max_shortening_mm", "lower_share"},
    "sheet": {"origin", "insertion", "width_mm", "below_mm", "max_shortening_mm"},
    "sphincter": {
        "center",
        "semi_axes_mm",
        "falloff",
        "max_contraction_mm",
        "protrusion_mm",
        "axis_u",
        "normal",
    },
    "waters": {"skin", "bone", "fall_start_mm", "fall_end_mm", "zone_deg", "clamp"},
    "lid": {"eye", "action", "origin", "insertion", "angle_deg"},
    "pterygoid": {"origin", "insertion", "reference", "max_travel_mm", "pivot"},
}
_OPTIONAL = {
    "linear": {"lower_share"},
    "sphincter": {"axis_u", "normal", "protrusion_mm"},
    "lid": {"angle_deg"},
    "pterygoid": {"pivot"},
}


class _Placer:
    """Resolves point specs of a muscle file on one face."""

    def __init__(self, face: FaceMesh, where: str):
        self.face = face
        self.where = where
        self.normals = face.vertex_normals

    def _vertices(self, spec: dict, ctx: str) -> np.ndarray:
        if "vertex" in spec:
            i = spec["vertex"]
            if not _is_index(i) or not 0 <= i < self.face.n_vertices:
                raise MyofaceFormatError(
                    f"{self.where}: {ctx}: vertex must be an index in 0..{self.face.n_vertices - 1}"
                    f"; got {i!r}"
                )
            return np.array([i])
        if "landmark" in spec:
            names = spec["landmark"]
            names = [names] if isinstance(names, str) else names
            if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
                raise MyofaceFormatError(
                    f"{self.where}: {ctx}: landmark must be a name or a list of names; got "
                    f"{spec['landmark']!r}"
                )
            try:
                return np.concatenate([np.asarray(self.face.landmark(n)) for n in names])
            except (KeyError, MyofaceValueError) as exc:
                raise MyofaceFormatError(f"{self.where}: {ctx}: {exc}") from None
        raise MyofaceFormatError(f"{self.where}: {ctx}: a point needs vertex, landmark or xyz_mm")

    def point(self, spec, ctx: str) -> np.ndarray:
        if not isinstance(spec, dict):
            raise MyofaceFormatError(f"{self.where}: {ctx} must be a table; got {spec!r}")
        unknown = set(spec) - {"vertex", "landmark", "xyz_mm", "offset_mm", "depth_mm"}
        if unknown:
            raise MyofaceFormatError(f"{self.where}: {ctx}: unknown keys {sorted(unknown)}")
        if "xyz_mm" in spec:
            p = _floats(spec["xyz_mm"], 3, f"{self.where}: {ctx}.xyz_mm")
            normal = None
        else:
            idx = self._vertices(spec, ctx)
            p = self.face.vertices[idx].mean(axis=0)
            n = self.normals[idx].sum(axis=0)
            normal = n / np.linalg.norm(n)
        if "offset_mm" in spec:
            p = p + _floats(spec["offset_mm"], 3, f"{self.where}: {ctx}.offset_mm")
        depth = _number(spec, "depth_mm", f"{self.where}: {ctx}", 0.0)
        if depth:
            if normal is None:
                raise MyofaceFormatError(f"{self.where}: {ctx}: depth_mm needs a vertex/landmark")
            p = p - depth * normal
        return p

    def normal_at(self, spec) -> np.ndarray:
        if isinstance(spec, dict) and ("vertex" in spec or "landmark" in spec):
            n = self.normals[self._vertices(spec, "normal")].sum(axis=0)
            return n / np.linalg.norm(n)
        return np.array([0.0, 0.0, 1.0])

    def vertex_set(self, items, ctx: str) -> np.ndarray:
        if not isinstance(items, list):
            raise MyofaceFormatError(
                f"{self.where}: {ctx} must be a list of vertex indices and landmark names; "
                f"got {items!r}"
            )
        out = []
        for it in items:
            if _is_index(it):
                out.append(self._vertices({"vertex": it}, ctx))
            else:
                out.append(self._vertices({"landmark": it}, ctx))
        return np.concatenate(out) if out else np.zeros(0, np.int64)


def _floats(v, n: int, ctx: str) -> np.ndarray:
    try:
        a = np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        a = np.zeros(0)
    if a.shape != (n,) or not np.isfinite(a).all():
        raise MyofaceFormatError(f"{ctx} must be {n} finite numbers; got {v!r}")
    return a


_REQUIRED = object()


def _number(entry: dict, key: str, ctx: str, default=_REQUIRED) -> float:
    """``entry[key]`` as a float (a format error unless it is a number); ``default`` when
    the key is absent and one is given."""
    if default is not _REQUIRED and key not in entry:
        return default
    v = entry.get(key)
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise MyofaceFormatError(f"{ctx}: {key} must be a number; got {v!r}")
    return float(v)


def _is_index(v) -> bool:
    """An integer (TOML's booleans are not indices)."""
    return isinstance(v, int) and not isinstance(v, bool)


def _build(entry: dict, placer: _Placer, ctx: str):
    kind = entry.get("type")
    if kind not in TYPES:
        raise MyofaceFormatError(f"{ctx}: type must be one of {TYPES}; got {kind!r}")
    keys = set(entry) - _COMMON_KEYS
    unknown = keys - _KEYS[kind]
    if unknown:
        raise MyofaceFormatError(f"{ctx}: unknown keys for a {kind} muscle: {sorted(unknown)}")
    missing = _KEYS[kind] - keys - _OPTIONAL.get(kind, set())
    if missing:
        raise MyofaceFormatError(f"{ctx}: missing keys for a {kind} muscle: {sorted(missing)}")
    region = entry.get("region", "all")
    mid = entry["id"]
    if kind == "linear":
        return LinearMuscle(
            mid,
            placer.point(entry["origin"], f"{ctx}.origin"),
            placer.point(entry["insertion"], f"{ctx}.insertion"),
            _number(entry, "radius_mm", ctx),
            _number(entry, "max_shortening_mm", ctx),
            region,
            _number(entry, "lower_share", ctx, 1.0),
        )
    if kind == "sheet":
        return SheetMuscle(
            mid,
            placer.point(entry["origin"], f"{ctx}.origin"),
            placer.point(entry["insertion"], f"{ctx}.insertion"),
            _number(entry, "width_mm", ctx),
            _number(entry, "below_mm", ctx),
            _number(entry, "max_shortening_mm", ctx),
            placer.normal_at(entry["insertion"]),
            region,
        )
    if kind == "sphincter":
        normal = (
            _floats(entry["normal"], 3, f"{ctx}.normal")
            if "normal" in entry
            else placer.normal_at(entry["center"])
        )
        axis_u = _floats(entry.get("axis_u", [1.0, 0.0, 0.0]), 3, f"{ctx}.axis_u")
        return SphincterMuscle(
            mid,
            placer.point(entry["center"], f"{ctx}.center"),
            normal,
            axis_u,
            tuple(_floats(entry["semi_axes_mm"], 2, f"{ctx}.semi_axes_mm")),
            _number(entry, "falloff", ctx),
            _number(entry, "max_contraction_mm", ctx),
            _number(entry, "protrusion_mm", ctx, 0.0),
            region,
        )
    if kind == "lid":
        eye = entry["eye"]
        if not isinstance(eye, str) or eye not in placer.face.landmarks:
            raise MyofaceFormatError(
                f"{ctx}: eye must name a landmark group of the face; got {eye!r}"
            )
        return LidMuscle(
            mid,
            eye,
            entry["action"],
            placer.point(entry["origin"], f"{ctx}.origin"),
            placer.point(entry["insertion"], f"{ctx}.insertion"),
            _number(entry, "angle_deg", ctx, 0.0),
        )
    if kind == "pterygoid":
        return PterygoidMuscle(
            mid,
            placer.point(entry["origin"], f"{ctx}.origin"),
            placer.point(entry["insertion"], f"{ctx}.insertion"),
            placer.point(entry["reference"], f"{ctx}.reference"),
            _number(entry, "max_travel_mm", ctx),
            placer.point(entry["pivot"], f"{ctx}.pivot") if "pivot" in entry else None,
        )
    return WatersMuscle(
        mid,
        placer.point(entry["skin"], f"{ctx}.skin"),
        placer.point(entry["bone"], f"{ctx}.bone"),
        _number(entry, "fall_start_mm", ctx),
        _number(entry, "fall_end_mm", ctx),
        _number(entry, "zone_deg", ctx),
        _number(entry, "clamp", ctx),
        region,
    )


def _build_jaw(spec: dict, placer: _Placer, where: str) -> Jaw:
    allowed = {
        "hinge",
        "axis",
        "max_angle_rad",
        "slide_mm",
        "hinge_angle_rad",
        "translation_from",
        "lower",
        "upper",
        "lower_below",
        "upper_above",
    }
    if not isinstance(spec, dict):
        raise MyofaceFormatError(f"{where}: [jaw] must be a table; got {spec!r}")
    unknown = set(spec) - allowed - {"note"}
    if unknown:
        raise MyofaceFormatError(f"{where}: [jaw]: unknown keys {sorted(unknown)}")
    if "hinge" not in spec or "max_angle_rad" not in spec:
        raise MyofaceFormatError(f"{where}: [jaw] needs hinge and max_angle_rad")
    face = placer.face
    y = face.vertices[:, 1]
    ones = placer.vertex_set(spec.get("lower", []), "[jaw].lower")
    zeros = placer.vertex_set(spec.get("upper", []), "[jaw].upper")
    if "lower_below" in spec:
        ones = np.r_[ones, np.flatnonzero(y < placer.point(spec["lower_below"], "lower_below")[1])]
    if "upper_above" in spec:
        zeros = np.r_[
            zeros, np.flatnonzero(y > placer.point(spec["upper_above"], "upper_above")[1])
        ]
    both = np.intersect1d(ones, zeros)
    ones, zeros = np.setdiff1d(ones, both), np.setdiff1d(zeros, both)
    if len(ones) == 0:
        raise MyofaceFormatError(f"{where}: [jaw]: no vertex is held at 1 (lower / lower_below)")
    if len(zeros) == 0:
        raise MyofaceFormatError(
            f"{where}: [jaw]: no vertex is held at 0 (upper / upper_above): the whole face "
            "would follow the jaw"
        )
    w = harmonic_weights(face.n_vertices, face.triangles, ones, zeros)
    return Jaw(
        placer.point(spec["hinge"], "[jaw].hinge"),
        _floats(spec.get("axis", [1.0, 0.0, 0.0]), 3, f"{where}: [jaw].axis"),
        _number(spec, "max_angle_rad", f"{where}: [jaw]"),
        w,
        _floats(spec.get("slide_mm", [0.0, 0.0, 0.0]), 3, f"{where}: [jaw].slide_mm"),
        _number(spec, "hinge_angle_rad", f"{where}: [jaw]", None),
        _number(spec, "translation_from", f"{where}: [jaw]", 0.0),
    )


def muscles_from_dict(
    doc: dict, face: FaceMesh, where: str = "muscle file", mirror: np.ndarray | None = None
) -> MuscleSet:
    """Build a :class:`MuscleSet` on ``face`` from a parsed muscle file (see module doc).

    Muscles with ``sides = "lr"`` are written for the subject's left. Without ``mirror`` the right
    one is the left one reflected in x (right for a symmetric face); with ``mirror`` (a vertex
    permutation pairing left and right vertices, :func:`myoface.face.default_mirror_map`) it is
    placed on the face's own right-side vertices, so an asymmetric (personal) face gets muscles
    that follow each side of it.
    """
    placer = _Placer(face, where)
    right_placer = _Placer(face.mirrored(mirror), where) if mirror is not None else None
    entries = doc.get("muscle", [])
    if not isinstance(entries, list) or not entries:
        raise MyofaceFormatError(f"{where}: no [[muscle]] entries")
    muscles = []
    for k, entry in enumerate(entries):
        ctx = f"{where}: muscle #{k + 1}"
        if not isinstance(entry, dict) or not isinstance(entry.get("id"), str):
            raise MyofaceFormatError(f"{ctx}: needs a string id")
        ctx = f"{where}: muscle {entry['id']!r}"
        sides = entry.get("sides", "mid")
        if sides not in SIDES:
            raise MyofaceFormatError(f"{ctx}: sides must be one of {SIDES}; got {sides!r}")
        try:
            if sides == "mid":
                muscles.append(_build(entry, placer, ctx))
            else:
                left = _build({**entry, "id": entry["id"] + "_l"}, placer, ctx)
                if right_placer is not None:
                    twin = _build({**entry, "id": entry["id"] + "_l"}, right_placer, ctx)
                else:
                    twin = left
                muscles += [left, twin.mirrored(entry["id"] + "_r")]
        except MyofaceValueError as exc:
            if isinstance(exc, MyofaceFormatError):
                raise
            raise MyofaceFormatError(f"{ctx}: {exc}") from None
    jaw = _build_jaw(doc["jaw"], placer, where) if "jaw" in doc else None
    meta = doc.get("meta", {})
    if not isinstance(meta, dict):
        raise MyofaceFormatError(f"{where}: [meta] must be a table; got {meta!r}")
    name = str(meta.get("name", where))
    bound = _build_bound_skin(doc["bound_skin"], face, where) if "bound_skin" in doc else None
    return MuscleSet(muscles, jaw, name=name, bound_skin=bound)


def _build_bound_skin(spec, face: FaceMesh, where: str) -> BoundSkin:
    ctx = f"{where}: [bound_skin]"
    if not isinstance(spec, dict) or set(spec) - {"vertices", "fat", "note"}:
        raise MyofaceFormatError(f"{ctx}: needs vertices and fat (and an optional note)")
    v = spec.get("vertices")
    if not isinstance(v, list) or not v or not all(_is_index(i) for i in v):
        raise MyofaceFormatError(f"{ctx}: vertices must be a list of vertex indices")
    if max(v) >= face.n_vertices or min(v) < 0:
        raise MyofaceFormatError(f"{ctx}: vertex index outside [0, {face.n_vertices - 1}]")
    try:
        return BoundSkin(
            v, tuple(_floats(spec.get("fat"), 3, f"{ctx}.fat")), str(spec.get("note", ""))
        )
    except MyofaceValueError as exc:
        raise MyofaceFormatError(f"{ctx}: {exc}") from None


def load_muscles(path: str | os.PathLike, face: FaceMesh) -> MuscleSet:
    """Read a TOML muscle file (see module doc) and place its muscles on ``face``."""
    path = Path(path)
    if not path.is_file():
        raise MyofaceFileNotFoundError(f"no such muscle file: {path}")

    doc = parse_toml(read_text(path, "muscle file (TOML)"), str(path))
    return muscles_from_dict(doc, face, where=str(path))


@lru_cache(maxsize=1)
def _default_doc() -> dict:
    text = (resources.files("myoface") / "data" / DEFAULT_MUSCLES_FILE).read_text()
    return tomllib.loads(text)


def with_default_lids(doc: dict) -> dict:
    """``doc`` (a parsed muscle file for the default topology) with the default set's lid
    muscles added when it has none: a personal face saved before the eyelids existed still
    blinks and takes AU5/AU7/AU43/AU45. ``doc`` itself is not changed."""
    entries = doc.get("muscle", [])
    if not isinstance(entries, list) or any(
        isinstance(e, dict) and e.get("type") == "lid" for e in entries
    ):
        return doc
    ids = {e.get("id") for e in entries if isinstance(e, dict)}
    lids = [e for e in _default_doc()["muscle"] if e.get("type") == "lid" and e["id"] not in ids]
    return {**doc, "muscle": [*entries, *lids]}


#: default muscles added after personal faces were first saved, and not recognisable by their
#: type as the lids are: a face file without them gets the default set's (AU24 needs the first,
#: AU4 the depressor supercilii, AU6 the orbicularis oculi's upper part, AD30 the lateral pterygoids)
LATER_DEFAULT_MUSCLES = (
    "orbicularis_oris_marginalis",
    "depressor_supercilii",
    "orbicularis_oculi_superior",
    "lateral_pterygoid",
)


def with_later_defaults(doc: dict) -> dict:
    """``doc`` (a parsed muscle file for the default topology) with what the default set gained
    since such files were written: the lids (:func:`with_default_lids`) and the muscles of
    :data:`LATER_DEFAULT_MUSCLES` it lacks. ``doc`` itself is not changed."""
    doc = with_default_lids(doc)
    entries = doc.get("muscle", [])
    if not isinstance(entries, list):
        return doc
    ids = {e.get("id") for e in entries if isinstance(e, dict)}
    extra = [
        e
        for e in _default_doc()["muscle"]
        if e["id"] in LATER_DEFAULT_MUSCLES and e["id"] not in ids
    ]
    return {**doc, "muscle": [*entries, *extra]} if extra else doc


def load_default_muscles(face: FaceMesh | None = None) -> MuscleSet:
    """The default muscle set (``data/default_muscles.toml``) placed on ``face``.

    ``face`` must have the default face's topology (468 vertices, MediaPipe indexing); default:
    the bundled default face.
    """
    if face is None:
        face = load_default_face()
    if face.n_vertices != 468:
        raise MyofaceValueError(
            "the default muscle set needs a face in the default (MediaPipe, 468-vertex) topology; "
            f"got {face.n_vertices} vertices. Give a muscle file for this mesh instead."
        )

    return muscles_from_dict(
        _default_doc(), face, where=DEFAULT_MUSCLES_FILE, mirror=default_mirror_map()
    )


# --------------------------------------------------------------------------- Waters' files


def _waters_file(path, name: str) -> Path:
    p = Path(path)
    if p.is_dir():
        p = p / name
    if not p.is_file():
        raise MyofaceFileNotFoundError(f"no such file: {p}")
    return p


def _waters_id(source: str, x: float) -> str:
    """``Left_Zygomatic_Major`` -> ``zygomatic_major_r``: the side follows the position.

    Waters' "Left" muscles lie at x < 0, which in our head frame (face looking along +z) is the
    subject's right; we name sides as the subject's, so the suffix comes from the sign of x.
    """
    base = source
    for prefix in ("Left_", "Right_"):
        if base.startswith(prefix):
            base = base[len(prefix) :]
    side = "l" if x > 0 else "r"
    return f"{base.lower()}_{side}"


def read_waters_muscles(path: str | os.PathLike) -> MuscleSet:
    """Read Waters' ``muscle.dat`` (a file or the geoface folder) as a :class:`MuscleSet`.

    Each entry: a name, the skin-end point, the bone point, then ``fall-start fall-end zone-angle
    clamp`` (Waters' units, scaled by ``WATERS_UNIT_MM``). No jaw. Ids are lower-case with the
    subject's side as suffix (see :func:`_waters_id`); ``source_name`` keeps Waters' name.
    """
    p = _waters_file(path, "muscle.dat")
    tok = read_text(p, "Waters muscle file").split()
    try:
        n = int(tok[0])
        muscles = []
        k = 1
        for _ in range(n):
            name = tok[k]
            vals = np.asarray(tok[k + 1 : k + 11], dtype=np.float64)
            if len(vals) != 10:
                raise IndexError("truncated entry")
            k += 11
            skin = vals[0:3] * WATERS_UNIT_MM
            bone = vals[3:6] * WATERS_UNIT_MM
            fs, fe, zone, clamp = vals[6:10]
            muscles.append(
                WatersMuscle(
                    _waters_id(name, skin[0]),
                    skin,
                    bone,
                    fs * WATERS_UNIT_MM,
                    fe * WATERS_UNIT_MM,
                    zone,
                    clamp,
                    source_name=name,
                )
            )
    except (ValueError, IndexError) as exc:
        raise MyofaceFormatError(f"cannot parse Waters muscle file {p}: {exc}") from None
    return MuscleSet(muscles, None, name="waters-geoface")


def read_waters_expressions(path: str | os.PathLike, muscles: MuscleSet) -> dict[str, np.ndarray]:
    """Read Waters' ``expression-macros.dat`` as contraction vectors over ``muscles``.

    Waters' values are his raw contraction values; we map each to c = min(value, clamp) / clamp
    of its muscle (his clamp is the muscle's largest value), so c is in [0, 1]. Returns
    ``{expression name (lower case): (M,) array}``.
    """
    p = _waters_file(path, "expression-macros.dat")
    by_source = {m.source_name: i for i, m in enumerate(muscles.muscles) if m.kind == "waters"}

    tok = read_text(p, "Waters expression file").split()
    out: dict[str, np.ndarray] = {}
    try:
        n = int(tok[0])
        k = 1
        for _ in range(n):
            name = tok[k].lower()
            k += 1
            c = np.zeros(len(muscles))
            while k < len(tok) and tok[k] in by_source:
                i = by_source[tok[k]]
                v = float(tok[k + 1])
                if not np.isfinite(v) or v < 0:
                    raise ValueError(f"bad value {tok[k + 1]!r} for {tok[k]}")
                c[i] = min(v, muscles.muscles[i].clamp) / muscles.muscles[i].clamp
                k += 2
            out[name] = c
    except (ValueError, IndexError) as exc:
        raise MyofaceFormatError(f"cannot parse Waters expression file {p}: {exc}") from None
    if k != len(tok):
        raise MyofaceFormatError(
            f"{p}: unexpected token {tok[k]!r} (a muscle not in the muscle set?)"
        )
    return out
