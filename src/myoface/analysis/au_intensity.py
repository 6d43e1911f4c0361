"""Action-unit intensities from contractions: how much of each FACS action unit a frame's
muscle contractions hold, on OpenFace 2.2's 0-5 scale, through the AU table
(:func:`myoface.control.facs.au_table`). :mod:`myoface.analysis.openface` writes them as its
``AUxx_r`` columns and :mod:`myoface.analysis.expressions` reads its rule on them (both import
them from here: neither imports the other for them)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from myoface.control.facs import au_table
from myoface.errors import MyofaceFormatError

#: OpenFace 2.2's AU intensity (regression) outputs, in its column order
OPENFACE_AUS = (1, 2, 4, 5, 6, 7, 9, 10, 12, 14, 15, 17, 20, 23, 25, 26, 45)

#: OpenFace AUs that myoface does not measure, always empty, and why
UNMEASURED_AUS = {
    7: "lid tightener: in the AU table it is the orbital sphincter (orbicularis oculi, 0.5) "
    "with the lid's palpebral part (0.3), a mix of the muscles of AU6 (the sphincter) and "
    "AU45 (the palpebral part), so the contractions cannot tell it from AU6 + AU45; it is "
    "reported as those two",
}
#: AU intensity scale: OpenFace's maximum (FACS's E) for an AU at intensity 1 in the AU table
OPENFACE_SCALE = 5.0


def _expand(base: str, side: str, muscle_ids) -> list[str]:
    """The muscle ids ``base`` stands for (as :mod:`myoface.control.facs` expands them)."""
    if base in muscle_ids and not side:
        return [base]
    return [f"{base}_{s}" for s in ([side] if side else ["l", "r"])]


@dataclass(frozen=True)
class AUBasis:
    """The AU table as a linear map from AU intensities to contractions.

    Attributes
    ----------
    muscles : tuple of str — the contraction columns (muscle ids and ``"jaw"``), M.
    units : tuple of (int, str) — the unknowns: (AU number, side), side "l", "r" or "" (an AU
        FACS scores on the whole face), K.
    weights : (M, K) ndarray — the contraction each unknown asks of each muscle at intensity 1
        (the AU table's weights).
    aus : tuple of int — the OpenFace AUs these units measure.
    """

    muscles: tuple
    units: tuple
    weights: np.ndarray
    aus: tuple


def au_basis(muscle_ids, aus=OPENFACE_AUS) -> AUBasis:
    """The unknowns of :func:`au_intensities` over the contraction columns ``muscle_ids``.

    An AU of ``aus`` is measured when it is in the AU table, not in :data:`UNMEASURED_AUS`, and
    every muscle it drives with its largest weight is in ``muscle_ids`` (its lesser muscles that
    are missing are left out). FACS's unilateral AUs (``sides`` in the table) have one unknown
    per side.
    """
    ids = list(muscle_ids)
    index = {k: i for i, k in enumerate(ids)}
    table = au_table()
    units, cols, measured = [], [], []
    for n in aus:
        if n in UNMEASURED_AUS or n not in table:
            continue
        au = table[n]
        top = max(au.muscles.values())
        principal = [b for b, w in au.muscles.items() if w == top]
        if not all(m in index for b in principal for m in _expand(b, "", ids)):
            continue
        measured.append(n)
        for side in ("l", "r") if au.sides else ("",):
            col = np.zeros(len(ids))
            for base, w in au.muscles.items():
                for m in _expand(base, side, ids):
                    if m in index:
                        col[index[m]] = w
            units.append((n, side))
            cols.append(col)
    w = np.column_stack(cols) if cols else np.zeros((len(ids), 0))
    return AUBasis(tuple(ids), tuple(units), w, tuple(measured))


def _mix(w: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The AU table's mixing rule: contractions ``1 - prod_k (1 - w[:, k] a_k)``."""
    return 1.0 - np.prod(1.0 - w * a[None, :], axis=1)


def _mix_jacobian(w: np.ndarray, a: np.ndarray) -> np.ndarray:
    """d contractions / d a (M, K) of :func:`_mix`: ``w[:, k]`` times the product of the other
    units' ``1 - w a``."""
    p = 1.0 - w * a[None, :]
    ones = np.ones((len(p), 1))
    # the product of the other units' factors: of those before k times of those after k
    before = np.cumprod(np.hstack([ones, p[:, :-1]]), axis=1)
    after = np.cumprod(np.hstack([ones, p[:, :0:-1]]), axis=1)[:, ::-1]
    return w * before * after


def fit_units(contractions: np.ndarray, basis: AUBasis) -> np.ndarray:
    """Intensities (K,) in [0, 1] of ``basis.units`` whose contractions (the AU table's mixing
    rule, probabilistic OR) are closest, in least squares, to ``contractions`` (M,).

    Bounded least squares: a linear fit (``scipy.optimize.lsq_linear``, the mixing rule's
    first-order form, exact for a single AU) refined through the mixing rule itself
    (``scipy.optimize.least_squares``, trust region reflective). The basis of the OpenFace AUs
    over the default face's muscles has full column rank, so the answer is unique.
    """
    from scipy.optimize import least_squares, lsq_linear

    c = np.asarray(contractions, dtype=np.float64)
    w = basis.weights
    k = w.shape[1]
    if k == 0:
        return np.zeros(0)
    if not np.any(c > 0):
        return np.zeros(k)
    a0 = lsq_linear(w, c, bounds=(0.0, 1.0), method="bvls").x
    res = least_squares(
        lambda a: _mix(w, a) - c,
        np.clip(a0, 0.0, 1.0),
        jac=lambda a: _mix_jacobian(w, a),
        bounds=(0.0, 1.0),
        method="trf",
    )
    return np.clip(res.x, 0.0, 1.0)


def au_intensities(contractions, muscle_ids, aus=OPENFACE_AUS, *, basis=None) -> np.ndarray:
    """OpenFace-style AU intensities (T, len(aus)) on 0-5 from contractions (T, M) over
    ``muscle_ids`` (or one frame, (M,) -> (len(aus),)).

    Per frame, the intensities of the AUs (per side for FACS's unilateral AUs) are fitted to the
    contraction vector through the AU table (:func:`fit_units`); an AU's intensity is the mean
    of its two sides' (for an AU of the whole face, its one value) times
    :data:`OPENFACE_SCALE`. A contraction vector made by a single AU at intensity i gives that
    AU 5 i and the others 0.

    Limits: the AU table's muscles are the model's, so an AU is only as distinct as its muscles
    are. AU7's muscles are AU6's and AU45's, and it is not measured (:data:`UNMEASURED_AUS`);
    AU25
    (lips part) is read from the depressor labii inferioris and the jaw together with AU26; a
    contraction of a muscle that only AUs outside OpenFace's list drive (e.g. the zygomaticus
    minor of AU11) is explained by the listed AUs as well as they can, or left unexplained.
    NaN for an AU that is not measured (:func:`au_basis`) and for a frame whose contractions
    are not all finite. ``basis``: :func:`au_basis` of ``muscle_ids`` and ``aus``, when the
    caller keeps it (it is made here otherwise).
    """
    c = np.asarray(contractions, dtype=np.float64)
    one = c.ndim == 1
    c = np.atleast_2d(c)
    ids = list(muscle_ids)
    if c.shape[1] != len(ids):
        raise MyofaceFormatError(
            f"contractions must be (T, {len(ids)}) over muscle_ids; got shape {c.shape}"
        )
    basis = au_basis(ids, aus) if basis is None else basis
    out = np.full((len(c), len(aus)), np.nan)
    col = {n: j for j, n in enumerate(aus)}
    for t, row in enumerate(c):
        if not np.isfinite(row).all():
            continue
        a = fit_units(np.clip(row, 0.0, 1.0), basis)
        for n in basis.aus:
            vals = [a[k] for k, (m, _) in enumerate(basis.units) if m == n]
            out[t, col[n]] = OPENFACE_SCALE * float(np.mean(vals))
    return out[0] if one else out
