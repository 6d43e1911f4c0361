"""Closed loop on a short synthetic sequence: render known contractions, analyse, compare.

Tolerances. With the default analysis (snakes, curve fit, a second tracking pass from the
model's prediction) the errors measured on this 16-frame sequence when this test was written
were: frontalis bellies RMSE 0.009-0.013, zygomatic majors 0.019-0.020, levator labii
superioris alaeque nasi 0.022-0.040, depressor labii inferioris 0.071-0.082, jaw 0.004;
correlation at least 0.94 for every muscle. The bounds below sit about 1.5-2.5x above those,
because the tracking moves by fractions of a pixel with floating-point-level changes (in the
renderer, the tissue solver) and the depressors, whose signature beyond the jaw's is a
sub-pixel change of the lower lip's outline at 256 x 256, amplify that. They are a regression
floor; the issue's targets (RMSE <= 0.05, correlation >= 0.9 for every muscle) are measured on
the 48-frame sequence by ``myoface bench --only analysis.closed_loop`` (see BENCHMARKS.md).
"""

import numpy as np
import pytest

from myoface.analysis.closed_loop import run_closed_loop
from myoface.model import build_face_model


@pytest.fixture(scope="module")
def plain():
    """The default analysis (no analysis by synthesis) of the 16-frame sequence."""
    return run_closed_loop(build_face_model(), n_frames=16, size=256)


@pytest.mark.slow
def test_closed_loop_recovers_every_muscle(plain):
    res = plain
    assert all(q == "ok" for q in res.quality)
    rmse, corr = (
        dict(zip(res.ids, res.rmse(), strict=True)),
        dict(zip(res.ids, res.corr(), strict=True)),
    )
    table = res.table()
    assert rmse["jaw"] < 0.02 and corr["jaw"] > 0.99, table
    for m in res.ids:
        bound = 0.2 if m.startswith("depressor") else 0.08 if m.startswith("levator") else 0.04
        assert rmse[m] < bound, table
        assert corr[m] > 0.85, table
    # every frame is measured and in range
    assert np.isfinite(res.estimate).all() and res.estimate.min() >= 0 and res.estimate.max() <= 1


@pytest.mark.slow
def test_analysis_by_synthesis_removes_the_trackers_bias(plain):
    """``synthesis=True``: the model, textured from the first frame and deformed by each
    estimate, is tracked like the video and the difference drives the fit. Measured when
    written, 16 frames, 3 rounds: worst RMSE 0.044 (depressors 0.032-0.044, levators
    0.029-0.039, frontalis at most 0.015) against 0.082 without. The bounds allow the same
    sub-pixel jitter as the test above; the depressors, whose error is the tracker's bias this
    removes, must come out at most 0.75 of the plain run's."""
    res = run_closed_loop(build_face_model(), n_frames=16, size=256, synthesis=True)
    assert all(q == "ok" for q in res.quality)
    rmse, table = dict(zip(res.ids, res.rmse(), strict=True)), res.table()
    base = dict(zip(plain.ids, plain.rmse(), strict=True))
    assert max(rmse.values()) < 0.07, table
    assert res.corr().min() > 0.95, table
    for s in "lr":
        m = f"depressor_labii_inferioris_{s}"
        assert rmse[m] < 0.75 * base[m], (table, plain.table())


def test_synthesis_is_refused_without_snakes():
    from myoface.errors import MyofaceValueError

    with pytest.raises(MyofaceValueError, match="synthesis=True needs tracker='snakes'"):
        run_closed_loop(build_face_model(), n_frames=2, tracker="oracle", synthesis=True)


@pytest.mark.slow
def test_the_papers_fiducial_scheme_is_still_available():
    """``estimator="fiducials"``: fiducial points read off the contours (Section V-F). Less
    accurate than the curve fit (its worst muscles were at RMSE 0.3-0.4 when the curve fit
    replaced it), but the jaw and the zygomatic majors are recovered (measured when written:
    jaw RMSE 0.072 with correlation 0.98, zygomatic majors 0.075-0.164 with 0.82-0.89)."""
    res = run_closed_loop(
        build_face_model(), n_frames=16, size=256, estimator="fiducials", reseed=False
    )
    ids = list(res.ids)
    rmse, corr = res.rmse(), res.corr()
    j = ids.index("jaw")
    assert rmse[j] < 0.15 and corr[j] > 0.9, res.table()
    for s in "lr":
        z = ids.index(f"zygomaticus_major_{s}")
        assert rmse[z] < 0.25 and corr[z] > 0.7, res.table()


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
