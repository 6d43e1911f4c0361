"""The fit's AU-space prior (myoface.analysis.au_prior): zero on every combination of the AU
table's units (so on every FACS expression the control level makes), positive off the
table's span, and its normal equations the gradient of its cost (the terms' contract)."""

from __future__ import annotations

import numpy as np
import pytest

from myoface.analysis.au_intensity import OPENFACE_AUS, au_basis
from myoface.analysis.au_prior import (
    AUSubspacePrior,
    au_prior_terms,
    off_table_projector,
    shared_aus,
    shared_projector,
)
from myoface.analysis.camera import HeadPose
from myoface.analysis.terms import Estimate
from myoface.errors import MyofaceValueError


@pytest.fixture(scope="module")
def ids():
    from myoface.face import load_default_face
    from myoface.model import build_face_model

    return tuple(build_face_model(load_default_face()).ids)


def _est(c, free):
    m = len(c)
    return Estimate(HeadPose.from_euler(0, 0, 0, (0, 0, -500)), np.asarray(c, float),
                    np.zeros((1, 3)), np.zeros((1, 3, m)), np.asarray(free))  # fmt: skip


def test_every_facs_expression_is_near_free(ids):
    """The six expressions' contractions (their FACS commands through the AU table, at 0.5
    and 1.0) lie within 0.15 (contraction units) of the table's span: exactly on it where no
    two of their AUs share a muscle; the control level combines AUs that do as 1 - prod(1 -
    w a) (myoface.control.facs), not a sum, so surprise's and fear's AU1 + AU2, both on the
    frontalis, are a little off the (linear) span."""
    from myoface.analysis.expressions import EXPRESSIONS
    from myoface.control import expression_contractions

    q = off_table_projector(ids)
    off = {}
    for name in EXPRESSIONS:
        for level in (0.5, 1.0):
            c = expression_contractions(name, level, list(ids))
            off[name, level] = float(np.linalg.norm(q @ c))
    assert max(off.values()) < 0.15, off
    for name in ("happiness", "sadness", "anger", "disgust"):
        assert off[name, 1.0] < 1e-3, (name, off[name, 1.0])


def test_random_au_combinations_are_free_and_single_muscles_are_not(ids):
    w = au_basis(list(ids), OPENFACE_AUS).weights
    prior = AUSubspacePrior(ids, 0.1)
    rng = np.random.default_rng(3)
    for _ in range(5):
        assert prior.cost(_est(w @ rng.uniform(0, 1, w.shape[1]), [])) < 1e-12
    # the marginal orbicularis oris is in no AU: all of it is off the table, (0.3 / 0.1)^2
    c = np.zeros(len(ids))
    c[ids.index("orbicularis_oris_marginalis")] = 0.3
    assert prior.cost(_est(c, [])) == pytest.approx(9.0)
    # one corrugator alone: AU4 pulls it with the depressor supercilii, so part of it is off
    c = np.zeros(len(ids))
    c[ids.index("corrugator_supercilii_l")] = 0.5
    assert 0.0 < prior.cost(_est(c, [])) < 25.0


def test_the_projector_is_one(ids):
    q = off_table_projector(ids)
    np.testing.assert_allclose(q @ q, q, atol=1e-10)
    np.testing.assert_allclose(q, q.T, atol=1e-12)
    rank = np.linalg.matrix_rank(au_basis(list(ids), OPENFACE_AUS).weights)
    assert round(np.trace(q)) == len(ids) - rank


