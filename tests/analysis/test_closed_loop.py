"""Closed loop on a short synthetic sequence: render known contractions, analyse, compare.

Tolerances. Every muscle moves in the sequence (``truth_sequence``: smooth curves of amplitude
0.3-0.8), so a constant guess of each muscle's mean contraction already scores an RMSE of the
truth's standard deviation, 0.11-0.27 here: an absolute bound near 0.2 says nothing. Each
estimate must therefore beat that baseline by a stated factor (``BASELINE_FRACTION``: RMSE
< 0.3 of it, i.e. at least 91% of the variance explained), as well as meet absolute bounds.
The absolute bounds start from the issue's targets (RMSE <= 0.05, correlation >= 0.9 for every
muscle; measured on the 48-frame sequence by ``myoface bench --only analysis.closed_loop``, see
BENCHMARKS.md), which the full analysis (with analysis by synthesis) meets; the plain analysis
leaves the tracker's sub-pixel bias in the muscles whose signature is smallest, and the bounds
say by how much it may.

The frames show the mouth drawn shut (as the paper's synthetic frames; ``run_closed_loop(teeth=
True)`` renders the teeth and the dark cavity, which the lips' snake then needs the mouth layer
for: see :func:`~myoface.analysis.closed_loop.run_closed_loop`) and are framed on the face over
the whole sequence. The sequences have 24 frames: once the jaw slid as well as
turned (4520154) the 16-frame sequence's steps of up to 0.21 in the jaw between frames moved
the chin and the lower lip by about 10 px at 256 x 256, more than the contours follow from one
frame to the next (measured at ca01a7d, the mouth drawn shut: jaw RMSE 0.111 on 16 frames).

With the default analysis (snakes, curve fit, a second tracking pass from the model's
prediction) the errors measured on the 24-frame sequence were: frontalis bellies RMSE
0.007-0.026, zygomatic majors 0.008-0.013, levator labii superioris alaeque nasi 0.013-0.017,
depressor labii inferioris 0.071-0.081, jaw 0.004 (with the mouth's inside rendered and no
mouth layer: depressors 0.145-0.241). Since the depressor labii inferioris' zone narrowed to
the lip (radius 14 -> 8 mm, 2026-12-01: it no longer drags the chin boss down, which a real
smile raises), its signature in the lower lip's outline is smaller and the plain analysis
recovers it less well: RMSE 0.098-0.118, correlation 0.86-0.94 (analysis by synthesis:
0.039-0.069, 0.95-0.99; these spreads are the analysis' response to rounding, see
``test_analysis_by_synthesis_removes_the_trackers_bias``); the other muscles as before.
"""

import numpy as np
import pytest

from myoface.analysis.closed_loop import run_closed_loop
from myoface.model import build_face_model

#: an estimate's RMSE must be below this fraction of a constant guess's (each muscle's mean
#: truth, whose RMSE is the truth's standard deviation): at least 91% of the variance explained
BASELINE_FRACTION = 0.3
#: frames in the sequences analysed here (see the module's docstring)
N_FRAMES = 24


def baseline_rmse(res) -> np.ndarray:
    """Per muscle, the RMSE of guessing its mean true contraction in every frame."""
    return res.truth.std(axis=0)


@pytest.fixture(scope="module")
def plain():
    """The default analysis (no analysis by synthesis) of the sequence."""
    return run_closed_loop(build_face_model(), n_frames=N_FRAMES, size=256)


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    reason=(
        "known regression of the closed-lipped default face (12834a7, issue 34): the paper's "
        "snakes on the synthetic closed loop read frontalis_outer_r at RMSE 0.056 against the "
        "0.04 bound (every other muscle within its bound; with the lips' colour layer, "
        "Analyzer(mouth_colour=True), opt-in, 0.025)"
    ),
)
def test_closed_loop_recovers_every_muscle(plain):
    res = plain
    assert all(q == "ok" for q in res.quality)
    rmse, corr = (
        dict(zip(res.ids, res.rmse(), strict=True)),
        dict(zip(res.ids, res.corr(), strict=True)),
    )
    base = dict(zip(res.ids, baseline_rmse(res), strict=True))
    table = res.table()
    assert rmse["jaw"] < 0.02 and corr["jaw"] > 0.99, table
    for m in res.ids:
        if m.startswith("depressor"):
            continue  # test_closed_loop_recovers_the_depressors
        # the target 0.05 for the frontalis and the zygomatics (at most 0.04: their
        # outlines move by pixels); the levators' by up to 1.6x (their nasolabial contours
        # are short), and 91% of the variance explained
        bound = 0.08 if m.startswith("levator") else 0.04
        assert rmse[m] < bound and rmse[m] < BASELINE_FRACTION * base[m], (m, table)
        assert corr[m] > 0.9, table  # the target
    # every frame is measured and in range
    assert np.isfinite(res.estimate).all() and res.estimate.min() >= 0 and res.estimate.max() <= 1


