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
    q, r = np.linalg.qr(w)
    keep = np.abs(np.diag(r)) > 1e-9 * max(1.0, np.abs(r).max())
    q = q[:, keep]
    return np.eye(len(muscle_ids)) - q @ q.T


def au_prior_terms(muscle_ids, settings=None) -> list:
    """The fit's AU-space prior for one frame's energy (the hook
    :meth:`~myoface.analysis.modelfit.ModelFit.terms` calls): ``[AUSubspacePrior]`` at
    ``settings.au_prior_sigma`` (:attr:`~myoface.analysis.weights.FitSettings.au_prior_sigma`),
    or ``[]`` when it is None or 0 (the default: off) or the AU table spans none of the
    muscles."""
    sigma = getattr(settings, "au_prior_sigma", None)
    if not sigma or off_table_projector(tuple(muscle_ids)) is None:
        return []
    return [AUSubspacePrior(muscle_ids, sigma)]


class AUSubspacePrior:
    """``|(I - P) c| / sigma``: the contractions held near the AU table's span (see the
    module's docstring)."""

    def __init__(self, muscle_ids, sigma: float = AU_PRIOR_SIGMA):
        self.ids = tuple(muscle_ids)
        self.sigma = float(sigma)
        self.q = off_table_projector(self.ids)

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