@pytest.mark.parametrize("n_free", [0, 5, None])
def test_normal_equations_give_the_costs_gradient(ids, n_free):
    m = len(ids)
    free = np.arange(m if n_free is None else n_free)
    rng = np.random.default_rng(5)
    c = rng.uniform(0, 1, m)
    prior = AUSubspacePrior(ids, 0.1)
    h, b = prior.normal_equations(_est(c, free))
    assert h.shape == (6 + len(free),) * 2
    assert np.linalg.eigvalsh(h).min() >= -1e-8 * (1 + np.abs(h).max())
    for _ in range(3):
        d = rng.normal(size=len(free))
        eps = 1e-6
        cp, cm = c.copy(), c.copy()
        cp[free] += eps * d
        cm[free] -= eps * d
        slope = (prior.cost(_est(cp, free)) - prior.cost(_est(cm, free))) / (2 * eps)
        assert slope == pytest.approx(-2 * b[6:] @ d, rel=1e-5, abs=1e-6)
        # the term is quadratic: Gauss-Newton's model of it is exact
        e = 0.01
        cp, cm = c.copy(), c.copy()
        cp[free] += e * d
        cm[free] -= e * d
        second = prior.cost(_est(cp, free)) + prior.cost(_est(cm, free))
        second -= 2 * prior.cost(_est(c, free))
        assert second == pytest.approx(2 * e**2 * d @ h[6:, 6:] @ d, rel=1e-6, abs=1e-9)


def test_the_hook_follows_the_settings(ids):
    class S:
        au_prior_sigma = None

    assert au_prior_terms(ids, S()) == []
    S.au_prior_sigma = 0.2
    (term,) = au_prior_terms(ids, S())
    assert term.sigma == 0.2
    assert au_prior_terms(ids, object()) == []  # (settings without the field: off)
    from myoface.analysis.weights import FitSettings

    # the whole table's: opt-in; by default the AUs that share a muscle (shared_au_sigma)
    (default,) = au_prior_terms(ids, FitSettings())
    np.testing.assert_array_equal(default.q, shared_projector(ids))
    assert au_prior_terms(ids, FitSettings(shared_au_sigma=None)) == []
    full = au_prior_terms(ids, FitSettings(au_prior_sigma=0.1))
    assert len(full) == 1 and full[0].sigma == 0.1
    np.testing.assert_array_equal(full[0].q, off_table_projector(ids))
    assert au_prior_terms(("no_such_muscle",), S()) == []
    with pytest.raises(MyofaceValueError):
        FitSettings(shared_au_sigma=-0.1)


def test_the_shared_aus_are_the_brow_raisers():
    """AU1 and AU2 share the frontalis' middle part, the principal muscle of neither; the
    orbital sphincter's upper part, AU6's and AU7's partner, does not count: AU7 is not
    measured."""
    assert shared_aus() == (1, 2)


def test_the_shared_prior_holds_the_frontalis_to_au1_and_au2(ids):
    q = shared_projector(ids)
    np.testing.assert_allclose(q @ q, q, atol=1e-10)
    np.testing.assert_allclose(q, q.T, atol=1e-12)
    held = {ids[i] for i in np.flatnonzero(np.abs(q).sum(axis=1) > 1e-12)}
    assert held == {f"frontalis_{p}_{s}" for p in ("inner", "major", "outer") for s in "lr"}
    # three parts a side, two AUs a side: one direction a side is off their span
    assert round(np.trace(q)) == 2
    prior = AUSubspacePrior(ids, 0.1, projector=q)
    w = au_basis(list(ids), (1, 2)).weights
    rng = np.random.default_rng(7)
    for _ in range(5):  # any AU1 and AU2 on either side: free
        assert prior.cost(_est(w @ rng.uniform(0, 1, w.shape[1]), [])) < 1e-12
    c = np.zeros(len(ids))
    c[ids.index("zygomaticus_major_l")] = 0.8  # (muscles of other AUs: not held at all)
    c[ids.index("corrugator_supercilii_r")] = 0.6
    assert prior.cost(_est(c, [])) == 0.0
    # the middle part alone (what the fit read on blurred frames) is mostly off the span,
    # and costs more than the inner and outer parts making the same raise with it
    alone = np.zeros(len(ids))
    alone[ids.index("frontalis_major_l")] = 1.0
    parts = np.zeros(len(ids))
    for p, v in (("inner", 0.7), ("major", 0.47), ("outer", 0.7)):
        parts[ids.index(f"frontalis_{p}_l")] = v
    assert prior.cost(_est(alone, [])) > 50 * max(prior.cost(_est(parts, [])), 1e-3)
    assert prior.cost(_est(alone, [])) > 50.0
