"""Cameras: perspective or orthographic, with presets fitted to a mesh.

Image coordinates are (x, y) = (column, row) in pixels, origin at the top-left corner of the
image, pixel centres at half-integers. Camera space: x right, y up, depth along the viewing
direction (positive in front of the camera). World units: mm.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from myoface.errors import MyofaceValueError


def _unit(v, name) -> np.ndarray:
    a = np.asarray(v, dtype=np.float64)
    n = np.linalg.norm(a)
    if a.shape != (3,) or not np.isfinite(a).all() or n < 1e-12:
        raise MyofaceValueError(f"{name} must be a finite, non-zero 3-vector; got {v!r}")
    return a / n


def _check_size(width, height) -> None:
    ok = all(isinstance(n, int | np.integer) and not isinstance(n, bool) for n in (width, height))
    if not ok:
        raise MyofaceValueError(
            f"camera width and height must be integers (pixels); got {width!r}x{height!r}"
        )
    if not (1 <= width <= 16384 and 1 <= height <= 16384):
        raise MyofaceValueError(
            f"image size must be between 1 and 16384 pixels; got {width}x{height}"
        )


@dataclass(frozen=True)
class Camera:
    """A pinhole (``fov_deg``) or orthographic (``ortho_height_mm``) camera.

    Parameters
    ----------
    eye, target : (3,) mm — camera position and the point it looks at.
    up : (3,) — the world direction that appears upwards.
    width, height : int — image size in pixels.
    fov_deg : float or None — vertical field of view; None for orthographic.
    ortho_height_mm : float — the world height the image spans (orthographic only).
    """

    eye: np.ndarray
    target: np.ndarray
    up: np.ndarray = (0.0, 1.0, 0.0)
    width: int = 512
    height: int = 512
    fov_deg: float | None = 20.0
    ortho_height_mm: float = 200.0

    def __post_init__(self):
        for k in ("eye", "target"):
            a = np.asarray(getattr(self, k), dtype=np.float64)
            if a.shape != (3,) or not np.isfinite(a).all():
                raise MyofaceValueError(f"camera {k} must be a finite 3-vector (mm)")
            object.__setattr__(self, k, a)
        _check_size(self.width, self.height)
        if self.fov_deg is not None and not 0.1 <= float(self.fov_deg) <= 170:
            raise MyofaceValueError(f"fov_deg must be in [0.1, 170]; got {self.fov_deg}")
        if self.fov_deg is None and not float(self.ortho_height_mm) > 0:
            raise MyofaceValueError("ortho_height_mm must be > 0")
        fwd = _unit(self.target - self.eye, "target - eye")
        up = _unit(self.up, "up")
        right = np.cross(fwd, up)
        if np.linalg.norm(right) < 1e-9:
            raise MyofaceValueError("camera up must not be parallel to the viewing direction")
        right /= np.linalg.norm(right)
        object.__setattr__(self, "up", np.cross(right, fwd))
        object.__setattr__(self, "_basis", np.stack([right, np.cross(right, fwd), fwd]))

    @property
    def orthographic(self) -> bool:
        return self.fov_deg is None

    @property
    def focal_px(self) -> float:
        """Pixels per unit of x/depth (perspective) or per mm (orthographic)."""
        if self.orthographic:
            return self.height / float(self.ortho_height_mm)
        return 0.5 * self.height / np.tan(np.deg2rad(self.fov_deg) / 2)

    def to_camera(self, points: np.ndarray) -> np.ndarray:
        """World points (N, 3) mm -> camera space (N, 3): x right, y up, depth forwards."""
        return (np.asarray(points, dtype=np.float64) - self.eye) @ self._basis.T

    def project(self, points: np.ndarray) -> np.ndarray:
        """World points (N, 3) -> (N, 3): pixel x, pixel y, depth (mm, > 0 in front)."""
        c = self.to_camera(points)
        f = self.focal_px
        out = np.empty_like(c)
        if self.orthographic:
            out[:, 0] = 0.5 * self.width + f * c[:, 0]
            out[:, 1] = 0.5 * self.height - f * c[:, 1]
        else:
            z = np.where(np.abs(c[:, 2]) < 1e-9, 1e-9, c[:, 2])
            out[:, 0] = 0.5 * self.width + f * c[:, 0] / z
            out[:, 1] = 0.5 * self.height - f * c[:, 1] / z
        out[:, 2] = c[:, 2]
        return out

    def with_size(self, width: int, height: int) -> Camera:
        return Camera(
            self.eye,
            self.target,
            self.up,
            int(width),
            int(height),
            self.fov_deg,
            self.ortho_height_mm,
        )

    # ------------------------------------------------------------------ presets
    @classmethod
    def looking_at(
        cls,
        vertices: np.ndarray,
        direction,
        *,
        width: int = 512,
        height: int = 512,
        fov_deg: float | None = 18.0,
        margin: float = 1.12,
    ) -> Camera:
        """A camera on ``direction`` (from the mesh towards the camera) framing ``vertices``."""
        _check_size(width, height)
        v = np.asarray(vertices, dtype=np.float64)
        lo, hi = v.min(axis=0), v.max(axis=0)
        center = 0.5 * (lo + hi)
        d = _unit(direction, "direction")
        up = np.array([0.0, 1.0, 0.0]) if abs(d[1]) < 0.95 else np.array([0.0, 0.0, -1.0])
        # the extent seen across and up, from the bounding sphere of the mesh
        radius = float(np.linalg.norm(v - center, axis=1).max())
        right = np.cross(d, up)
        right /= np.linalg.norm(right)
        upv = np.cross(right, d) * -1
        rel = v - center
        half_h = np.abs(rel @ upv).max() * margin
        half_w = np.abs(rel @ right).max() * margin
        half = max(half_h, half_w * height / width)
        if fov_deg is None:
            return cls(center + d * 3 * radius, center, up, width, height, None, 2 * half)
        dist = half / np.tan(np.deg2rad(fov_deg) / 2) + radius
        return cls(center + d * dist, center, up, width, height, fov_deg)

    @classmethod
    def front(cls, vertices, **kw) -> Camera:
        """Looking at the face from the front (+z)."""
        return cls.looking_at(vertices, (0.0, 0.0, 1.0), **kw)

    @classmethod
    def three_quarter(cls, vertices, side: str = "l", **kw) -> Camera:
        """From 35 degrees towards the subject's left (``"l"``, +x) or right, slightly above."""
        s = 1.0 if side == "l" else -1.0
        a = np.deg2rad(35.0)
        return cls.looking_at(vertices, (s * np.sin(a), 0.12, np.cos(a)), **kw)

    @classmethod
    def profile(cls, vertices, side: str = "l", **kw) -> Camera:
        """From the subject's left (``"l"``) or right side."""
        return cls.looking_at(vertices, (1.0 if side == "l" else -1.0, 0.0, 0.0), **kw)
