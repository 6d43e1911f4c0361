"""The codec benchmark's reading of x264's rate-PSNR curve (``myoface.bench.codec``), on a
known curve: the bytes it reports for a PSNR are the curve's, from two points bracketing it,
never a point's own bytes past the target (a rate control's step)."""

from __future__ import annotations

import numpy as np
import pytest

import myoface.bench.codec as C


def _known_curve(monkeypatch, db_of_log_bytes, log_bytes_of_crf):
    calls = []

    def point(kind, quick, crf, scale):
        crf = round(float(crf), 2)
        calls.append((crf, scale))
        lb = log_bytes_of_crf(crf, scale)
        return {"bytes": int(round(np.exp(lb))), "crf": crf, "scale": scale,
                "face_psnr_db": float(db_of_log_bytes(lb, scale))}  # fmt: skip

    monkeypatch.setattr(C, "_x264_crf_point", point)
    monkeypatch.setattr(C, "_cache", {})
    return calls


def test_the_bytes_for_a_psnr_are_interpolated_between_bracketing_points(monkeypatch):
    # a curve bent in log-bytes (so a straight line between far points would be off), the
    # quarter size the cheapest
    def lb_of_crf(crf, scale):
        return 9.0 + (51 - crf) * 0.06 + 1.2 * np.log2(scale)

    def db_of_lb(lb, scale):
        x = lb - 1.2 * np.log2(scale) - 9.0
        return 20.0 + 4.0 * x - 0.8 * x**2

    _known_curve(monkeypatch, db_of_lb, lb_of_crf)
    target = 24.3
    r = C._x264_for_psnr("sample", False, target)
    # the truth: solve 20 + 4x - 0.8x^2 = target at the quarter size
    x = (4 - np.sqrt(16 - 4 * 0.8 * (target - 20))) / (2 * 0.8)
    truth = np.exp(9.0 + x - 1.2 * 2)
    assert r["scale"] == 0.25
    lo, hi = r["bracket"]
    assert lo["face_psnr_db"] < target <= hi["face_psnr_db"]
    assert hi["face_psnr_db"] - lo["face_psnr_db"] <= C.CURVE_GAP_DB + 1e-9
    assert lo["bytes"] <= r["bytes"] <= hi["bytes"]
    assert r["bytes"] == pytest.approx(truth, rel=0.01)
    # the sizes' answers: each its own curve's
    assert set(r["sizes"]) == {"1.0", "0.5", "0.25"}
    assert r["sizes"]["1.0"] > r["sizes"]["0.5"] > r["sizes"]["0.25"]


def test_a_target_beyond_or_below_the_curve(monkeypatch):
    _known_curve(monkeypatch, lambda lb, s: 10.0 + 2 * lb, lambda crf, s: 10.0 - crf / 51)
    assert C._x264_for_psnr("sample", False, 40.0) is None  # (x264 never reaches it)
    below = C._x264_for_psnr("sample", False, 20.0)  # (x264 beats it at CRF 51)
    assert below["below_curve"] and below["bytes"] == int(round(np.exp(9.0)))
