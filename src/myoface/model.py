"""The assembled face model (immutable) and its state (a value), in the style of warp.sim.

:class:`FaceModel` joins the geometry, physics and muscle levels. It is built once, never
changes, and may be shared between threads: the face, the muscles, the tissue lattice, the packed
arrays that map a contraction vector c (M,) (one entry per id of the muscle set, the jaw last) to
target positions of the kinematic nodes — the bone layer, rotated by the jaw, and the fascia nodes
the muscles reach, displaced by eq. (5) (Terzopoulos & Waters 1993) — and results derived from
the model alone (e.g. the analysis' responses to each muscle, :meth:`FaceModel.memo`, kept
with the tissue's own in the lattice's memo, :meth:`myoface.tissue.TissueModel.memo`).

:class:`FaceState` (node positions, velocities, contractions, time) is a value: :func:`relax`,
:func:`step` and :func:`simulate` take one and return a new one. Whoever needs a state (the
viewer, an analysis run, a video writer) keeps its own.

Example
-------
>>> from myoface.model import build_face_model, relax
>>> fm = build_face_model()
>>> res = relax(fm, {"zygomaticus_major_l": 0.8, "zygomaticus_major_r": 0.8})
>>> skin = fm.skin_vertices(res.state)          # (468, 3) mm
>>> res2 = fm.relax({"zygomaticus_major_l": 0.9}, res.state)   # warm start from the smile
"""

from __future__ import annotations

import os
from collections.abc import Callable, Hashable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from myoface.errors import MyofaceFileNotFoundError, MyofaceFormatError, MyofaceValueError
from myoface.face import (
    FaceMesh,
    default_mirror_map,
    is_default_topology,
    load_default_face,
    load_mesh,
    read_waters_geoface,
)
from myoface.face.facefile import read_face
from myoface.face.teeth import fit_dentition, lip_contact
from myoface.muscles import (
    MuscleSet,
    load_default_muscles,
    load_muscles,
    muscles_from_dict,
    read_waters_expressions,
    read_waters_muscles,
    rotate_about_axis,
)
from myoface.muscles.io import with_later_defaults
from myoface.muscles.lids import build_eyelids
from myoface.tissue import (
    RelaxResult,
    TissueModel,
    TissueParams,
    TissueState,
    assemble_tissue,
    step_rk2,
)
from myoface.tissue import relax as relax_tissue
from myoface.tissue.assemble import bind_layer
from myoface.tissue.model import LayerMaterial

#: fascia nodes whose largest unit-contraction displacement is below this (mm) stay free
DRIVEN_MIN_MM = 1e-3


def _frozen(a) -> np.ndarray:
    a = np.array(a, dtype=np.float64)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, eq=False)
class FaceState:
    """A configuration of a face model's tissue: a value (its arrays are read-only).

    Attributes
    ----------
    x : (N, 3) float ndarray — every lattice node's position, mm (the first V are the skin).
    v : (N, 3) float ndarray — velocities, mm/s.
    contractions : (M,) float ndarray — the contractions the kinematic nodes were set to.
    t : float — time, s.
    previous_x : (N, 3) float ndarray or None — the positions a :func:`relax` started from
        (None for a state made otherwise): the next relax repeats that move in its initial
        guess, a warm start for the next frame of a video.
    """

    x: np.ndarray
    v: np.ndarray
    contractions: np.ndarray
    t: float = 0.0
    previous_x: np.ndarray | None = None

    def __post_init__(self):
        for name in ("x", "v", "contractions"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))
        if self.previous_x is not None:
            object.__setattr__(self, "previous_x", _frozen(self.previous_x))

    @classmethod
    def _from_tissue(cls, s: TissueState, contractions, previous_x=None) -> FaceState:
        return cls(s.x, s.v, contractions, float(s.t), previous_x)

    def tissue_state(self) -> TissueState:
        """A (mutable) copy for the tissue level's functions."""
        return TissueState(self.x.copy(), self.v.copy(), self.t, self.previous_x)


