"""Benchmarks of the snakes (names stable across releases), with scikit-image's active_contour as the
peer on the same synthetic task in the same run."""

from __future__ import annotations

import time

import numpy as np

from myoface.bench import Measurement, benchmark

SIZE = 256
N_FRAMES = 20
STEP_PX = (1.2, 0.8)  # translation of every feature per frame (x, y)
RADII = (7.5, 5.5)  # ellipse semi-axes, px: about 41 nodes 1 px apart
SIGMA = 1.5


def ellipse_task(n_frames: int = N_FRAMES, size: int = SIZE, seed: int = 0):
    """9 dark ellipses on a bright, slightly noisy 256x256 background, all translating.

    Returns (frames (T, H, W) uint8, centres (T, 9, 2) (x, y) px, initial contours list of
    (K, 2) started 2.5 px outside the true boundary).
    """
    rng = np.random.default_rng(seed)
    ys, xs = np.mgrid[0:size, 0:size]
    base = np.array(
        [[size * (0.2 + 0.3 * i), size * (0.2 + 0.3 * j)] for j in range(3) for i in range(3)]
    )
    frames, centres = [], []
    ra, rb = RADII
    for k in range(n_frames):
        c = base + np.array(STEP_PX) * k
        img = np.full((size, size), 200.0)
        for cx, cy in c:
            # anti-aliased disc edge: a 1-px ramp across the boundary
            r = np.sqrt(((xs - cx) / ra) ** 2 + ((ys - cy) / rb) ** 2)
            inside = np.clip((1.0 - r) * min(ra, rb) + 0.5, 0, 1)
            img = img * (1 - inside) + 50.0 * inside
        img += rng.normal(0, 4.0, img.shape)
        frames.append(np.clip(img, 0, 255).astype(np.uint8))
        centres.append(c)
    t = np.linspace(0, 2 * np.pi, 41, endpoint=False)
    init = [
        np.column_stack([cx + (ra + 2.5) * np.cos(t), cy + (rb + 2.5) * np.sin(t)])
        for cx, cy in centres[0]
    ]
    return np.stack(frames), np.stack(centres), init


def ellipse_distance(points: np.ndarray, center, radii=RADII) -> np.ndarray:
    """Distance (px) of (x, y) points to an axis-aligned ellipse (dense sampling of the curve)."""
    t = np.linspace(0, 2 * np.pi, 4000, endpoint=False)
    curve = np.column_stack([center[0] + radii[0] * np.cos(t), center[1] + radii[1] * np.sin(t)])
    d = np.linalg.norm(points[:, None, :] - curve[None, :, :], axis=2)
    return d.min(axis=1)


def track_myoface(frames, init):
    """Our tracker: image force p = 0.02 (the synthetic edges are soft, sigma 1.5 px) and at
    most 40 iterations per frame (the paper: contours settle "within a few steps" per frame,
    and the next frame continues from there)."""
    from myoface.analysis.potentials import image_potential
    from myoface.analysis.snakes import SnakeParams, Snakes, make_contours

    snakes = Snakes(make_contours(init, closed=True), SnakeParams(p=0.02, max_iter=40))
    out = None
    for f in frames:
        out = snakes.relax(image_potential(f, sigma=SIGMA))
    return out.split()


def track_skimage(frames, init):
    """The peer: active_contour per contour per frame, from the previous frame's result, on the
    same frames smoothed with the same Gaussian; parameters were the best of several tried
    (skimage's defaults lose more contours)."""
    from skimage.filters import gaussian
    from skimage.segmentation import active_contour

    snakes = [c[:, ::-1].copy() for c in init]  # skimage takes (row, col)
    for f in frames:
        g = gaussian(f, SIGMA, preserve_range=True)
        snakes = [
            active_contour(
                g,
                s,
                alpha=0.015,
                beta=0.1,
                w_line=0,
                w_edge=1,
                gamma=0.01,
                max_num_iter=100,
                boundary_condition="periodic",
            )
            for s in snakes
        ]
    return [s[:, ::-1] for s in snakes]


def _max_err(contours, centres):
    return max(
        float(ellipse_distance(c, ctr).max()) for c, ctr in zip(contours, centres, strict=True)
    )


def _skimage_available() -> bool:
    try:
        import skimage.segmentation  # noqa: F401
    except ImportError:
        return False
    return True


@benchmark(
    "snakes.track_fps_9x40_256",
    "1/s",
    higher_is_better=True,
    peer="skimage.segmentation.active_contour",
)
def bench_track_fps(quick: bool) -> Measurement:
    """9 closed contours x 41 nodes tracked through 256x256 frames (potential included,
    decoding excluded); the peer runs active_contour per contour per frame on the same frames."""
    n = 10 if quick else N_FRAMES
    frames, centres, init = ellipse_task(n)
    track_myoface(frames[:2], init)  # JIT
    reps = 3 if quick else 7
    ts = []
    for _ in range(reps):
        t0 = time.perf_counter()
        track_myoface(frames, init)
        ts.append(time.perf_counter() - t0)
    fps = n / float(np.median(ts))
    peer = None
    if _skimage_available():
        t0 = time.perf_counter()
        track_skimage(frames[: (3 if quick else n)], init)
        peer = (3 if quick else n) / (time.perf_counter() - t0)
    return Measurement(fps, reps, peer)


@benchmark(
    "snakes.max_err_px", "px", higher_is_better=False, peer="skimage.segmentation.active_contour"
)
def bench_max_err(quick: bool) -> Measurement:
    """Worst distance (px) of any node to its true ellipse after tracking the synthetic task."""
    n = 10 if quick else N_FRAMES
    frames, centres, init = ellipse_task(n)
    err = _max_err(track_myoface(frames, init), centres[-1])
    peer = _max_err(track_skimage(frames, init), centres[-1]) if _skimage_available() else None
    return Measurement(err, 1, peer)