@pytest.mark.slow
def test_closed_loop_recovers_the_depressors(plain):
    """The depressors' signature beyond the jaw's is a sub-pixel change of the lower lip's
    outline at 256 x 256, where the tracker's bias (which analysis by synthesis removes, see
    below) stays: three times the issue's target RMSE (0.05), at least 58% of the variance
    explained (under 0.65 of the constant guess's RMSE), correlation above 0.8 (measured
    0.105-0.118, 0.40-0.56 of the constant guess's, 0.86-0.94: see the module's docstring)."""
    rmse = dict(zip(plain.ids, plain.rmse(), strict=True))
    corr = dict(zip(plain.ids, plain.corr(), strict=True))
    base = dict(zip(plain.ids, baseline_rmse(plain), strict=True))
    for m in (f"depressor_labii_inferioris_{s}" for s in "lr"):
        assert rmse[m] < 0.15 and rmse[m] < 0.65 * base[m], (m, base[m], plain.table())
        assert corr[m] > 0.8, plain.table()


#: the two depressors' spread with analysis by synthesis, over ten sequences equal to the
#: test's within 1e-9 (rounding): RMSE 0.039-0.069 (median 0.056), 0.15-0.33 of a constant
#: guess's, correlation 0.95-0.99 (the other muscles: at most 0.027, 0.11 and at least 0.995)
DEPRESSOR_SYNTHESIS_RMSE = 0.09
DEPRESSOR_SYNTHESIS_FRACTION = 0.45


@pytest.mark.slow
def test_analysis_by_synthesis_removes_the_trackers_bias(plain):
    """``synthesis=True``: the model, textured from the first frame and deformed by each
    estimate (the lower teeth moved with its jaw), is tracked like the video and the
    difference drives the fit. Measured on the bench's 48 frames with the mouth rendered:
    worst RMSE 0.026 (depressors 0.024-0.026, levators 0.013-0.020, frontalis at most 0.010)
    against 0.168 without (depressors 0.157-0.168). The depressors, whose error is the
    tracker's bias this removes, must each come out below the plain run's, and together at
    least 10% below it.

    The depressors' numbers are not repeatable to better than about +-0.015: a difference of
    1e-14 mm in a relaxed skin (numba's cached kernels round differently from freshly
    compiled ones) or of 1e-9 in the true contractions moves a few rendered pixels by one
    level and a relax's stopping iteration, and over the 24 frames the depressors' estimates
    drift apart by up to 0.08. Over ten sequences equal within 1e-9 (2026-12-01): depressors
    RMSE 0.039-0.069 with synthesis against 0.076-0.112 without, their sum always below 0.8
    of the plain run's; so their own bounds (``DEPRESSOR_SYNTHESIS_*``) sit above that
    spread, and they miss the issue's target of 0.05 in half of those sequences (median
    0.056: since the depressor labii inferioris' zone narrowed to the lip its signature is
    smaller). The other muscles keep the tight bounds."""
    res = run_closed_loop(build_face_model(), n_frames=N_FRAMES, size=256, synthesis=True)
    assert all(q == "ok" for q in res.quality)
    rmse, table = dict(zip(res.ids, res.rmse(), strict=True)), res.table()
    corr = dict(zip(res.ids, res.corr(), strict=True))
    guess = dict(zip(res.ids, baseline_rmse(res), strict=True))
    base = dict(zip(plain.ids, plain.rmse(), strict=True))
    dep = [f"depressor_labii_inferioris_{s}" for s in "lr"]
    for m in res.ids:
        if m in dep:
            assert rmse[m] < DEPRESSOR_SYNTHESIS_RMSE, (m, table)
            assert rmse[m] < DEPRESSOR_SYNTHESIS_FRACTION * guess[m], (m, table)
            assert corr[m] > 0.9, (m, table)  # the target
            assert rmse[m] < base[m], (table, plain.table())
        else:
            assert rmse[m] < 0.05 and rmse[m] < BASELINE_FRACTION * guess[m], (m, table)
            assert corr[m] > 0.95, (m, table)
    assert sum(rmse[m] for m in dep) < 0.9 * sum(base[m] for m in dep), (table, plain.table())