class FaceModel:
    """A face mesh + tissue lattice + muscle set. Immutable: safe to share between threads.

    Attributes
    ----------
    face : FaceMesh — the rest skin surface.
    muscles : MuscleSet
    tissue : TissueModel — with the bone layer and the muscle-driven fascia nodes kinematic.
    ids : tuple of str — contraction vector order (``muscles.ids``).
    driven_nodes : (D,) int — fascia nodes moved by at least one muscle.
    expressions : dict of name -> (M,) — expressions that came with the model (Waters' macros).
    stable_dt : float — the RK2 step (s) inside the explicit scheme's stability limit,
        computed once per model (``tissue.stable_dt``).
    """

    def __init__(
        self,
        face: FaceMesh,
        muscles: MuscleSet,
        params: TissueParams | None = None,
        expressions: dict[str, np.ndarray] | None = None,
    ):
        s = super().__setattr__
        s("face", face)
        s("muscles", muscles)
        s("ids", muscles.ids)
        base = assemble_tissue(face.vertices, face.triangles, params)
        if muscles.bound_skin is not None:  # skin bound to its muscle (MuscleSet.bound_skin)
            base = bind_layer(
                base, muscles.bound_skin.vertices, "fat", LayerMaterial(*muscles.bound_skin.fat)
            )
        nv = base.n_vertices
        fascia = base.layer_nodes("fascia")
        jaw_w = muscles.jaw.weights if muscles.jaw is not None else np.zeros(nv)
        if len(jaw_w) != nv:
            raise MyofaceValueError(
                f"the muscle set's jaw has {len(jaw_w)} weights but the face {nv} vertices"
            )
        fb = muscles.basis(base.rest_positions[fascia], jaw_w)
        # muscles that move the mandible (the lateral pterygoids) drive no fascia of their own
        on_bone = muscles.mandible_index
        fb[:, :, on_bone] = 0.0
        reach = np.abs(fb).max(axis=(1, 2))
        driven_v = np.flatnonzero(reach > DRIVEN_MIN_MM)
        driven = fascia[driven_v]
        s("driven_nodes", driven)
        tissue: TissueModel = base.with_kinematic(driven)
        s("tissue", tissue)
        kin = tissue.kinematic_index
        # per kinematic node: its vertex, rest position, jaw weight and muscle basis
        s("_kin_vertex", kin % nv)
        s("_kin_rest", _frozen(tissue.rest_positions[kin]))
        s("_kin_jaw", _frozen(jaw_w[kin % nv]))
        basis = np.zeros((len(kin), 3, len(self.ids)))
        basis[np.searchsorted(kin, driven)] = fb[driven_v]
        # ... and, as the jaw's opening, on the fascia nodes the other muscles hold
        for i in on_bone:
            basis[:, :, i] = muscles.muscles[i].field(tissue.rest_positions[kin], jaw_w[kin % nv])
        s("_kin_basis", _frozen(basis))
        s("expressions", dict(expressions or {}))
        s(
            "_rest",
            FaceState(
                tissue.rest_positions, np.zeros_like(tissue.rest_positions), np.zeros(len(self.ids))
            ),
        )
        #: the eyelids moved by the lid muscles (None without lid muscles or eye openings)
        s("eyelids", build_eyelids(face, muscles))
        #: the teeth behind the lips (None for a face without the lip landmark groups)
        s("dentition", fit_dentition(face))

    def __setattr__(self, name, value):
        raise AttributeError(f"FaceModel is immutable: cannot set {name!r}")

    # ------------------------------------------------------------------ inputs
    @property
    def n_muscles(self) -> int:
        return len(self.ids)

    def validate(self, contractions) -> np.ndarray:
        """See :meth:`MuscleSet.validate`."""
        return self.muscles.validate(contractions)

    def targets(self, contractions) -> np.ndarray:
        """Positions (K, 3) mm of the kinematic nodes for ``contractions``.

        The jaw rotates each kinematic node by its vertex's jaw weight times the opening angle
        and slides it by that weight times the condylar slide; the muscles then add
        ``sum_i c_i B_i`` (T&W 1993, eq. (5)), rotated with the jaw.
        """
        c = self.validate(contractions)
        x = self._kin_rest + self._kin_basis @ c
        j = self.muscles.jaw_index
        if j is not None and c[j] > 0:
            x = self.muscles.jaw.rotate(x, self._kin_jaw, c[j])
        return x

    @property
    def stable_dt(self) -> float:
        return self.tissue.stable_dt

    def rest_state(self) -> FaceState:
        """The rest configuration: no contraction, zero velocity, t = 0."""
        return self._rest

    def memo(self, key: Hashable, compute: Callable[[], object]):
        """A result derived from this model alone (never from a state), computed once.

        ``compute()`` runs at most once per key, even when several threads ask at the same
        time; its result must not be changed by the caller. Kept in the memo of the model's
        lattice (this model's own, :meth:`myoface.tissue.TissueModel.memo`), beside what the
        tissue's solvers keep, under keys of their own."""
        return self.tissue.memo((FaceModel, key), compute)

    # ------------------------------------------------------------------ physics
    def relax(self, contractions, state: FaceState | None = None, **kwargs) -> RelaxResult:
        """:func:`relax` on this model."""
        return relax(self, contractions, state, **kwargs)

    def step(
        self, state: FaceState | None, contractions, dt: float | None = None, n_steps: int = 1
    ) -> FaceState:
        """:func:`step` on this model."""
        return step(self, state, contractions, dt, n_steps)

    def simulate(
        self, contractions, times, state: FaceState | None = None, *, dt: float | None = None
    ) -> Simulation:
        """:func:`simulate` on this model."""
        return simulate(self, contractions, times, state, dt=dt)

    # ------------------------------------------------------------------ outputs
    def skin_vertices(self, state: FaceState | None = None) -> np.ndarray:
        """Positions (V, 3) mm of the skin (epidermal) nodes of ``state`` (default: rest), with
        the lips kept out of the teeth and from passing through each other
        (:func:`myoface.face.teeth.lip_contact`; no change where they do not touch)."""
        s = self._rest if state is None else state
        skin = np.array(s.x[: self.face.n_vertices])
        if self.eyelids is not None and s is not self._rest:
            # the eyelids placed over the eyeballs by the lid muscles (myoface.muscles.lids)
            skin = self.eyelids.apply(skin, s.contractions)
        if self.dentition is None or s is self._rest:
            return skin
        return lip_contact(skin, self.dentition, self.jaw_pose(s))

    def jaw_pose(self, state: FaceState | None = None):
        """The mandible's rigid motion from rest in ``state`` (default: rest): ``(rotation
        (3, 3), translation (3,) mm)``, ``x -> rotation @ x + translation``, the jaw's full
        rotation about its hinge and condylar slide (:meth:`myoface.muscles.Jaw.pose`, what the
        lower teeth follow); the identity without a jaw."""
        s = self._rest if state is None else state
        j = self.muscles.jaw_index
        if j is None:
            return np.eye(3), np.zeros(3)
        rot, shift = self.muscles.jaw.pose(float(s.contractions[j]))
        turn, moved = 0.0, np.zeros(3)
        for i in self.muscles.mandible_index:  # the pterygoids' turn, before the opening
            m, c = self.muscles.muscles[i], float(s.contractions[i])
            turn += c * m.turn_rad
            moved -= c * np.cross([0.0, m.turn_rad, 0.0], m.pivot)
        if turn == 0.0:
            return rot, shift
        # the bone layer follows the turns' linear sum (exact to second order in the angle,
        # 0.5 mm at the chin at a full excursion); the teeth its rotation, with the same motion
        # of the hinge axis' origin
        lat = rotate_about_axis(np.eye(3), np.zeros(3), [0.0, 1.0, 0.0], turn).T
        return rot @ lat, rot @ moved + shift

    def skin_mesh(self, state: FaceState | None = None) -> FaceMesh:
        """The skin of ``state`` (default: rest) as a FaceMesh (same topology, UVs, texture,
        landmarks)."""
        return self.face.with_vertices(self.skin_vertices(state))

    def summary(self) -> str:
        return (
            f"{self.face.name}: {self.face.n_vertices} vertices, {self.face.n_triangles} "
            f"triangles; {len(self.muscles.muscles)} muscles"
            f"{' + jaw' if self.muscles.jaw is not None else ''}; "
            f"{len(self.driven_nodes)} driven fascia nodes; lattice: {self.tissue.summary()}"
        )


