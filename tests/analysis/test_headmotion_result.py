"""The head-motion benchmark's result: its gain (a reading's bias apart from its scatter)."""

import numpy as np

from myoface.bench.headmotion import PAPER_MUSCLES, HeadMotionResult


def _result(truth, estimate, ids):
    n = len(truth)
    z3, z1 = np.zeros((n, 3)), np.zeros(n)
    return HeadMotionResult(tuple(ids), truth, estimate, z3, z3, z1, z1, 0, z1)


def test_gain_is_the_reading_over_the_truth_and_ignores_scatter_and_lost_frames():
    rng = np.random.default_rng(3)
    ids = list(PAPER_MUSCLES[:3])
    t = np.clip(np.sin(np.linspace(0, 3 * np.pi, 200))[:, None] * [0.8, 0.5, 0.0], 0, None)
    # read at 0.6, 1.0 and (a muscle that never moves) at a small spurious level, with zero-mean
    # scatter, and two frames lost
    e = t * [0.6, 1.0, 0.0] + rng.normal(0, 0.02, t.shape) + [0, 0, 0.05]
    e[[10, 50]] = np.nan
    res = _result(t, e, ids)
    g = res.gain()
    assert abs(g[0] - 0.6) < 0.02 and abs(g[1] - 1.0) < 0.02, g
    assert np.isnan(g[2])  # (its truth does not move: no gain to speak of)
    s = res.summary(muscles=ids)
    assert (
        abs(s["gain_least"] - g[0]) < 1e-12 and abs(s["gain_median"] - 0.5 * (g[0] + g[1])) < 1e-12
    )
    assert "gain" in res.table().splitlines()[0]
    # a muscle that moves only on frames that were lost has no gain either (not a division by 0)
    t2 = np.zeros((6, 1))
    t2[3] = 0.5
    e2 = np.zeros((6, 1))
    e2[3] = np.nan
    assert np.isnan(_result(t2, e2, ids[:1]).gain()[0])
