"""A prior of the 3-D fit in action-unit space: the paper's control level (FACS action units,
each a fixed pattern of muscles) as a term of one frame's energy.

The fit's unknowns are the model's contractions (39 with the jaw); the AU table
(``data/facs_action_units.toml``, :func:`~myoface.analysis.au_intensity.au_basis`) says
which patterns of them a face makes: 28 units (AUs, left and right where FACS scores the
sides apart) spanning a 28-dimensional subspace. Contractions outside that span (e.g. the
corrugator without the depressor supercilii it pulls with in AU4, or the lip depressor's
share of an opened mouth given to the jaw's neighbours) are what the fit uses when the skin
cannot tell muscles apart. This term penalises that component:

    E_au = |(I - P) c|^2 / sigma^2,    P = W W^+  (the projector onto the AU table's span)

a Gaussian on the distance (in contraction units) from the nearest combination of AUs,
signed intensities allowed (the span, not the cone: linear, so its normal equations are
exact and cheap). ``sigma`` says how far from the table a face may go before the pixels
have to pay for it. Muscles no AU uses (the marginal orbicularis oris) are outside the span
entirely and are held near 0 by it.

By default (:attr:`~myoface.analysis.weights.FitSettings.shared_au_sigma`) the fit holds only
the AUs that share a muscle none of them drives as its principal one near their span
(:func:`shared_aus`: AU1 and AU2, which share the frontalis' middle part); the whole table's
prior is opt-in (:attr:`~myoface.analysis.weights.FitSettings.au_prior_sigma`).

Like the other priors it takes the terms' protocol (:mod:`myoface.analysis.terms`):
``prepare``, ``normal_equations`` (``H = J^T J``, ``b = -J^T r`` on the contraction block)
and ``cost``.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

#: the prior's standard deviation, in contraction units (0-1) off the AU table's span, where
#: it is used (``FitSettings(au_prior_sigma=AU_PRIOR_SIGMA)``): a muscle pattern 0.1 away from
#: any combination of AUs costs as much as a landmark 1 sigma off
AU_PRIOR_SIGMA = 0.1


@lru_cache(maxsize=8)
def off_table_projector(muscle_ids: tuple) -> np.ndarray | None:
    """``I - P`` (M, M): the component of contractions over ``muscle_ids`` that no
    combination of the AU table's units makes (P the orthogonal projector onto the span of
    the units' muscle patterns, :attr:`~myoface.analysis.au_intensity.AUBasis.weights`);
    None when the table measures no AU on these muscles (e.g. a model of other muscles)."""
    from myoface.analysis.au_intensity import OPENFACE_AUS, au_basis

    w = au_basis(list(muscle_ids), OPENFACE_AUS).weights
    if w.size == 0 or not np.abs(w).any():
        return None
    return _complement(w)


def _complement(w) -> np.ndarray:
    """``I - Q Q^T`` (N, N): the orthogonal projector onto what the columns of ``w`` (N, K)
    do not span (their rank from the QR's diagonal)."""
    q, r = np.linalg.qr(w)
    keep = np.abs(np.diag(r)) > 1e-9 * max(1.0, np.abs(r).max())
    q = q[:, keep]
    return np.eye(len(w)) - q @ q.T


def shared_aus() -> tuple[int, ...]:
    """The measured AUs (OpenFace's, less :data:`~myoface.analysis.au_intensity.
    UNMEASURED_AUS`) that share a muscle which none of them drives as its principal one
    (its largest weight): the muscle's contraction belongs to neither AU, and the skin's
    motion alone does not say how to split it. In the AU table: AU1 and AU2, which share the
    frontalis' middle part (0.25 and 0.5 of their principal parts, the inner and the outer).
    (The orbital sphincter's upper part is AU6's and AU7's partner alike, but AU7 is not
    measured: its muscles are AU6's and AU45's.)"""
    from myoface.analysis.au_intensity import OPENFACE_AUS, UNMEASURED_AUS
    from myoface.control.facs import au_table

    table = au_table()
    aus = [n for n in OPENFACE_AUS if n in table and n not in UNMEASURED_AUS]
    partners: dict[str, list[int]] = {}  # (muscle: the AUs that drive it below their top)
    principal: set[str] = set()
    for n in aus:
        top = max(table[n].muscles.values())
        for base, w in table[n].muscles.items():
            if w < top:
                partners.setdefault(base, []).append(n)
            else:
                principal.add(base)
    out: set[int] = set()
    for base, ns in partners.items():
        if len(ns) >= 2 and base not in principal:
            out.update(ns)
    return tuple(sorted(out))


@lru_cache(maxsize=8)
def shared_projector(muscle_ids: tuple) -> np.ndarray | None:
    """``I - P`` (M, M) over the muscles of :func:`shared_aus` (zero elsewhere): the
    component of their contractions that no combination of those AUs makes; None when the
    model has none of them."""
    from myoface.analysis.au_intensity import au_basis

    w = au_basis(list(muscle_ids), shared_aus()).weights
    rows = np.flatnonzero(np.abs(w).sum(axis=1) > 0)
    if len(rows) == 0:
        return None
    out = np.zeros((len(muscle_ids), len(muscle_ids)))
    out[np.ix_(rows, rows)] = _complement(w[rows])
    return out


def au_prior_terms(muscle_ids, settings=None) -> list:
    """The fit's AU-space prior for one frame's energy (the hook
    :meth:`~myoface.analysis.modelfit.ModelFit.terms` calls): ``[AUSubspacePrior]`` at
    ``settings.au_prior_sigma`` (:attr:`~myoface.analysis.weights.FitSettings.au_prior_sigma`:
    the whole AU table's span; opt-in), else over the AUs that share a muscle
    (:func:`shared_projector`) at ``settings.shared_au_sigma``
    (:attr:`~myoface.analysis.weights.FitSettings.shared_au_sigma`: on by default), or ``[]``
    when the sigma is None or 0 or the AUs span none of the muscles."""
    ids = tuple(muscle_ids)
    sigma = getattr(settings, "au_prior_sigma", None)
    if sigma:
        return [] if off_table_projector(ids) is None else [AUSubspacePrior(ids, sigma)]
    sigma = getattr(settings, "shared_au_sigma", None)
    if sigma:
        q = shared_projector(ids)
        return [] if q is None else [AUSubspacePrior(ids, sigma, projector=q)]
    return []


class AUSubspacePrior:
    """``|(I - P) c| / sigma``: the contractions held near the AU table's span (see the
    module's docstring)."""

    def __init__(self, muscle_ids, sigma: float = AU_PRIOR_SIGMA, projector=None):
        self.ids = tuple(muscle_ids)
        self.sigma = float(sigma)
        #: ``I - P`` (M, M): the whole table's (:func:`off_table_projector`) or a part's
        self.q = off_table_projector(self.ids) if projector is None else np.asarray(projector)

    def prepare(self, est) -> None:
        pass

    def normal_equations(self, est):
        n = est.n_unknowns
        h, b = np.zeros((n, n)), np.zeros(n)
        free = np.asarray(est.free)
        if len(free):
            r = self.q @ est.contractions / self.sigma
            j = self.q[:, free] / self.sigma
            h[6:, 6:] = j.T @ j
            b[6:] = -j.T @ r
        return h, b

    def cost(self, est) -> float:
        r = self.q @ est.contractions / self.sigma
        return float(r @ r)