def test_synthesis_is_refused_without_snakes():
    from myoface.errors import MyofaceValueError

    with pytest.raises(MyofaceValueError, match="synthesis=True needs tracker='snakes'"):
        run_closed_loop(build_face_model(), n_frames=2, tracker="oracle", synthesis=True)


@pytest.fixture(scope="module")
def fiducials():
    """``estimator="fiducials"``: fiducial points read off the contours (Section V-F), on the
    same 16-frame sequence."""
    return run_closed_loop(
        build_face_model(), n_frames=N_FRAMES, size=256, estimator="fiducials", reseed=False
    )


def _recovered(res, muscle, fraction=0.5, min_corr=0.9):
    """(ok, message): ``muscle``'s RMSE under ``fraction`` of the constant guess's (0.5: at
    least 75% of the variance explained) and its correlation above ``min_corr``."""
    j = list(res.ids).index(muscle)
    rmse, base, corr = res.rmse()[j], baseline_rmse(res)[j], res.corr()[j]
    msg = f"{muscle}: rmse {rmse:.3f} (constant guess {base:.3f}), corr {corr:.3f}\n{res.table()}"
    return rmse < fraction * base and corr > min_corr, msg


@pytest.mark.slow
def test_the_papers_fiducial_scheme_recovers_the_jaw(fiducials):
    """The paper's scheme is less accurate than the curve fit, and no target is set for it;
    "recovered" here means at least 75% of the variance explained (RMSE under half a constant
    guess's) with correlation above 0.9. Measured: jaw RMSE 0.072-0.083 against a constant
    guess's 0.194 (0.37-0.43 of it), correlation 0.98."""
    ok, msg = _recovered(fiducials, "jaw")
    assert ok, msg


@pytest.mark.slow
@pytest.mark.xfail(
    strict=True,
    raises=AssertionError,
    reason="known defect: the paper's fiducial scheme does not recover the zygomatic majors "
    "(RMSE 0.17-0.20 on the left, 1.0-1.3x a constant guess's 0.16; 0.075-0.079 on the right, "
    "0.62-0.65x of 0.12); the curve fit (the default) does",
)
def test_the_papers_fiducial_scheme_recovers_the_zygomatic_majors(fiducials):
    """As for the jaw: each zygomatic major's RMSE under half a constant guess's, correlation
    above 0.9."""
    for s in "lr":
        ok, msg = _recovered(fiducials, f"zygomaticus_major_{s}")
        assert ok, msg


@pytest.mark.xfail(
    strict=False,
    raises=AssertionError,
    reason="known regression of the jaw's (two-phase, 493ac9d): the estimator on the model's "
    "true curves ends at worst RMSE 0.0059 after 6 rounds (depressor labii inferioris; 0.009 "
    "with the camera framed at rest) against 0.0006 when written; 0.0047 on 2026-12-07 "
    "(frontalis inner; it passes, under the 0.005 bound by a hair: kept non-strict)",
)
def test_the_estimator_alone_converges_on_true_curves():
    """``tracker="oracle"``: the curve fit given the model's exact section curves. The
    linear fit alone is far off where the tissue is nonlinear (the jaw with the lower lip);
    the rounds through the tissue must take it to the truth. Measured when written, 16 frames:
    worst RMSE 0.0006 after 6 rounds; 0.005 leaves room for floating-point differences in the
    tissue solver between machines."""
    model = build_face_model()
    res = run_closed_loop(model, n_frames=16, size=256, refine=6, tracker="oracle")
    assert res.rmse().max() < 0.005, res.table()
    linear = run_closed_loop(model, n_frames=16, size=256, refine=0, tracker="oracle")
    assert linear.rmse().max() > 10 * res.rmse().max(), linear.table()


def test_unknown_tracker_is_refused():
    from myoface.errors import MyofaceValueError

    with pytest.raises(MyofaceValueError, match="tracker must be one of"):
        run_closed_loop(build_face_model(), n_frames=2, tracker="psychic")
