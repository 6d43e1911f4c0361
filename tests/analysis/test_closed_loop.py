"""Closed loop on a short synthetic sequence: render known contractions, analyse, compare.

Tolerances: the errors measured when this test was written were jaw RMSE 0.065-0.08 with
correlation 0.95-0.97, and zygomatic majors RMSE 0.06-0.125 with correlation 0.80-0.97 on this
16-frame sequence; the spread comes from floating-point-level changes in the tracking (the joint
inversion is ill-conditioned between muscles with overlapping effects). The bounds sit above that
spread, so the test fails on a real regression and not on noise. They are a regression floor, not the
issue's targets (RMSE <= 0.05 and correlation >= 0.9 for every muscle):
the jaw and the zygomatic majors are recovered well; the frontalis bellies (whose fields overlap
on the brow), the depressor labii inferioris (confounded with the jaw on the lower lip) and the
levator labii superioris alaeque nasi (a small motion at the nose) are not yet.
"""

import numpy as np
import pytest

from myoface.analysis.closed_loop import run_closed_loop
from myoface.model import build_face_model


@pytest.mark.slow
def test_closed_loop_recovers_jaw_and_zygomatic_major():
    res = run_closed_loop(build_face_model(), n_frames=16, size=256)
    assert all(q == "ok" for q in res.quality)
    rmse, corr = res.rmse(), res.corr()
    ids = list(res.ids)
    j = ids.index("jaw")
    assert rmse[j] < 0.15 and corr[j] > 0.9, res.table()
    for s in "lr":
        z = ids.index(f"zygomaticus_major_{s}")
        assert rmse[z] < 0.2 and corr[z] > 0.7, res.table()
    # every frame is measured and in range
    assert np.isfinite(res.estimate).all() and res.estimate.min() >= 0 and res.estimate.max() <= 1
