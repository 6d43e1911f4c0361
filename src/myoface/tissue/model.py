"""The layered tissue lattice as data: parameters, the packed arrays of a model, its state.

A :class:`TissueModel` is read-only and knows no solver (as warp.sim's Model knows no
integrator): the builder (:mod:`myoface.tissue.assemble`) stands above it, the force kernels and
the integrators (:mod:`~myoface.tissue.rk2`, :mod:`~myoface.tissue.solver`,
:func:`~myoface.tissue.relax`) take it. What they derive from a model alone (the Hessian's
pattern, the Newton solver's factor, the RK2 kernel's plans, the stable time step) is kept in the
model's :meth:`TissueModel.memo`, its one owner.

Structure (Terzopoulos & Waters 1993, Section III-A/D, Fig. 3): every skin vertex is copied three
times along its inward normal, giving four node layers —

====  ==========================  =====================================
 k    node layer                  depth below the skin (defaults, mm)
====  ==========================  =====================================
 0    epidermis (the skin mesh)   0
 1    dermis / fat interface      ``dermis_mm`` = 2
 2    fascia (muscles attach)     ``dermis_mm + fat_mm`` = 6
 3    bone (fixed)                ``dermis_mm + fat_mm + muscle_mm`` = 9
====  ==========================  =====================================

Each skin triangle spans three stacked triangular-prism (pentahedral) elements: dermis (0-1),
subcutaneous fat (1-2) and muscle (2-3). Springs: the triangle edges of layers 0-2, the vertical
edges, and both diagonals of every quadrilateral side face (against shear). Nodes are numbered
``layer * n_vertices + vertex``, so the skin nodes are ``0 .. n_vertices-1`` in mesh order.

The paper gives no numeric values for masses, stiffnesses or damping; the defaults below are
ours, chosen from soft-tissue orders of magnitude (skin ~ 0.1-1 MPa; fat an order softer; collagen
stiffening ~10x past ~15 % strain) and for an over-damped, stable lattice, as the paper asks.
Units: mm, g, s; stiffness in g/s^2 (= uN/mm; 1 N/m = 1000 g/s^2).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Hashable
from dataclasses import dataclass, field, fields, replace

import numpy as np

from myoface.errors import MyofaceValueError
from myoface.tissue.forces import LAW_CONTINUOUS

#: names of the three element layers and the epidermis (the rows of the material table)
LAYERS = ("epidermis", "dermis", "fat", "muscle")
NODE_LAYERS = ("epidermis", "dermis_bottom", "fascia", "bone")
#: RK2 safety factor on the stability limit (see :func:`stable_time_step`)
STABLE_DT_SAFETY = 0.5


@dataclass(frozen=True)
class LayerMaterial:
    """Biphasic spring material of one layer (eq. 2).

    Attributes
    ----------
    alpha : float
        Stiffness at small strain, g/s^2.
    beta : float
        Stiffness past the threshold, g/s^2 (``alpha < beta``).
    strain_c : float
        Threshold strain: ``e^c_k = strain_c * l_k``.
    volume : float
        Volume-preservation weight (dimensionless): element j gets
        ``kv_j = volume * alpha / A_j^2`` (A_j: its mean cross-section area, mm^2), so that
        compressing it by d mm costs about as much energy as a spring of stiffness ``2 volume alpha``.
    """

    alpha: float
    beta: float
    strain_c: float
    volume: float = 1.0

    def __post_init__(self):
        if not (
            self.alpha > 0 and self.beta >= self.alpha and self.strain_c >= 0 and self.volume >= 0
        ):
            raise MyofaceValueError(
                f"layer material needs 0 < alpha <= beta, strain_c >= 0, volume >= 0; got {self}"
            )


@dataclass(frozen=True)
class TissueParams:
    """Parameters of the tissue lattice (all defaults are ours; the paper gives none)."""

    dermis_mm: float = 2.0
    fat_mm: float = 4.0
    muscle_mm: float = 3.0
    epidermis: LayerMaterial = LayerMaterial(2000.0, 20000.0, 0.15, 0.0)
    dermis: LayerMaterial = LayerMaterial(1500.0, 15000.0, 0.15, 1.0)
    fat: LayerMaterial = LayerMaterial(300.0, 3000.0, 0.30, 2.0)
    muscle: LayerMaterial = LayerMaterial(1000.0, 10000.0, 0.20, 1.0)
    #: tissue density, g/mm^3 (water); node masses are lumped from element volumes
    density: float = 1.0e-3
    #: damping ratio of the lattice's slowest mode (> 1: over-damped, as the paper asks, "slightly");
    #: damping is mass-proportional, gamma_i = 2 zeta omega_min m_i, so faster modes ring down at
    #: the same rate zeta omega_min instead of crawling like a uniformly over-damped lattice
    damping_ratio: float = 1.1
    #: how the two phases of eq. (2) join: "continuous" (the stiffness switches, the force is
    #: continuous; needed by the implicit solver) or "paper" (eq. 2 literally; RK2 only)
    biphasic: str = "continuous"
    #: normal smoothing passes before offsetting the layers (avoids crossings at sharp creases)
    normal_smoothing: int = 2

    def materials(self) -> np.ndarray:
        """(4, 3) table [alpha, beta, strain_c] in :data:`LAYERS` order."""
        return np.array(
            [
                [m.alpha, m.beta, m.strain_c]
                for m in (self.epidermis, self.dermis, self.fat, self.muscle)
            ],
            dtype=np.float64,
        )

    @property
    def depths_mm(self) -> np.ndarray:
        """Depth of node layers 0..3 below the skin, mm."""
        return np.cumsum([0.0, self.dermis_mm, self.fat_mm, self.muscle_mm])


class Memo:
    """Results derived from one model alone, each computed once: ``memo(key, compute)``.

    ``compute()`` runs at most once per key, even when several threads ask at the same time (the
    first builds it under a lock of that key, the others wait and then share it; keys do not wait
    for each other); afterwards a plain lookup. A ``compute`` that raises stores nothing. What it
    returns is shared: callers must not change it."""

    def __init__(self):
        self._values: dict = {}
        self._locks: dict = {}
        self._lock = threading.Lock()

    def __call__(self, key: Hashable, compute: Callable[[], object]):
        try:
            return self._values[key]
        except KeyError:
            pass
        with self._lock:
            lock = self._locks.setdefault(key, threading.Lock())
        with lock:
            if key not in self._values:
                self._values[key] = compute()
            return self._values[key]


def _read_only(a):
    """A read-only view of ``a`` (the caller's array keeps its own flags)."""
    if not isinstance(a, np.ndarray):
        return a
    v = a.view()
    v.flags.writeable = False
    return v


@dataclass(frozen=True, eq=False)
class TissueModel:
    """Packed, read-only arrays of an assembled lattice (build with
    :func:`~myoface.tissue.assemble.assemble_tissue` or
    :func:`~myoface.tissue.assemble.make_lattice`).

    Frozen, its arrays read-only views: a model never changes, so it may be shared between
    threads, and what is derived from it alone is kept in :meth:`memo`. A changed copy
    (``dataclasses.replace``, :meth:`with_kinematic`) is a new model with an empty memo.

    Attributes
    ----------
    rest_positions : (N, 3) float64, mm
    n_vertices : int — skin vertices; node ``k * n_vertices + v`` is vertex v in layer k.
    skin_triangles : (F, 3) int64 — the skin mesh (nodes of layer 0).
    node_layer : (N,) int8 — 0 epidermis, 1 dermis bottom, 2 fascia, 3 bone.
    spring_i, spring_j : (S,) int64 — spring end nodes.
    rest_length : (S,) float64, mm — natural lengths l_k.
    spring_material : (S,) int64 — row of ``materials`` (:data:`LAYERS` order).
    materials : (4, 3) float64 — [alpha, beta, strain_c].
    elements : (E, 6) int64 — prisms [a0, b0, c0, a1, b1, c1] (top triangle, then the deeper one).
    element_layer : (E,) int8 — 1 dermis, 2 fat, 3 muscle.
    rest_volume : (E,) float64, mm^3; volume_weight : (E,) float64 — kv_j.
    volume_sign : float — +1 or -1 so that ``volume_sign * signed volume`` is positive at rest.
    mass : (N,) float64, g; damping : (N,) float64, g/s.
    kinematic : (N,) bool — nodes whose positions are prescribed (bone, plus driven fascia nodes).
    """

    rest_positions: np.ndarray
    n_vertices: int
    skin_triangles: np.ndarray
    node_layer: np.ndarray
    spring_i: np.ndarray
    spring_j: np.ndarray
    rest_length: np.ndarray
    spring_material: np.ndarray
    materials: np.ndarray
    elements: np.ndarray
    element_layer: np.ndarray
    rest_volume: np.ndarray
    volume_weight: np.ndarray
    volume_sign: float
    mass: np.ndarray
    damping: np.ndarray
    kinematic: np.ndarray
    spring_law: int = LAW_CONTINUOUS
    params: TissueParams = field(default_factory=TissueParams)

    def __post_init__(self):
        for f in fields(self):
            object.__setattr__(self, f.name, _read_only(getattr(self, f.name)))
        object.__setattr__(self, "_memo", Memo())

    def memo(self, key: Hashable, compute: Callable[[], object]):
        """A result derived from this model alone, computed once (see :class:`Memo`): the
        one place where the solvers and the integrators keep what they build per model (and,
        through :meth:`myoface.model.FaceModel.memo`, the levels above)."""
        return self._memo(key, compute)

    @property
    def n_nodes(self) -> int:
        return len(self.rest_positions)

    @property
    def n_springs(self) -> int:
        return len(self.spring_i)

    @property
    def n_elements(self) -> int:
        return len(self.elements)

    @property
    def kinematic_index(self) -> np.ndarray:
        """Indices of the kinematic nodes, in the order :func:`~myoface.tissue.relax` expects
        their targets."""
        return self.memo("kinematic_index", lambda: _read_only(np.flatnonzero(self.kinematic)))

    @property
    def free_index(self) -> np.ndarray:
        return self.memo("free_index", lambda: _read_only(np.flatnonzero(~self.kinematic)))

    @property
    def stable_dt(self) -> float:
        """The paper RK2's default time step, s: inside the explicit scheme's stability limit
        (:func:`stable_time_step`), computed once per model."""
        return self.memo("stable_dt", lambda: stable_time_step(self))

    def layer_nodes(self, layer: int | str) -> np.ndarray:
        """Node indices of node layer ``layer`` (0-3 or a name in :data:`NODE_LAYERS`), in vertex order."""
        k = NODE_LAYERS.index(layer) if isinstance(layer, str) else int(layer)
        return np.arange(k * self.n_vertices, (k + 1) * self.n_vertices)

    def with_kinematic(self, nodes: np.ndarray) -> TissueModel:
        """A copy in which ``nodes`` (indices) are kinematic too, e.g. muscle-driven fascia nodes."""
        kin = self.kinematic.copy()
        kin[np.asarray(nodes, dtype=np.int64)] = True
        return replace(self, kinematic=kin)

    def summary(self) -> str:
        counts = {name: int(np.sum(self.spring_material == k)) for k, name in enumerate(LAYERS)}
        per = ", ".join(f"{k} {v}" for k, v in counts.items())
        return (
            f"{self.n_nodes} nodes ({int(self.kinematic.sum())} kinematic), "
            f"{self.n_elements} elements, {self.n_springs} springs ({per})"
        )


@dataclass
class TissueState:
    """Positions ``x`` (N, 3) mm and velocities ``v`` (N, 3) mm/s of every node, at time ``t`` s.

    ``previous_x`` (N, 3) mm, optional: the positions the state was relaxed from (set by
    :func:`~myoface.tissue.relax`); the Newton solver repeats that move in the next relax's
    initial guess (:func:`myoface.tissue.solver.extrapolated_start`)."""

    x: np.ndarray
    v: np.ndarray
    t: float = 0.0
    previous_x: np.ndarray | None = None

    def copy(self) -> TissueState:
        return TissueState(self.x.copy(), self.v.copy(), self.t, self.previous_x)


def rest_state(model: TissueModel) -> TissueState:
    """The assembled rest configuration with zero velocity."""
    return TissueState(model.rest_positions.copy(), np.zeros_like(model.rest_positions), 0.0)


def targets_array(model: TissueModel, targets) -> np.ndarray:
    """``targets`` checked: (K, 3) float64 positions (mm) of the kinematic nodes in
    ``model.kinematic_index`` order; None gives their rest positions."""
    k = model.kinematic_index
    if targets is None:
        return model.rest_positions[k]
    t = np.asarray(targets, dtype=np.float64)
    if t.shape != (len(k), 3):
        raise MyofaceValueError(
            f"targets must have shape ({len(k)}, 3) (one per kinematic node); got {t.shape}"
        )
    if not np.isfinite(t).all():
        raise MyofaceValueError("targets must be finite")
    return t


def stable_time_step(model: TissueModel, safety: float = STABLE_DT_SAFETY) -> float:
    """A time step (s) inside the explicit scheme's stability limit, from each free node's
    stiffest local oscillator (beta springs) and its damping (see the comments for the two
    limits: the oscillator's, and the slow growth of lightly damped modes under RK2).

    Computed afresh on every call; ``model.stable_dt`` holds the default one, computed once per
    model."""
    stiff = np.zeros(model.n_nodes)
    kb = model.materials[model.spring_material, 1]
    np.add.at(stiff, model.spring_i, kb)
    np.add.at(stiff, model.spring_j, kb)
    free = ~model.kinematic
    w = np.sqrt(stiff[free] / model.mass[free])
    g = model.damping[free] / model.mass[free]
    # for x'' + g x' + w^2 x = 0, midpoint RK2 is stable for dt below about 2 / (g/2 + w) ...
    dt_osc = safety * np.min(2.0 / (0.5 * g + w))
    # ... but its amplification factor on an undamped mode is sqrt(1 + (w dt)^4 / 4) > 1: the
    # lightly damped high modes grow by about (w dt)^4 / 8 per step unless the damping takes away
    # more (g dt / 2). Keep that growth to half the damping's decay: (w dt)^4 / 8 < g dt / 4.
    dt_weak = np.min(np.cbrt(2.0 * g / w**4)) if np.all(g > 0) else np.inf
    return float(min(dt_osc, dt_weak))
