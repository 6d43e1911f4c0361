"""Small synthetic streams for the stream tests (no analysis: parameters made here)."""

from __future__ import annotations

import io

import numpy as np

from myoface.analysis.camera import PinholeCamera, rotmat
from myoface.codec.entropy import QUALITIES
from myoface.codec.params import APPEARANCE_LIMITS, N_APPEARANCE, FrameParams
from myoface.codec.stream import Header, StreamWriter, encode_image

M = 35  # the default face's contractions


def header(quality: str = "medium", segment_frames: int = 16, width=48, height=32) -> Header:
    rng = np.random.default_rng(5)
    img = np.zeros((height, width, 3), np.uint8)
    img[..., 0] = np.linspace(0, 255, width)[None, :]
    img[..., 1] = 90
    cal = FrameParams(np.eye(3), [0.0, 0.0, -600.0], np.zeros(M), [0.05, 0.0, np.nan, np.nan])
    return Header(
        width=width, height=height, fps=30.0, n_frames_hint=0, quality=quality,
        steps=QUALITIES[quality][0], segment_frames=segment_frames,
        camera=PinholeCamera(40.0, width / 2, height / 2), face="default", ids_crc=1234,
        n_contractions=M, calibration_index=0, calibration=cal,
        identity_mm=rng.normal(0, 2, (468, 3)), identity_step_mm=0.1, background=0,
        image_codec="webp", image=encode_image(img, "webp", 80),
    )  # fmt: skip


def frames(n: int, seed: int = 0) -> list[FrameParams]:
    """A random walk of head pose, contractions, gaze and appearance, with jumps (escapes),
    unmeasured frames and closed eyes."""
    rng = np.random.default_rng(seed)
    c = np.zeros(M)
    rv = np.zeros(3)
    tr = np.array([0.0, 0.0, -600.0])
    g = np.array([0.05, 0.0, 0.05, 0.0])
    lim = np.asarray(APPEARANCE_LIMITS)
    app = np.zeros(N_APPEARANCE)
    out = []
    for k in range(n):
        c = np.clip(c + rng.normal(0, 0.02, M) * (rng.random(M) < 0.4), 0, 1)
        if k % 37 == 5:
            c = rng.random(M)  # a jump far beyond the residuals coded directly
        rv = rv + rng.normal(0, 0.003, 3)
        tr = tr + rng.normal(0, 0.5, 3)
        g = np.clip(g + rng.normal(0, 0.02, 4), -0.6, 0.6)
        gaze = g.copy()
        if rng.random() < 0.1:
            gaze[:2] = np.nan
        if rng.random() < 0.05:
            gaze[:] = np.nan
        app = np.clip(app + rng.normal(0, 0.03, N_APPEARANCE) * lim, -lim, lim)
        if k % 41 == 7:
            app = rng.uniform(-lim, lim)  # (beyond the residuals coded directly)
        out.append(FrameParams(rotmat(rv), tr, c, gaze, measured=rng.random() > 0.05,
                               appearance=app))  # fmt: skip
    return out


def stream(n: int = 60, seed: int = 0, **kw) -> tuple[bytes, list[FrameParams], list[int]]:
    """A stream of ``n`` frames: its bytes, the decoder's parameters the writer reported,
    and the stream's length after each frame's packet was written (flushed)."""
    buf = io.BytesIO()
    w = StreamWriter(buf, header(**kw))
    decoded, ends = [], []
    for p in frames(n, seed):
        decoded.append(w.write(p))
        ends.append(len(buf.getvalue()))
    w.close()
    return buf.getvalue(), decoded, ends
