"""The assembled face model: a face mesh, its tissue lattice and its muscles, driven together.

:class:`FaceModel` joins the geometry, physics and muscle levels: a contraction vector c (M,)
(one entry per id of the muscle set, the jaw last) becomes target positions of the kinematic
nodes — the bone layer, rotated by the jaw, and the fascia nodes the muscles reach, displaced by
eq. (5) (Terzopoulos & Waters 1993) — and the lattice relaxes (or is integrated in time) to the
deformed skin.

Example
-------
>>> from myoface.model import build_face_model
>>> fm = build_face_model()
>>> res = fm.relax({"zygomaticus_major_l": 0.8, "zygomaticus_major_r": 0.8})
>>> skin = fm.skin_vertices()          # (468, 3) mm
"""

from __future__ import annotations

import copy
import os
from collections.abc import Callable
from pathlib import Path

import numpy as np

from myoface.errors import MyofaceFileNotFoundError, MyofaceFormatError, MyofaceValueError
from myoface.face import FaceMesh, load_default_face, load_mesh, read_waters_geoface
from myoface.muscles import (
    MuscleSet,
    load_default_muscles,
    load_muscles,
    read_waters_expressions,
    read_waters_muscles,
)
from myoface.tissue import (
    RelaxResult,
    TissueModel,
    TissueParams,
    TissueState,
    assemble_tissue,
    relax,
    rest_state,
    stable_time_step,
    step_rk2,
)

#: fascia nodes whose largest unit-contraction displacement is below this (mm) stay free
DRIVEN_MIN_MM = 1e-3


