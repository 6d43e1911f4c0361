"""One frame's energy minimised: bounded Gauss-Newton (Levenberg's damping on a rejected step)
over the sum of the terms it is given (:mod:`myoface.analysis.terms`).

Each step solves the summed normal equations for (omega, dt, dc[free]) with the contractions
kept in [0, 1] (a small box-constrained quadratic programme,
:func:`~myoface.analysis._fitkernels.box_qp`), damped in proportion to each unknown's
curvature (Levenberg 1944, Marquardt 1963); a step that does not lower the energy is retried
with ten times the damping, an accepted one divides it by ten.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from myoface.analysis._fitkernels import box_qp
from myoface.analysis.camera import HeadPose, rotmat
from myoface.analysis.terms import Estimate, Term

#: a frame's steps stop once a step is below all of these: head rotation
#: (rad; 0.006 degrees), head translation (mm) and contraction. Each is far below what the
#: landmarks resolve (MediaPipe's ~1 mm scatter moves a contraction by a few hundredths);
#: tolerances ten times tighter took a third more iterations on single_face.mp4 for the same
#: analysis.fidelity (0.694 against 0.693). Nor are they what takes the photometric fit's
#: steps: five times looser (0.03 degrees, 0.05 mm, 0.02) took the sample's 644 steps to 608
#: and its pass from 2.78 to 2.66 s (medians of four passes alternating, 2026-12-08): its
#: frames run to :attr:`~myoface.analysis.weights.FitSettings.photo_iterations` either way.
STEP_TOL_RAD = 1e-4
STEP_TOL_MM = 1e-2
STEP_TOL_CONTRACTION = 5e-3
#: Levenberg's damping: its start, its floor, and the retries of a rejected step
LAMBDA_START = 1e-3
LAMBDA_MIN = 1e-7
RETRIES = 6


def _next_level(terms) -> bool:
    """Move every coarse-to-fine term still on a coarse level to its next (``advance()``);
    whether any did (the frame is then not done)."""
    moved = False
    for t in terms:
        if getattr(t, "settling", False):
            t.advance()
            moved = True
    return moved


def bounded_gauss_newton(
    terms: Sequence[Term],
    forward: Callable[[np.ndarray], np.ndarray],
    jac: np.ndarray,
    pose: HeadPose,
    contractions: np.ndarray,
    free: np.ndarray,
    iterations: int,
) -> tuple[HeadPose, np.ndarray, int, bool]:
    """Minimise ``sum(term.cost)`` from ``pose`` and ``contractions`` (M,) in [0, 1].

    ``forward(c)``: the model's skin (V, 3) mm, head frame, at contractions ``c``; ``jac``
    (V, 3, M): its response to them (the forward model is linear in ``c`` over a frame);
    ``free``: the contractions that move (the others stay). At most ``iterations`` steps.
    A term with ``settling`` True (a coarse-to-fine term on one of its coarse levels,
    :class:`~myoface.analysis.photometric.PhotometricTerm`) keeps the steps going: where they
    would stop, its ``advance()`` moves it to its next level instead.
    Returns (pose, contractions, steps taken, converged)."""
    free = np.asarray(free, dtype=np.int64)
    jac = np.ascontiguousarray(jac)
    c = np.array(contractions, dtype=np.float64)
    lam = LAMBDA_START
    conv = False
    it = 0
    while it < iterations:
        it += 1
        est = Estimate(pose, c, forward(c), jac, free)
        for t in terms:
            t.prepare(est)
        hess, rhs = None, None
        for t in terms:
            h, b = t.normal_equations(est)
            hess, rhs = (h, b) if hess is None else (hess + h, rhs + b)
        cost0 = sum(t.cost(est) for t in terms)
        # (a few dozen unknowns: numpy's calls cost more than their arithmetic, so as few
        # as will do)
        n = len(rhs)
        cf = c[free]
        lo = np.empty(n)
        lo[:6] = -np.inf
        np.negative(cf, out=lo[6:])
        hi = np.empty(n)
        hi[:6] = np.inf
        np.subtract(1.0, cf, out=hi[6:])
        dg = np.maximum(hess.diagonal(), 1e-12)
        for _ in range(RETRIES):
            damped = hess.copy()
            damped.flat[:: n + 1] += lam * dg
            step = box_qp(damped, rhs, lo, hi)
            new_pose = HeadPose(rotmat(step[:3]) @ pose.rotation, pose.translation_mm + step[3:6])
            new_c = c.copy()
            new_c[free] = np.minimum(np.maximum(cf + step[6:], 0.0), 1.0)
            trial = Estimate(new_pose, new_c, forward(new_c), jac, free)
            cost1 = sum(t.cost(trial) for t in terms)
            if cost1 <= cost0 + 1e-9 * abs(cost0):
                lam = max(lam / 10, LAMBDA_MIN)
                break
            lam *= 10
        else:
            # no step lowers the cost: at a minimum (to rounding), or of a coarse level
            if _next_level(terms):
                continue
            conv = True
            break
        pose, c = new_pose, new_c
        small = (
            np.abs(step[:3]).max() < STEP_TOL_RAD
            and np.abs(step[3:6]).max() < STEP_TOL_MM
            and (len(free) == 0 or np.abs(step[6:]).max() < STEP_TOL_CONTRACTION)
        )
        if small and not _next_level(terms):
            conv = True
            break
    return pose, c, it, conv
