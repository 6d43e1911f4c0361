"""The camera and the head's pose in front of it: what the 3-D fit projects through.

Camera frame (:class:`HeadPose`): x right, y up, z towards the viewer (the head frame's axes
when the face looks into the camera), the camera at the origin looking along -z; the head frame
maps into it by ``P = R X + t``. Angles: ``R = Ry(yaw) Rx(pitch) Rz(roll)`` (intrinsic y-x-z):
yaw > 0 turns the face towards the subject's left (the image's right), pitch > 0 nods it down,
roll > 0 tilts its top towards the subject's right (counter-clockwise in the image).

Image coordinates are (x, y) = (column, row), pixels. The projection and its Jacobian live
here once (:meth:`PinholeCamera.project`, :meth:`PinholeCamera.projection_jacobian`); every
term of the fit that compares the model with an image goes through them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from myoface.errors import MyofaceValueError
from myoface.face.personal import fit_similarity_3d

#: the vertical field of view assumed for a video whose camera is not known: a typical webcam
#: or phone front camera (60-78 degrees diagonal) on a 16:9 or 4:3 frame
DEFAULT_FOV_DEG = 45.0
#: the order of the head's Euler angles: yaw about y, then pitch about x, then roll about z
EULER_ORDER = "YXZ"
#: the head's 3-D pose as CSV columns, in order (:meth:`HeadPose.columns`): angles (deg) and
#: the head frame's origin in the camera frame (x right, y up, mm; ``head_tz_mm`` its distance
#: in front of the camera)
POSE_COLUMNS = (
    "head_yaw_deg",
    "head_pitch_deg",
    "head_roll_deg",
    "head_tx_mm",
    "head_ty_mm",
    "head_tz_mm",
)


@dataclass(frozen=True)
class PinholeCamera:
    """A pinhole camera's intrinsics: focal length and principal point, pixels; image (x, y) =
    (column, row)."""

    focal_px: float
    cx: float
    cy: float

    def __post_init__(self):
        vals = (self.focal_px, self.cx, self.cy)
        if not all(np.isfinite(v) for v in vals) or not self.focal_px > 0:
            raise MyofaceValueError(
                f"a camera needs a finite focal length > 0 px and principal point; got {vals}"
            )

    @classmethod
    def for_image(cls, width: int, height: int, fov_deg: float = DEFAULT_FOV_DEG):
        """The camera of a ``width`` x ``height`` image with vertical field of view
        ``fov_deg`` and the principal point at the image's centre."""
        if not 1 <= fov_deg <= 170:
            raise MyofaceValueError(f"fov_deg must be in [1, 170]; got {fov_deg}")
        f = 0.5 * height / np.tan(np.radians(fov_deg) / 2)
        return cls(float(f), 0.5 * width, 0.5 * height)

    def project(self, p: np.ndarray) -> np.ndarray:
        """Camera-frame points (N, 3) mm -> (N, 2) pixels (x, y)."""
        f = self.focal_px / np.maximum(-p[:, 2], 1e-6)
        out = np.empty((len(p), 2))
        np.multiply(p[:, 0], f, out=out[:, 0])
        np.multiply(p[:, 1], -f, out=out[:, 1])
        out[:, 0] += self.cx
        out[:, 1] += self.cy
        return out

    def projection_jacobian(self, p: np.ndarray) -> np.ndarray:
        """d(x, y)/dP (N, 2, 3), pixels per mm, of :meth:`project` at camera-frame points
        ``p`` (N, 3) mm."""
        f = self.focal_px
        d = np.maximum(-p[:, 2], 1e-6)
        out = np.zeros((len(p), 2, 3))
        out[:, 0, 0] = f / d
        out[:, 0, 2] = f * p[:, 0] / d**2
        out[:, 1, 1] = -f / d
        out[:, 1, 2] = -f * p[:, 1] / d**2
        return out