@dataclass(frozen=True, eq=False)
class Simulation:
    """The outcome of :func:`simulate`: the skin at each requested time and the final state."""

    skin: np.ndarray  # (T, V, 3) mm
    state: FaceState


def relax(
    model: FaceModel,
    contractions,
    state: FaceState | None = None,
    *,
    method: str | None = None,
    tol_mm: float | None = None,
    max_iter: int | None = None,
) -> RelaxResult:
    """The tissue's equilibrium for ``contractions``, starting from ``state`` (default: rest).

    Parameters
    ----------
    model : FaceModel
    contractions : mapping {id: value} or (M,) array in [0, 1]
    state : FaceState, optional
        The initial guess (a warm start: in a video, the previous frame's state).
    method : str, optional
        See :func:`myoface.tissue.relax` (default: its fast solver; ``"rk2"`` the paper's
        explicit integration run to rest).
    tol_mm, max_iter : optional
        See :func:`myoface.tissue.relax`.

    Returns
    -------
    RelaxResult
        Its ``state`` is a new :class:`FaceState`; ``state`` is not changed.
    """
    c = model.validate(contractions)
    s0 = (model._rest if state is None else state).tissue_state()
    kw = {
        k: v
        for k, v in (("method", method), ("tol_mm", tol_mm), ("max_iter", max_iter))
        if v is not None
    }
    res = relax_tissue(model.tissue, s0, model.targets(c), **kw)
    return replace(res, state=FaceState._from_tissue(res.state, c, res.state.previous_x))


