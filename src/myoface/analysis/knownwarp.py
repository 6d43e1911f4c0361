"""Known answers made from real frames: a frame warped by a known smooth displacement field
(the expression's regions moved by set amounts), with a few degrees and pixels of fake head
motion on top. The warped frames keep the real frame's texture, noise and lighting, and the
true motion of every point is known, so a reader of facial motion (a detector, an optical
flow, a judge of resynthesis) can be validated on them before it is trusted.

The field is a sum of Gaussian bumps, one per moved point, each of ``radius`` pixels and a
displacement (pixels) of its own; then the whole frame is moved by a similarity (rotation,
scale and translation about the face's centre: the head's motion in the image plane). A pixel
``x`` of the source frame lands at ``y = S(x + d(x))``. The warped frame is sampled backward:
for each ``y``, ``x`` is found by fixed-point iteration of ``x = S^-1(y) - d(x)`` (the bumps are
smooth and small against their radius, so it contracts) and the source is sampled there
bilinearly (OpenCV's ``remap``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from myoface.errors import MyofaceValueError
from myoface.facemesh import import_opencv

#: fixed-point iterations of the backward map (the residual falls by the bumps' largest
#: gradient, |d'| < 0.3, each iteration: 1e-6 px after 12)
BACKWARD_ITERATIONS = 12
#: the backward map's grid step, pixels (interpolated between: the field is smooth)
GRID_PX = 4


def _cv2():
    return import_opencv("a known warp")


@dataclass(frozen=True)
class KnownWarp:
    """A known smooth warp of a frame (see the module's docstring).

    Attributes
    ----------
    centres : (K, 2) pixels (x, y): where each bump is centred (a point the warp moves).
    shifts : (K, 2) pixels: each bump's displacement at its centre.
    radius : float or (K,) pixels: the bumps' Gaussian radius (sigma).
    rotation_deg, scale, translation_px : the head's motion in the image plane, a similarity
        about ``pivot`` applied after the bumps (0, 1, (0, 0): none).
    pivot : (2,) pixels: the similarity's centre (e.g. the face's centre).
    """

    centres: np.ndarray
    shifts: np.ndarray
    radius: float | np.ndarray
    rotation_deg: float = 0.0
    scale: float = 1.0
    translation_px: tuple = (0.0, 0.0)
    pivot: np.ndarray = field(default_factory=lambda: np.zeros(2))

    def __post_init__(self):
        c = np.asarray(self.centres, dtype=np.float64).reshape(-1, 2)
        s = np.asarray(self.shifts, dtype=np.float64).reshape(-1, 2)
        r = np.broadcast_to(np.asarray(self.radius, dtype=np.float64), (len(c),))
        if len(c) != len(s) or not (np.isfinite(c).all() and np.isfinite(s).all()):
            raise MyofaceValueError("centres and shifts must be finite (K, 2) arrays alike")
        if not (r > 0).all():
            raise MyofaceValueError("the bumps' radius must be > 0 pixels")
        if not self.scale > 0:
            raise MyofaceValueError(f"scale must be > 0; got {self.scale}")
        object.__setattr__(self, "centres", c)
        object.__setattr__(self, "shifts", s)
        object.__setattr__(self, "radius", r.copy())
        object.__setattr__(self, "pivot", np.asarray(self.pivot, dtype=np.float64).reshape(2))

    # ------------------------------------------------------------------ the field
    def bumps(self, x: np.ndarray) -> np.ndarray:
        """The expression's displacement d(x) (N, 2) pixels at points ``x`` (N, 2)."""
        x = np.asarray(x, dtype=np.float64)
        out = np.zeros_like(x)
        for c, s, r in zip(self.centres, self.shifts, self.radius, strict=True):
            w = np.exp(-((x - c) ** 2).sum(-1) / (2.0 * r * r))
            out += w[..., None] * s
        return out

    def _similarity(self) -> tuple[np.ndarray, np.ndarray]:
        """(A (2, 2), b (2,)) of ``S(x) = A x + b``."""
        t = np.radians(self.rotation_deg)
        a = self.scale * np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])
        b = self.pivot + np.asarray(self.translation_px, dtype=np.float64) - a @ self.pivot
        return a, b

    def moved(self, x: np.ndarray) -> np.ndarray:
        """Where the points ``x`` (N, 2) of the source frame are in the warped frame."""
        x = np.asarray(x, dtype=np.float64)
        a, b = self._similarity()
        return (x + self.bumps(x)) @ a.T + b

    def head_only(self, x: np.ndarray) -> np.ndarray:
        """Where the points ``x`` would be with the head's motion alone (no expression)."""
        a, b = self._similarity()
        return np.asarray(x, dtype=np.float64) @ a.T + b

    # ------------------------------------------------------------------ the image
    def apply(self, image: np.ndarray) -> np.ndarray:
        """The warped frame (same size and type as ``image``). The backward map is solved
        on a grid of every :data:`GRID_PX` pixels and interpolated between (the field is
        smooth on the scale of its bumps: 0.01 px off for a 3 px bump of 25 px radius)."""
        cv2 = _cv2()
        img = np.asarray(image)
        h, w = img.shape[:2]
        gh, gw = -(-h // GRID_PX) + 1, -(-w // GRID_PX) + 1
        yy, xx = np.mgrid[0:gh, 0:gw].astype(np.float64) * GRID_PX
        y = np.stack([xx, yy], -1).reshape(-1, 2)
        a, b = self._similarity()
        z = (y - b) @ np.linalg.inv(a).T  # S^-1(y)
        x = z.copy()
        for _ in range(BACKWARD_ITERATIONS):
            x = z - self.bumps(x)
        x = np.ascontiguousarray(x.reshape(gh, gw, 2), dtype=np.float32)
        # every pixel's source, interpolated between the grid's nodes (node (i, j) is pixel
        # (j, i) * GRID_PX)
        gy, gx = np.mgrid[0:h, 0:w].astype(np.float32) / GRID_PX
        mx = cv2.remap(x[..., 0], gx, gy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        my = cv2.remap(x[..., 1], gx, gy, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        return cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)


def region_warp(points: np.ndarray, regions: dict, amounts: dict, radius_px: float,
                **head) -> KnownWarp:  # fmt: skip
    """A :class:`KnownWarp` that moves the points of ``regions`` ({name: point indices}) of
    ``points`` (N, 2+) pixels by ``amounts`` ({name: (dx, dy) pixels, or (M, 2) per point})
    with bumps of ``radius_px``; ``head``: :class:`KnownWarp`'s similarity (its ``pivot``
    defaults to the points' centre)."""
    pts = np.asarray(points, dtype=np.float64)[:, :2]
    centres, shifts = [], []
    for name, idx in regions.items():
        if name not in amounts:
            continue
        a = np.broadcast_to(np.asarray(amounts[name], dtype=np.float64), (len(idx), 2))
        centres.append(pts[list(idx)])
        shifts.append(a)
    if not centres:
        centres, shifts = [np.zeros((0, 2))], [np.zeros((0, 2))]
    head.setdefault("pivot", pts.mean(0))
    return KnownWarp(np.vstack(centres), np.vstack(shifts), radius_px, **head)
