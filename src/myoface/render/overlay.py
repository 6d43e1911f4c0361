"""Overlays drawn onto rendered images: the mesh wireframe and muscle vectors (as the paper's
Fig. 4). Lines are anti-aliased by drawing with sub-pixel steps and bilinear splatting."""

from __future__ import annotations

import numpy as np
from numba import njit

from myoface.render.camera import Camera


@njit(cache=True)
def _draw_lines(img, p0, p1, color, alpha, width):
    h, w = img.shape[0], img.shape[1]
    for k in range(p0.shape[0]):
        x0, y0, x1, y1 = p0[k, 0], p0[k, 1], p1[k, 0], p1[k, 1]
        n = int(max(abs(x1 - x0), abs(y1 - y0)) * 2) + 2
        for s in range(n + 1):
            t = s / n
            x = x0 + (x1 - x0) * t - 0.5
            y = y0 + (y1 - y0) * t - 0.5
            for oy in range(-width + 1, width):
                for ox in range(-width + 1, width):
                    xi = int(np.floor(x)) + ox
                    yi = int(np.floor(y)) + oy
                    fx = x - np.floor(x)
                    fy = y - np.floor(y)
                    for dy in range(2):
                        for dx in range(2):
                            px, py = xi + dx, yi + dy
                            if 0 <= px < w and 0 <= py < h:
                                wgt = (fx if dx else 1 - fx) * (fy if dy else 1 - fy)
                                a = alpha * wgt * 0.5
                                for c in range(3):
                                    img[py, px, c] = img[py, px, c] * (1 - a) + color[c] * a


def overlay_segments(
    image: np.ndarray,
    camera: Camera,
    starts: np.ndarray,
    ends: np.ndarray,
    color=(255, 210, 40),
    alpha: float = 1.0,
    width: int = 1,
    endpoints: bool = True,
) -> np.ndarray:
    """Draw 3-D segments (N, 3) mm projected by ``camera`` onto a copy of ``image`` (uint8).

    ``camera`` must have the image's size. With ``endpoints`` the start of each segment gets a
    small dot (the muscle's attachment, as in the paper's Fig. 4).
    """
    img = image.astype(np.float64)
    a = camera.project(np.asarray(starts, float))[:, :2]
    b = camera.project(np.asarray(ends, float))[:, :2]
    col = np.asarray(color, dtype=np.float64)
    _draw_lines(img, a, b, col, float(alpha), int(width))
    if endpoints:
        _draw_lines(img, a - [1.2, 0], a + [1.2, 0], col, float(alpha), int(width) + 1)
    return np.clip(img + 0.5, 0, 255).astype(np.uint8)


def overlay_wireframe(
    image: np.ndarray,
    camera: Camera,
    vertices: np.ndarray,
    edges: np.ndarray,
    color=(255, 255, 255),
    alpha: float = 0.35,
) -> np.ndarray:
    """Draw mesh edges (E, 2) of ``vertices`` (V, 3) onto a copy of ``image``."""
    v = np.asarray(vertices, float)
    e = np.asarray(edges)
    return overlay_segments(image, camera, v[e[:, 0]], v[e[:, 1]], color, alpha, 1, False)