def step(
    model: FaceModel,
    state: FaceState | None,
    contractions,
    dt: float | None = None,
    n_steps: int = 1,
) -> FaceState:
    """``n_steps`` paper RK2 steps of ``dt`` s (default: the model's stable step) from ``state``
    (default: rest) with the kinematic nodes at ``contractions``; returns the new state."""
    c = model.validate(contractions)
    dt = None if dt is None else float(dt)  # None: the stable step, halved where it must be
    s0 = (model._rest if state is None else state).tissue_state()
    s = step_rk2(model.tissue, s0, model.targets(c), dt, n_steps)
    return FaceState._from_tissue(s, c)


def simulate(
    model: FaceModel,
    contractions: Callable[[float], object] | np.ndarray,
    times: np.ndarray,
    state: FaceState | None = None,
    *,
    dt: float | None = None,
) -> Simulation:
    """Integrate in time (paper RK2) from ``state`` (default: rest) at ``times[0]``.

    ``contractions`` is a function of time returning a contraction vector/mapping, or an
    array (T, M) giving the contractions at each of ``times`` (held between samples).
    Returns the skin (T, V, 3) mm at each of ``times`` and the final state.
    """
    times = np.asarray(times, dtype=np.float64)
    if (
        times.ndim != 1
        or len(times) == 0
        or not np.isfinite(times).all()
        or np.any(np.diff(times) < 0)
    ):
        raise MyofaceValueError("times must be a non-empty, finite, non-decreasing 1-D array (s)")
    if callable(contractions):
        get = contractions
    else:
        table = np.asarray(contractions, dtype=np.float64)
        if table.shape != (len(times), model.n_muscles):
            raise MyofaceValueError(
                f"contractions must have shape ({len(times)}, {model.n_muscles}); got {table.shape}"
            )

        def get(t, _table=table):
            return _table[min(np.searchsorted(times, t, side="right") - 1, len(times) - 1)]

    dt = model.stable_dt if dt is None else float(dt)
    if not dt > 0:
        raise MyofaceValueError(f"dt must be > 0 s; got {dt}")
    s = model._rest if state is None else state
    out = np.empty((len(times), model.face.n_vertices, 3))
    t = float(times[0])
    for k, tk in enumerate(times):
        while t < tk - 1e-12:
            h = min(dt, tk - t)
            n = max(1, int(np.floor((tk - t) / h + 1e-9)))
            s = step(model, s, get(t), h, n)
            t += n * h
        out[k] = model.skin_vertices(s)
    return Simulation(out, s)


