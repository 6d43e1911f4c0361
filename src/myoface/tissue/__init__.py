"""Physics level: the layered mass-spring tissue (Terzopoulos & Waters 1993, Section III-A/B/D).

Builder (:mod:`~myoface.tissue.assemble`) -> immutable model and its state
(:mod:`~myoface.tissue.model`) -> the integrators that take them (:mod:`~myoface.tissue.rk2`,
the Newton solver :mod:`~myoface.tissue.solver`, :func:`relax` in
:mod:`~myoface.tissue.equilibrium`), in the style of warp.sim::

    model = assemble_tissue(face.vertices, face.triangles)      # TissueModel (packed arrays)
    state = rest_state(model)                                   # TissueState (x, v)
    result = relax(model, state, targets)                       # equilibrium, converged flag
    state = step_rk2(model, state, targets, n_steps=100)        # the paper's dynamics
"""

from myoface.tissue.assemble import assemble_tissue, lowest_frequency, make_lattice
from myoface.tissue.equilibrium import (
    RelaxResult,
    RelaxWarning,
    internal_forces,
    kinetic_energy,
    potential_energy,
    relax,
)
from myoface.tissue.forces import LAW_CONTINUOUS, LAW_PAPER
from myoface.tissue.hessian import stiffness_matrix
from myoface.tissue.model import (
    LAYERS,
    NODE_LAYERS,
    LayerMaterial,
    TissueModel,
    TissueParams,
    TissueState,
    rest_state,
    stable_time_step,
)
from myoface.tissue.rk2 import step_rk2

__all__ = [
    "LAW_CONTINUOUS",
    "LAW_PAPER",
    "LAYERS",
    "NODE_LAYERS",
    "LayerMaterial",
    "RelaxResult",
    "RelaxWarning",
    "TissueModel",
    "TissueParams",
    "TissueState",
    "assemble_tissue",
    "internal_forces",
    "kinetic_energy",
    "lowest_frequency",
    "make_lattice",
    "potential_energy",
    "relax",
    "rest_state",
    "stable_time_step",
    "step_rk2",
    "stiffness_matrix",
]