@dataclass(frozen=True)
class HeadPose:
    """The head frame in the camera frame: ``P = rotation @ X + translation_mm``."""

    rotation: np.ndarray
    translation_mm: np.ndarray

    @classmethod
    def from_euler(cls, yaw_deg=0.0, pitch_deg=0.0, roll_deg=0.0, translation_mm=(0, 0, -600)):
        r = Rotation.from_euler(EULER_ORDER, [yaw_deg, pitch_deg, roll_deg], degrees=True)
        return cls(r.as_matrix(), np.asarray(translation_mm, dtype=np.float64))

    @property
    def angles_deg(self) -> np.ndarray:
        """(yaw, pitch, roll) degrees."""
        return Rotation.from_matrix(self.rotation).as_euler(EULER_ORDER, degrees=True)

    def apply(self, x: np.ndarray) -> np.ndarray:
        """Head-frame points (N, 3) mm -> camera frame (N, 3) mm."""
        return np.asarray(x) @ self.rotation.T + self.translation_mm

    def columns(self) -> dict[str, float]:
        """The CSV's pose columns (:data:`POSE_COLUMNS`) and their values."""
        yaw, pitch, roll = self.angles_deg
        tx, ty, tz = self.translation_mm
        vals = (yaw, pitch, roll, tx, ty, -tz)
        return {c: float(v) for c, v in zip(POSE_COLUMNS, vals, strict=True)}

    @classmethod
    def from_columns(cls, row: dict) -> HeadPose:
        """The inverse of :meth:`columns`."""
        yaw, pitch, roll, tx, ty, tz = (row[c] for c in POSE_COLUMNS)
        return cls.from_euler(yaw, pitch, roll, (tx, ty, -tz))


def check_points(points, n: int) -> np.ndarray:
    """``points`` as a finite (n, 3) float array (x, y px; z relative depth px, NaN when a
    (n, 2) array was given); a clear error otherwise."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[0] != n or p.shape[1] not in (2, 3) or not np.isfinite(p).all():
        raise MyofaceValueError(
            f"landmarks must be finite ({n}, 3) points (x, y px; z relative depth px); got "
            f"shape {p.shape}"
        )
    if p.shape[1] == 2:
        p = np.column_stack([p, np.full(n, np.nan)])
    return p


def initial_pose(shape: np.ndarray, points: np.ndarray, camera: PinholeCamera) -> HeadPose:
    """A closed-form pose of ``shape`` (V, 3) mm, head frame, for ``points`` (V, 3) (x, y px,
    z relative depth px): the weak-perspective similarity (Umeyama 1991) between the shape and
    the points, its scale read as focal length over depth."""
    p = np.asarray(points, dtype=np.float64)
    z = p[:, 2] if np.isfinite(p[:, 2]).all() else np.zeros(len(p))
    dst = np.column_stack([p[:, 0] - camera.cx, camera.cy - p[:, 1], -z])
    s, r, t = fit_similarity_3d(shape, dst)
    if not s > 0:
        raise MyofaceValueError("degenerate landmarks: cannot place the head")
    d = camera.focal_px / s
    # the shape's centroid projects to where the points' centroid is, at depth d
    c = shape.mean(axis=0)
    pc = s * r @ c + t  # px, at the centroid
    centroid_cam = np.array([pc[0] * d / camera.focal_px, pc[1] * d / camera.focal_px, -d])
    return HeadPose(r, centroid_cam - r @ c)


def rotvec(rot: np.ndarray) -> np.ndarray:
    """The rotation vector (3,) rad of a rotation matrix (the logarithm map). (In Python's
    floats: the fit calls it for a 3 x 3 matrix at every step, where numpy's calls cost more
    than the arithmetic.)"""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = np.asarray(rot, dtype=np.float64).tolist()
    cos = min(max((r00 + r11 + r22 - 1.0) / 2.0, -1.0), 1.0)
    angle = math.acos(cos)
    axis = (r21 - r12, r02 - r20, r10 - r01)
    if angle < 1e-6:
        return np.array([0.5 * a for a in axis])
    if angle > np.pi - 1e-6:
        return Rotation.from_matrix(rot).as_rotvec()
    k = angle / (2.0 * math.sin(angle))
    return np.array([a * k for a in axis])


def rotation_angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    """The angle (degrees) of the rotation that takes rotation ``b`` (3, 3) to ``a``."""
    return float(np.degrees(np.linalg.norm(rotvec(np.asarray(a) @ np.asarray(b).T))))


def rotmat(v: np.ndarray) -> np.ndarray:
    """The rotation matrix of a rotation vector (Rodrigues' formula)."""
    # (in Python's floats, R = cos I + sin [a]x + (1 - cos) a a^T for the unit axis a: the fit
    # calls it at every step, where numpy's calls on 3 x 3 arrays cost more than the work)
    x, y, z = (float(c) for c in v)
    angle = math.sqrt(x * x + y * y + z * z)
    if angle < 1e-9:
        return np.array([[1.0, -z, y], [z, 1.0, -x], [-y, x, 1.0]])
    x, y, z = x / angle, y / angle, z / angle
    c, s = math.cos(angle), math.sin(angle)
    t = 1.0 - c
    return np.array([
        [c + t * x * x, t * x * y - s * z, t * x * z + s * y],
        [t * x * y + s * z, c + t * y * y, t * y * z - s * x],
        [t * x * z - s * y, t * y * z + s * x, c + t * z * z],
    ])  # fmt: skip
