"""The equilibrium of the tissue lattice (:func:`relax`), and its energies and forces.

Three solvers behind one API (:func:`relax`):

* ``"rk2"`` — the paper's explicit second-order Runge-Kutta (midpoint) scheme on
  ``m x'' + gamma x' + g + q = 0`` (eq. 3-4), two force evaluations per step, run until the
  lattice is at rest (:mod:`myoface.tissue.rk2`, which also steps it in time: ``step_rk2``);
* ``"newton"`` (default; ``"implicit"`` is an alias) — quasi-static: the equilibrium is the
  minimum of the lattice's potential energy over the free nodes, found by inexact Newton on the
  exact Hessian with CG preconditioned by a symmetric block Gauss-Seidel sweep of that Hessian,
  from the linear response to the move of the kinematic nodes (a factorisation of the rest
  stiffness kept per model) (:mod:`myoface.tissue.solver`);
* ``"lbfgs"`` — the same minimum by L-BFGS with the sparse LU of a rest stiffness matrix as its
  initial inverse Hessian and a backtracking line search: slower, kept as the reference the
  Newton solver is tested and benchmarked against.

Both quasi-static solvers land on the same equilibrium as the dynamic scheme (tests check this)
at a small fraction of its cost.

Kinematic nodes (bone, and fascia nodes driven by muscles, eq. 5) are set to their target
positions; their velocities are zero.

References: Terzopoulos & Waters 1993, eq. (3)-(4) and Section III-B.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np
from numba import njit
from scipy.sparse.linalg import splu

from myoface.errors import MyofaceSimulationError, MyofaceValueError
from myoface.tissue.forces import LAW_PAPER, _prism_volume
from myoface.tissue.forces import internal_forces_numba as _forces
from myoface.tissue.hessian import kernel_args, stiffness_matrix
from myoface.tissue.model import TissueModel, TissueState, rest_state, targets_array
from myoface.tissue.rk2 import run_rk2
from myoface.tissue.solver import NEWTON_TOL_MM, relax_newton

#: default equilibrium tolerance of "lbfgs" and "rk2": largest node move in the last solver step
#: (time step), mm. (L-BFGS steps are short and its error is several times its last step.)
RELAX_TOL_MM = 1e-4
#: the solvers :func:`relax` accepts; "implicit" is an alias of "newton"
RELAX_METHODS = ("newton", "lbfgs", "rk2", "implicit")


class RelaxWarning(UserWarning):
    """A relaxation hit its iteration limit before reaching the tolerance."""


@dataclass
class RelaxResult:
    """The outcome of :func:`relax`.

    Attributes
    ----------
    state : TissueState — the equilibrium (or the last iterate if not converged).
    converged : bool
    iterations : int — Newton iterations (newton), quasi-Newton iterations (lbfgs) or time
        steps (rk2).
    residual_mm : float — the largest node move in the last iteration (step size for rk2:
        ``max |v| dt``).
    max_force : float — largest net internal force on a free node at the end, uN.
    method : str
    """

    state: TissueState
    converged: bool
    iterations: int
    residual_mm: float
    max_force: float
    method: str


@njit(cache=True, nogil=True)
def _start(xs, kin, tg, rest, x, x_kin_start):
    """In one pass: ``x`` = ``xs`` (N, 3) with its kinematic nodes ``kin`` moved to ``tg``
    (K, 3), and where they were into ``x_kin_start`` (K, 3). Returns (whether ``xs`` is
    finite, whether its kinematic nodes are at their rest positions ``rest`` (N, 3))."""
    finite = True
    for i in range(xs.shape[0]):
        for c in range(3):
            v = xs[i, c]
            finite = finite and np.isfinite(v)
            x[i, c] = v
    at_rest = True
    for a in range(kin.shape[0]):
        i = kin[a]
        for c in range(3):
            v = xs[i, c]
            x_kin_start[a, c] = v
            at_rest = at_rest and v == rest[i, c]
            x[i, c] = tg[a, c]
    return finite, at_rest


def internal_forces(model: TissueModel, x: np.ndarray) -> np.ndarray:
    """-(g + q): the spring and volume forces on every node, (N, 3) uN (eq. 3-4)."""
    f = np.empty_like(x)
    _forces(x, *kernel_args(model), f)
    return f


def potential_energy(model: TissueModel, x: np.ndarray) -> float:
    """Elastic energy of the springs plus the volume penalty Q, nJ (= g mm^2 / s^2)."""
    return float(_energy(x, *kernel_args(model)))


def kinetic_energy(model: TissueModel, v: np.ndarray) -> float:
    return float(0.5 * np.sum(model.mass[:, None] * v * v))


@njit(cache=True)
def _energy(x, si, sj, rest, mat_id, mat, law, elems, rest_vol, kv, vsign):
    en = 0.0
    for k in range(si.shape[0]):
        i = si[k]
        j = sj[k]
        rx = x[j, 0] - x[i, 0]
        ry = x[j, 1] - x[i, 1]
        rz = x[j, 2] - x[i, 2]
        e = np.sqrt(rx * rx + ry * ry + rz * rz) - rest[k]
        m = mat_id[k]
        ec = mat[m, 2] * rest[k]
        if e <= ec:
            en += 0.5 * mat[m, 0] * e * e
        elif law == LAW_PAPER:
            en += 0.5 * mat[m, 0] * ec * ec + 0.5 * mat[m, 1] * (e * e - ec * ec)
        else:
            en += (
                0.5 * mat[m, 0] * ec * ec
                + mat[m, 0] * ec * (e - ec)
                + 0.5 * mat[m, 1] * (e - ec) ** 2
            )
    for q in range(elems.shape[0]):
        dv = _prism_volume(x, elems[q], vsign) - rest_vol[q]
        en += kv[q] * dv * dv
    return en


# ------------------------------------------------------------------------------ implicit ----


def _preconditioner(model: TissueModel):
    """Sparse LU of the rest stiffness with every spring at the geometric mean of its two phases,
    sqrt(alpha beta): kept in ``model.memo`` (built once), it serves as the initial inverse
    Hessian of L-BFGS. (SuperLU's solve only reads the factor.)"""

    def build():
        g = np.sqrt(model.materials[:, 0] * model.materials[:, 1])
        mats = np.column_stack([g, g, model.materials[:, 2]])
        a = stiffness_matrix(model, model.rest_positions, materials=mats).tocsc()
        return splu(
            a, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0, options={"SymmetricMode": True}
        )

    return model.memo("precond_lu", build)


def _relax_lbfgs(model, x, tol_mm, max_iter, memory=8):
    """L-BFGS on the potential energy over the free nodes, initial inverse Hessian = the cached
    sparse LU of the rest stiffness (quasi-Newton in the sense of Liu, Bouaziz & Kavan 2017),
    Armijo backtracking with a safeguarded quadratic step (so an overshooting trial step is cut
    to its predicted minimiser in one go, not by repeated halving). Monotone in energy; one
    factorisation per model, none per call."""
    free = model.free_index
    lu = _preconditioner(model)
    xf = x[free].reshape(-1)

    def grad(xflat):
        xx = x.copy()
        xx[free] = xflat.reshape(-1, 3)
        return xx, -internal_forces(model, xx)[free].reshape(-1)

    x, g = grad(xf)
    energy = potential_energy(model, x)
    hist_s, hist_y = [], []
    step = np.inf
    for it in range(1, max_iter + 1):
        if not np.isfinite(g).all():
            raise MyofaceSimulationError(f"lbfgs relax: non-finite forces at iteration {it}")
        q = g.copy()
        coeffs = []
        for s_, y_ in zip(reversed(hist_s), reversed(hist_y), strict=True):
            rho = 1.0 / (y_ @ s_)
            a = rho * (s_ @ q)
            q -= a * y_
            coeffs.append((a, rho, s_, y_))
        z = lu.solve(q)
        for a, rho, s_, y_ in reversed(coeffs):
            z += s_ * (a - rho * (y_ @ z))
        d = -z
        slope = float(g @ d)
        if slope >= 0:  # not a descent direction (should not happen): restart from the LU step
            hist_s.clear()
            hist_y.clear()
            d = -lu.solve(g)
            slope = float(g @ d)
        t = 1.0
        while True:
            xn = x.copy()
            xn[free] += (t * d).reshape(-1, 3)
            en = potential_energy(model, xn)
            if en <= energy + 1e-4 * t * slope or t < 1e-4:
                break
            # safeguarded minimiser of the quadratic through phi(0), phi'(0), phi(t)
            # (Nocedal & Wright 2006, eq. 3.58), kept within [0.1 t, 0.5 t]
            curv = en - energy - slope * t
            tq = -slope * t * t / (2.0 * curv) if curv > 0 else 0.5 * t
            t = min(max(tq, 0.1 * t), 0.5 * t)
        gn = -internal_forces(model, xn)[free].reshape(-1)
        sv = t * d
        yv = gn - g
        if yv @ sv > 1e-12 * (sv @ sv):
            hist_s.append(sv)
            hist_y.append(yv)
            if len(hist_s) > memory:
                hist_s.pop(0)
                hist_y.pop(0)
        x, g, energy = xn, gn, en
        step = float(np.abs(sv).max())
        if step < tol_mm:
            return x, True, it, step
    return x, False, max_iter, step


def relax(
    model: TissueModel,
    state: TissueState | None = None,
    targets=None,
    *,
    method: str = "newton",
    tol_mm: float | None = None,
    max_iter: int | None = None,
    dt: float | None = None,
) -> RelaxResult:
    """Bring the lattice to equilibrium with the kinematic nodes at ``targets``.

    Parameters
    ----------
    model : TissueModel
    state : TissueState, optional
        Where to start (default: rest). Its velocities are ignored by ``"newton"`` and
        ``"lbfgs"``. A nearby equilibrium (the previous frame's) makes a good start: the Newton
        solver adds the free nodes' linear response to the move of the kinematic nodes from
        where they are in ``state`` to ``targets``.
    targets : (K, 3) float ndarray, optional
        Positions (mm) of the kinematic nodes in ``model.kinematic_index`` order (default: rest).
    method : {"newton", "lbfgs", "rk2", "implicit"}
        ``"implicit"`` is an alias of ``"newton"``; see the module docstring.
    tol_mm : float, optional
        Converged when the largest node move (mm) of

        * ``"newton"``: the last Newton step (default :data:`~myoface.tissue.solver.NEWTON_TOL_MM`,
          0.01 mm). The Newton step estimates the distance to the equilibrium; the step is taken,
          and the error left after it is about a tenth of it or less (the CG's relative accuracy,
          plus the quadratic term), so the default leaves about 1e-3 mm;
        * ``"lbfgs"``: the last quasi-Newton step (default :data:`RELAX_TOL_MM`, 1e-4 mm);
        * ``"rk2"``: one time step, ``max |v| dt`` (default :data:`RELAX_TOL_MM`).
    max_iter : int, optional
        Newton iterations (default 50), quasi-Newton iterations (default 300) or RK2 steps
        (default 200,000).
    dt : float, optional
        RK2 time step, s (default ``model.stable_dt``, computed once per model).

    Returns
    -------
    RelaxResult
        ``converged=False`` comes with a :class:`RelaxWarning`.

    References: Terzopoulos & Waters 1993, eq. (3)-(5) and Section III.
    """
    if method not in RELAX_METHODS:
        raise MyofaceValueError(f"method must be one of {RELAX_METHODS}; got {method!r}")
    method = "newton" if method == "implicit" else method
    if tol_mm is None:
        tol_mm = NEWTON_TOL_MM if method == "newton" else RELAX_TOL_MM
    if not tol_mm > 0:
        raise MyofaceValueError(f"tol_mm must be > 0 mm; got {tol_mm}")
    state = state if state is not None else rest_state(model)
    tg = targets_array(model, targets)
    kin = model.kinematic_index
    xs = np.ascontiguousarray(state.x, dtype=np.float64)
    if xs.shape != model.rest_positions.shape:
        raise MyofaceValueError(
            f"the start state's positions must have shape {model.rest_positions.shape}; "
            f"got {xs.shape}"
        )
    x = np.empty_like(xs)
    x_kin_start = np.empty((len(kin), 3))
    finite, from_rest = _start(xs, kin, tg, model.rest_positions, x, x_kin_start)
    if not finite:
        raise MyofaceValueError("the start state's positions must be finite")
    if method == "newton":
        x0 = x
        try:
            x, ok, it, res, _, fmax = relax_newton(
                model, x0, x_kin_start, tol_mm, max_iter or 50, previous_x=state.previous_x
            )
        except MyofaceSimulationError:
            if from_rest:  # nothing to fall back on
                raise
            ok = False
        if not ok and not from_rest:
            # a warm start far from the new targets (a jump between distant expressions) can
            # leave Newton's basin; the linear response from rest is a start that always works
            x = model.rest_positions.copy()
            x[model.kinematic_index] = tg
            x, ok, it, res, _, fmax = relax_newton(
                model, x, model.rest_positions[model.kinematic_index], tol_mm, max_iter or 50
            )
        out = TissueState(x, np.zeros_like(x), state.t)
    elif method == "lbfgs":
        x, ok, it, res = _relax_lbfgs(model, x, tol_mm, max_iter or 300)
        out = TissueState(x, np.zeros_like(x), state.t)
    else:
        dt = model.stable_dt if dt is None else float(dt)
        v = state.v.copy()
        v[model.kinematic_index] = 0.0
        n = max_iter or 200_000
        it, res, bad = run_rk2(model, x, v, n, dt, tol_mm)
        if bad >= 0:
            raise MyofaceSimulationError(f"RK2 produced NaN/Inf at step {bad} (dt = {dt:g} s)")
        ok = res < tol_mm
        out = TissueState(x, v, state.t + it * dt)
    if method != "newton":  # the Newton solver has the forces at its last iterate
        fmax = float(np.abs(internal_forces(model, out.x)[model.free_index]).max())
    if not ok:
        warnings.warn(
            f"tissue relax ({method}) did not converge in {it} iterations "
            f"(last move {res:.2e} mm > tol {tol_mm:g} mm)",
            RelaxWarning,
            stacklevel=2,
        )
    out.previous_x = state.x.copy()
    return RelaxResult(out, bool(ok), int(it), float(res), fmax, method)