class FaceModel:
    """A face mesh + tissue lattice + muscle set, with the current tissue state.

    Attributes
    ----------
    face : FaceMesh — the rest skin surface.
    muscles : MuscleSet
    tissue : TissueModel — with the bone layer and the muscle-driven fascia nodes kinematic.
    state : TissueState — the current configuration (starts at rest).
    ids : tuple of str — contraction vector order (``muscles.ids``).
    driven_nodes : (D,) int — fascia nodes moved by at least one muscle.
    expressions : dict of name -> (M,) — expressions that came with the model (Waters' macros).
    """

    def __init__(
        self,
        face: FaceMesh,
        muscles: MuscleSet,
        params: TissueParams | None = None,
        expressions: dict[str, np.ndarray] | None = None,
    ):
        self.face = face
        self.muscles = muscles
        self.ids = muscles.ids
        base = assemble_tissue(face.vertices, face.triangles, params)
        nv = base.n_vertices
        fascia = base.layer_nodes("fascia")
        jaw_w = muscles.jaw.weights if muscles.jaw is not None else np.zeros(nv)
        if len(jaw_w) != nv:
            raise MyofaceValueError(
                f"the muscle set's jaw has {len(jaw_w)} weights but the face {nv} vertices"
            )
        fb = muscles.basis(base.rest_positions[fascia], jaw_w)
        reach = np.abs(fb).max(axis=(1, 2))
        driven_v = np.flatnonzero(reach > DRIVEN_MIN_MM)
        self.driven_nodes = fascia[driven_v]
        self.tissue: TissueModel = base.with_kinematic(self.driven_nodes)
        kin = self.tissue.kinematic_index
        # per kinematic node: its vertex, rest position, jaw weight and muscle basis
        self._kin_vertex = kin % nv
        self._kin_rest = self.tissue.rest_positions[kin]
        self._kin_jaw = jaw_w[self._kin_vertex]
        basis = np.zeros((len(kin), 3, len(self.ids)))
        pos = np.searchsorted(kin, self.driven_nodes)
        basis[pos] = fb[driven_v]
        self._kin_basis = basis
        self.expressions = dict(expressions or {})
        self.state: TissueState = rest_state(self.tissue)
        self._contractions = np.zeros(len(self.ids))
        #: results derived from this model that do not change with its state (e.g. the
        #: analysis' responses to each muscle), computed once per model
        self.cache: dict = {}

    # ------------------------------------------------------------------ inputs
    @property
    def n_muscles(self) -> int:
        return len(self.ids)

    @property
    def contractions(self) -> np.ndarray:
        """The contraction vector of the current state (M,)."""
        return self._contractions.copy()

    def validate(self, contractions) -> np.ndarray:
        """See :meth:`MuscleSet.validate`."""
        return self.muscles.validate(contractions)

    def targets(self, contractions) -> np.ndarray:
        """Positions (K, 3) mm of the kinematic nodes for ``contractions``.

        The jaw rotates each kinematic node by its vertex's jaw weight times the opening angle;
        the muscles then add ``sum_i c_i B_i`` (T&W 1993, eq. (5)), rotated with the jaw.
        """
        c = self.validate(contractions)
        disp = self._kin_basis @ c
        x = self._kin_rest + disp
        j = self.muscles.jaw_index
        if j is not None and c[j] > 0:
            x = self.muscles.jaw.rotate(x, self._kin_jaw, c[j])
        return x

    def clone(self) -> FaceModel:
        """A model at rest sharing this one's structure (face, muscles, tissue, caches) with
        its own state: cheap, for a second simulation such as a video export. Do not run the
        physics of both at the same time from two threads."""
        twin = copy.copy(self)
        twin.reset()
        return twin

    # ------------------------------------------------------------------ physics
    def reset(self) -> None:
        """Back to the rest state."""
        self.state = rest_state(self.tissue)
        self._contractions = np.zeros(len(self.ids))

    def relax(
        self,
        contractions,
        *,
        start: str = "current",
        method: str = "implicit",
        tol_mm: float | None = None,
        max_iter: int | None = None,
    ) -> RelaxResult:
        """Set ``contractions`` and bring the tissue to equilibrium; update :attr:`state`.

        Parameters
        ----------
        contractions : mapping {id: value} or (M,) array in [0, 1]
        start : {"current", "rest"} — the initial guess.
        method : {"implicit", "rk2"} — see :func:`myoface.tissue.relax`.
        """
        if start not in ("current", "rest"):
            raise MyofaceValueError(f"start must be 'current' or 'rest'; got {start!r}")
        c = self.validate(contractions)
        s0 = self.state if start == "current" else rest_state(self.tissue)
        kw = {} if tol_mm is None else {"tol_mm": tol_mm}
        res = relax(self.tissue, s0, self.targets(c), method=method, max_iter=max_iter, **kw)
        self.state = res.state
        self._contractions = c
        return res

    def step(self, contractions, dt: float | None = None, n_steps: int = 1) -> TissueState:
        """Advance :attr:`state` by ``n_steps`` RK2 steps of ``dt`` s (default: stable step)."""
        c = self.validate(contractions)
        dt = self.stable_dt() if dt is None else float(dt)
        self.state = step_rk2(self.tissue, self.state, self.targets(c), dt, n_steps)
        self._contractions = c
        return self.state

    def stable_dt(self) -> float:
        if "stable_dt" not in self.tissue.cache:
            self.tissue.cache["stable_dt"] = stable_time_step(self.tissue)
        return self.tissue.cache["stable_dt"]

    def simulate(
        self,
        contractions: Callable[[float], object] | np.ndarray,
        times: np.ndarray,
        *,
        dt: float | None = None,
    ) -> np.ndarray:
        """Integrate in time (paper RK2) and return the skin at each of ``times`` (T, V, 3) mm.

        ``contractions`` is a function of time returning a contraction vector/mapping, or an
        array (T, M) giving the contractions at each of ``times`` (held between samples).
        Starts from the current state at ``times[0]``.
        """
        times = np.asarray(times, dtype=np.float64)
        if times.ndim != 1 or len(times) == 0 or np.any(np.diff(times) < 0):
            raise MyofaceValueError("times must be a non-empty, non-decreasing 1-D array (s)")
        if callable(contractions):
            get = contractions
        else:
            table = np.asarray(contractions, dtype=np.float64)
            if table.shape != (len(times), self.n_muscles):
                raise MyofaceValueError(
                    f"contractions must have shape ({len(times)}, {self.n_muscles}); "
                    f"got {table.shape}"
                )

            def get(t, _table=table):
                return _table[min(np.searchsorted(times, t, side="right") - 1, len(times) - 1)]

        dt = self.stable_dt() if dt is None else float(dt)
        out = np.empty((len(times), self.face.n_vertices, 3))
        t = float(times[0])
        for k, tk in enumerate(times):
            while t < tk - 1e-12:
                h = min(dt, tk - t)
                n = max(1, int(np.floor((tk - t) / h + 1e-9)))
                c = self.validate(get(t))
                self.state = step_rk2(self.tissue, self.state, self.targets(c), h, n)
                self._contractions = c
                t += n * h
            out[k] = self.skin_vertices()
        return out

    # ------------------------------------------------------------------ outputs
    def skin_vertices(self, state: TissueState | None = None) -> np.ndarray:
        """Positions (V, 3) mm of the skin (epidermal) nodes of ``state`` (default current)."""
        s = self.state if state is None else state
        return s.x[: self.face.n_vertices].copy()

    def skin_mesh(self, state: TissueState | None = None) -> FaceMesh:
        """The deformed skin as a FaceMesh (same topology, UVs, texture, landmarks)."""
        return self.face.with_vertices(self.skin_vertices(state))

    def summary(self) -> str:
        return (
            f"{self.face.name}: {self.face.n_vertices} vertices, {self.face.n_triangles} "
            f"triangles; {len(self.muscles.muscles)} muscles"
            f"{' + jaw' if self.muscles.jaw is not None else ''}; "
            f"{len(self.driven_nodes)} driven fascia nodes; lattice: {self.tissue.summary()}"
        )


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

    from myoface.face import default_mirror_map, is_default_topology
    from myoface.face.facefile import read_face
    from myoface.muscles import muscles_from_dict

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
    ms = muscles_from_dict(doc, face, where=f"{path}:muscles.toml", mirror=mirror)
    return FaceModel(face, ms, params)