def build_face_model(
    face: FaceMesh | None = None,
    muscles: MuscleSet | None = None,
    params: TissueParams | None = None,
) -> FaceModel:
    """A face model from a face and a muscle set (default: the bundled face and muscles)."""
    face = face if face is not None else load_default_face()
    muscles = muscles if muscles is not None else load_default_muscles(face)
    return FaceModel(face, muscles, params)


def load_face_model(path: str | os.PathLike | None = None, *, muscles=None, params=None):
    """Load a face model from ``path``.

    - ``None`` or ``"default"``: the bundled default face and muscles;
    - a folder with Waters' geoface files (``faceline.dat``, ``index.dat``, ``muscle.dat``,
      optionally ``expression-macros.dat``, whose expressions land in ``model.expressions``);
    - a ``.myoface`` face file (:mod:`myoface.face.facefile`), e.g. a personal face made by
      ``myoface face from-scan`` / ``from-photo``: its mesh, texture and muscles;
    - a mesh file (OBJ/PLY/...) with a muscle file: ``muscles=`` or ``<mesh stem>.muscles.toml``
      beside it; a mesh in the default 468-vertex topology may use the default muscles.
    """
    if path is None or str(path) == "default":
        return build_face_model(params=params)
    p = Path(path)
    if not p.exists():
        raise MyofaceFileNotFoundError(f"no such face model: {p}")
    if p.is_dir():
        if not (p / "faceline.dat").is_file():
            raise MyofaceFileNotFoundError(
                f"{p} is a folder but not a Waters geoface folder (no faceline.dat)"
            )
        face = read_waters_geoface(p)
        ms = load_muscles(muscles, face) if muscles else read_waters_muscles(p)
        expr = {}
        if (p / "expression-macros.dat").is_file() and not muscles:
            expr = read_waters_expressions(p, ms)
        return FaceModel(face, ms, params, expressions=expr)
    if p.suffix.lower() == ".myoface":
        return _load_face_file(p, muscles, params)
    face = load_mesh(p)
    if face.n_vertices == 468 and not face.landmarks:
        # the default (MediaPipe) topology: give it the default face's landmark groups
        face = FaceMesh(
            face.vertices,
            face.triangles,
            face.uv,
            face.texture,
            load_default_face().landmarks,
            name=face.name,
        )
    side = p.with_name(p.stem + ".muscles.toml")
    if muscles:
        ms = load_muscles(muscles, face)
    elif side.is_file():
        ms = load_muscles(side, face)
    elif face.n_vertices == 468:
        ms = load_default_muscles(face)
    else:
        raise MyofaceFileNotFoundError(
            f"no muscle file for {p}: give one (muscles=...) or put it at {side}"
        )
    return FaceModel(face, ms, params)


def _load_face_file(path: Path, muscles, params) -> FaceModel:
    import tomllib

    face, toml_text, _ = read_face(path)
    if muscles:
        return FaceModel(face, load_muscles(muscles, face), params)
    default_topology = is_default_topology(face)
    if toml_text is None:
        if not default_topology:
            raise MyofaceFileNotFoundError(
                f"{path} holds no muscles and is not in the default topology: give muscles=..."
            )
        return FaceModel(face, load_default_muscles(face), params)
    try:
        doc = tomllib.loads(toml_text)
    except tomllib.TOMLDecodeError as exc:
        raise MyofaceFormatError(f"{path}: its muscles.toml is not valid TOML: {exc}") from None
    mirror = default_mirror_map() if default_topology else None
    if default_topology:
        # a face saved before the eyelids (or the lips' marginal part) gets the default ones
        doc = with_later_defaults(doc)
    ms = muscles_from_dict(doc, face, where=f"{path}:muscles.toml", mirror=mirror)
    return FaceModel(face, ms, params)
