"""Cylindrical range and colour maps of a head: the layout of a Cyberware-type scan.

A map samples a head on a cylinder around a vertical axis: column ``j`` is an angle around the
axis, row ``i`` a height, and each cell holds the radius (mm) of the outermost surface point met by
the horizontal ray from the axis at that angle and height, with the surface colour registered to
it. References: Terzopoulos & Waters 1993, Section IV (512 x 256 maps of the Cyberware scanner).

Layout (all of myoface)
-----------------------
- Head frame: +y up, +z out of the face, subject's left at +x; millimetres.
- Angle ``theta_rad = atan2(x - axis_x, z - axis_z)``: 0 in front of the face (+z), increasing
  towards the subject's left (+x), in [-pi, pi). Column ``j`` (of ``W``) is centred on
  ``theta = -pi + 2 pi (j + 0.5) / W``; seen as an image, the face looks like a photo of it.
- Height: row ``i`` (of ``H``) is centred on ``y = y_top_mm - (i + 0.5) * dy`` with
  ``dy = (y_top_mm - y_bottom_mm) / H``: row 0 is the top of the head, as in an image.
- ``radius_mm`` (H, W) float32 with NaN where the ray met no surface (a hole); ``rgb`` (H, W, 3)
  uint8, registered cell for cell (black in holes).

Files: ``.npz`` with arrays ``radius_mm``, ``rgb`` and a JSON string ``meta`` (axis_x_mm,
axis_z_mm, y_top_mm, y_bottom_mm, format version, and the head's 68 iBUG landmarks in the maps'
frame as ``landmarks_mm`` or null); or a folder with ``range.png`` (16-bit
grey, radius in units of 0.01 mm, 0 = hole), ``rgb.png`` and ``maps.json`` (the same meta).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numba
import numpy as np

from myoface._io import atomic_output
from myoface.errors import (
    MyofaceFileNotFoundError,
    MyofaceFormatError,
    MyofaceValueError,
    user_message,
)
from myoface.face.image import read_image
from myoface.face.mesh import MAX_COORDINATE_MM

#: map size of the Cyberware scanner the paper used (W angles x H heights), T&W 1993 §IV
CYBERWARE_SHAPE = (256, 512)
#: radius resolution of the 16-bit PNG layout: 0.01 mm (radii up to 655 mm)
PNG_RADIUS_STEP_MM = 0.01
FORMAT_VERSION = 1


@dataclass(eq=False)
class CylindricalMaps:
    """A registered pair of cylindrical maps: radius (range) and colour.

    Parameters
    ----------
    radius_mm : (H, W) float ndarray — radius of the surface per cell, NaN in holes.
    rgb : (H, W, 3) uint8 ndarray — colour registered to ``radius_mm``.
    axis_x_mm, axis_z_mm : float — where the vertical axis crosses the horizontal plane.
    y_top_mm, y_bottom_mm : float — heights of the top edge of row 0 and the bottom edge of the
        last row (``y_top_mm > y_bottom_mm``).
    landmarks_mm : (68, 3) float ndarray, optional — the head's iBUG-68 landmarks in the maps'
        frame, when they were known as the maps were made.
    """

    radius_mm: np.ndarray
    rgb: np.ndarray
    axis_x_mm: float = 0.0
    axis_z_mm: float = 0.0
    y_top_mm: float = 1.0
    y_bottom_mm: float = 0.0
    landmarks_mm: np.ndarray | None = None

    def __post_init__(self):
        r = np.asarray(self.radius_mm, dtype=np.float32)
        if r.ndim != 2 or min(r.shape) < 2:
            raise MyofaceValueError(f"radius_mm must be an (H, W) array; got shape {r.shape}")
        rgb = np.asarray(self.rgb)
        if rgb.shape != (*r.shape, 3):
            raise MyofaceValueError(
                f"the colour map must have the range map's size {r.shape[1]}x{r.shape[0]} "
                f"(W x H) with 3 channels; got shape {rgb.shape}"
            )
        if rgb.dtype != np.uint8:
            raise MyofaceValueError(f"the colour map must be uint8; got {rgb.dtype}")
        if np.any(r[np.isfinite(r)] < 0) or np.isinf(r).any():
            raise MyofaceValueError("radii must be >= 0 (NaN marks a hole)")
        if not self.y_top_mm > self.y_bottom_mm:
            raise MyofaceValueError(
                f"y_top_mm must be above y_bottom_mm; got {self.y_top_mm} <= {self.y_bottom_mm}"
            )
        self.radius_mm, self.rgb = r, rgb
        if self.landmarks_mm is not None:
            lm = np.asarray(self.landmarks_mm, dtype=np.float64)
            if lm.shape != (68, 3):
                raise MyofaceValueError(f"landmarks_mm must be (68, 3); got {lm.shape}")
            self.landmarks_mm = lm

    # ----------------------------------------------------------------- geometry
    @property
    def shape(self) -> tuple[int, int]:
        """(H, W): heights x angles."""
        return self.radius_mm.shape

    @property
    def dy_mm(self) -> float:
        return (self.y_top_mm - self.y_bottom_mm) / self.shape[0]

    @property
    def holes(self) -> np.ndarray:
        """(H, W) bool: cells where the ray met no surface."""
        return np.isnan(self.radius_mm)

    def to_cells(self, theta_rad, y_mm) -> tuple[np.ndarray, np.ndarray]:
        """Continuous (row, col) cell coordinates of angles and heights (cell centres integral)."""
        h, w = self.shape
        col = (np.asarray(theta_rad) + np.pi) * w / (2 * np.pi) - 0.5
        row = (self.y_top_mm - np.asarray(y_mm)) / self.dy_mm - 0.5
        return row, col

    def from_cells(self, row, col) -> tuple[np.ndarray, np.ndarray]:
        """Angles (rad) and heights (mm) of continuous (row, col) cell coordinates."""
        h, w = self.shape
        theta = (np.asarray(col) + 0.5) * 2 * np.pi / w - np.pi
        y = self.y_top_mm - (np.asarray(row) + 0.5) * self.dy_mm
        return theta, y

    def to_cylindrical(self, points_mm: np.ndarray) -> np.ndarray:
        """(N, 3) points -> (N, 3) columns (theta_rad, y_mm, radius_mm) about this map's axis."""
        p = np.asarray(points_mm, dtype=np.float64)
        dx, dz = p[:, 0] - self.axis_x_mm, p[:, 2] - self.axis_z_mm
        return np.column_stack([np.arctan2(dx, dz), p[:, 1], np.hypot(dx, dz)])

    def to_cartesian(self, theta_rad, y_mm, radius_mm) -> np.ndarray:
        """Angles, heights and radii -> (N, 3) points in the head frame (mm)."""
        t, r = np.asarray(theta_rad, float), np.asarray(radius_mm, float)
        return np.column_stack(
            [
                self.axis_x_mm + r * np.sin(t),
                np.asarray(y_mm, float),
                self.axis_z_mm + r * np.cos(t),
            ]
        )

    def sample_radius(self, theta_rad, y_mm) -> np.ndarray:
        """Radius (mm) at angles/heights, bilinear over the valid cells of the four around
        (angle wraps around); NaN only where all four are holes."""
        row, col = self.to_cells(theta_rad, y_mm)
        r = self.radius_mm.astype(np.float64)[..., None]
        valid = np.isfinite(r)
        num = _bilinear(np.where(valid, r, 0.0), row, col)[..., 0]
        den = _bilinear(valid.astype(np.float64), row, col)[..., 0]
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(den > 1e-9, num / np.maximum(den, 1e-12), np.nan)

    def uv_of(self, theta_rad, y_mm) -> np.ndarray:
        """Texture coordinates (N, 2) into :attr:`rgb` (v = 0 at the bottom row's edge)."""
        u = (np.asarray(theta_rad) + np.pi) / (2 * np.pi)
        v = (np.asarray(y_mm) - self.y_bottom_mm) / (self.y_top_mm - self.y_bottom_mm)
        return np.column_stack([u, v])

    def points(self) -> np.ndarray:
        """(H*W, 3) surface points of every cell (NaN rows in holes)."""
        h, w = self.shape
        row, col = np.mgrid[0:h, 0:w]
        t, y = self.from_cells(row.ravel(), col.ravel())
        return self.to_cartesian(t, y, self.radius_mm.ravel())

    def filled(self, max_hole_cells: int = 64) -> CylindricalMaps:
        """A copy with small holes (connected, at most ``max_hole_cells`` cells, not touching the
        top or bottom row) filled by harmonic interpolation of the radius and colour around them.
        """
        from scipy import ndimage

        hole = self.holes
        lab, n = ndimage.label(hole)
        if n == 0:
            return self
        sizes = ndimage.sum_labels(hole, lab, np.arange(1, n + 1))
        edge = set(np.unique(lab[[0, -1]])) - {0}
        small = [k + 1 for k in range(n) if sizes[k] <= max_hole_cells and k + 1 not in edge]
        fill = np.isin(lab, small)
        if not fill.any():
            return self
        r = self.radius_mm.astype(np.float64)
        rgb = self.rgb.astype(np.float64)
        r[fill] = np.nanmean(r)
        known = ~hole
        for _ in range(400):  # Jacobi sweeps of the Laplace equation inside the small holes
            for arr in (r, rgb):
                nb = (
                    np.roll(arr, 1, 1)
                    + np.roll(arr, -1, 1)
                    + _shift_rows(arr, 1)
                    + _shift_rows(arr, -1)
                ) / 4
                arr[fill] = nb[fill]
        r[~known & ~fill] = np.nan
        return CylindricalMaps(
            r.astype(np.float32),
            np.clip(rgb, 0, 255).round().astype(np.uint8),
            self.axis_x_mm,
            self.axis_z_mm,
            self.y_top_mm,
            self.y_bottom_mm,
            self.landmarks_mm,
        )

    # ----------------------------------------------------------------- files
    def meta(self) -> dict:
        return {
            "format": "myoface cylindrical maps",
            "version": FORMAT_VERSION,
            "axis_x_mm": float(self.axis_x_mm),
            "axis_z_mm": float(self.axis_z_mm),
            "y_top_mm": float(self.y_top_mm),
            "y_bottom_mm": float(self.y_bottom_mm),
            "landmarks_mm": None if self.landmarks_mm is None else self.landmarks_mm.tolist(),
        }

    def save(self, path: str | os.PathLike) -> Path:
        """Write ``path.npz`` (one file) or, for a path without suffix, a folder of PNGs."""
        path = Path(path)
        if path.suffix.lower() == ".npz":
            with atomic_output(path) as tmp:
                with open(tmp, "wb") as fh:
                    np.savez_compressed(
                        fh, radius_mm=self.radius_mm, rgb=self.rgb, meta=json.dumps(self.meta())
                    )
            return path
        if path.suffix:
            raise MyofaceValueError(f"maps are saved as .npz or as a folder; got {path}")
        import imageio.v3 as iio

        r = self.radius_mm
        if np.nanmax(r) / PNG_RADIUS_STEP_MM >= 65535:
            raise MyofaceValueError("radii above 655 mm do not fit the 16-bit PNG layout")
        rng = np.where(np.isnan(r), 0, np.maximum(np.round(r / PNG_RADIUS_STEP_MM), 1))
        path.mkdir(parents=True, exist_ok=True)
        with atomic_output(path / "range.png") as tmp:
            iio.imwrite(tmp, rng.astype(np.uint16))
        with atomic_output(path / "rgb.png") as tmp:
            iio.imwrite(tmp, self.rgb)
        with atomic_output(path / "maps.json") as tmp:
            tmp.write_text(json.dumps(self.meta(), indent=1) + "\n")
        return path


def load_maps(path: str | os.PathLike) -> CylindricalMaps:
    """Read maps written by :meth:`CylindricalMaps.save` (``.npz`` or a folder of PNGs)."""
    path = Path(path)
    if not path.exists():
        raise MyofaceFileNotFoundError(f"no such maps file or folder: {path}")
    try:
        if path.is_dir():
            import imageio.v3 as iio

            for name in ("range.png", "rgb.png", "maps.json"):
                if not (path / name).is_file():
                    raise MyofaceFormatError(f"{path} has no {name}: not a maps folder")
            rng = iio.imread(path / "range.png")
            rgb = read_image(path / "rgb.png", "colour map")
            meta = json.loads((path / "maps.json").read_text())
            radius = np.where(rng == 0, np.nan, rng.astype(np.float64) * PNG_RADIUS_STEP_MM)
        else:
            with np.load(path, allow_pickle=False) as z:
                missing = {"radius_mm", "rgb", "meta"} - set(z.files)
                if missing:
                    raise MyofaceFormatError(f"{path}: not a maps file (missing {sorted(missing)})")
                radius, rgb, meta = z["radius_mm"], z["rgb"], json.loads(str(z["meta"]))
    except (OSError, ValueError, KeyError) as exc:
        if isinstance(exc, MyofaceFormatError):
            raise
        raise MyofaceFormatError(f"cannot read maps from {path}: {user_message(exc)}") from None
    radius = np.asarray(radius)
    if radius.dtype.kind == "f":
        with np.errstate(invalid="ignore"):
            far = radius > MAX_COORDINATE_MM
        if far.any():
            raise MyofaceFormatError(
                f"{path}: a radius of {float(radius[far].max()):.3g} mm; a head's maps have radii "
                f"within {MAX_COORDINATE_MM:.0f} mm (1 km). Are they in millimetres?"
            )
    try:
        return CylindricalMaps(
            radius,
            rgb,
            float(meta["axis_x_mm"]),
            float(meta["axis_z_mm"]),
            float(meta["y_top_mm"]),
            float(meta["y_bottom_mm"]),
            meta.get("landmarks_mm"),
        )
    except KeyError as exc:
        raise MyofaceFormatError(f"{path}: maps meta lacks {exc}") from None
    except MyofaceValueError as exc:
        raise MyofaceFormatError(f"{path}: {exc}") from None


def _shift_rows(a: np.ndarray, k: int) -> np.ndarray:
    """Rows shifted by k with the edge row repeated (no wrap in height)."""
    out = np.roll(a, k, 0)
    if k > 0:
        out[:k] = a[:1]
    else:
        out[k:] = a[-1:]
    return out


def _bilinear(img: np.ndarray, row, col) -> np.ndarray:
    """Bilinear lookup in (H, W, C) at continuous cells; columns wrap, rows clamp."""
    h, w = img.shape[:2]
    row = np.clip(np.asarray(row, float), 0, h - 1)
    col = np.asarray(col, float)
    r0 = np.minimum(np.floor(row).astype(np.int64), h - 2)
    c0 = np.floor(col).astype(np.int64)
    fr, fc = (row - r0)[:, None], (col - c0)[:, None]
    c0w, c1w = c0 % w, (c0 + 1) % w
    return (
        img[r0, c0w] * (1 - fr) * (1 - fc)
        + img[r0, c1w] * (1 - fr) * fc
        + img[r0 + 1, c0w] * fr * (1 - fc)
        + img[r0 + 1, c1w] * fr * fc
    )


# --------------------------------------------------------------------------- ray casting


@numba.njit(cache=True)
def _cast_kernel(verts, tris, theta, h, w, y_top, dy, radius, tri_id, bary):
    two_pi = 2.0 * np.pi
    for f in range(tris.shape[0]):
        a, b, c = tris[f, 0], tris[f, 1], tris[f, 2]
        t0, t1, t2 = theta[a], theta[b], theta[c]
        tmin = min(t0, t1, t2)
        tmax = max(t0, t1, t2)
        shift = 0.0
        if tmax - tmin > np.pi:  # straddles the seam behind the head: unwrap
            t0 = t0 + two_pi if t0 < 0 else t0
            t1 = t1 + two_pi if t1 < 0 else t1
            t2 = t2 + two_pi if t2 < 0 else t2
            tmin = min(t0, t1, t2)
            tmax = max(t0, t1, t2)
            shift = 1.0
        ymin = min(verts[a, 1], verts[b, 1], verts[c, 1])
        ymax = max(verts[a, 1], verts[b, 1], verts[c, 1])
        r_lo = max(0, int(np.ceil((y_top - ymax) / dy - 0.5)))
        r_hi = min(h - 1, int(np.floor((y_top - ymin) / dy - 0.5)))
        c_lo = int(np.ceil((tmin + np.pi) * w / two_pi - 0.5))
        c_hi = int(np.floor((tmax + np.pi) * w / two_pi - 0.5))
        if r_lo > r_hi or c_lo > c_hi:
            continue
        e1x = verts[b, 0] - verts[a, 0]
        e1y = verts[b, 1] - verts[a, 1]
        e1z = verts[b, 2] - verts[a, 2]
        e2x = verts[c, 0] - verts[a, 0]
        e2y = verts[c, 1] - verts[a, 1]
        e2z = verts[c, 2] - verts[a, 2]
        for col in range(c_lo, c_hi + 1):
            th = (col + 0.5) * two_pi / w - np.pi
            dx, dz = np.sin(th), np.cos(th)
            cw = col % w if shift > 0 else col
            if cw < 0 or cw >= w:
                continue
            # Moller-Trumbore with direction (dx, 0, dz) from (0, y, 0)
            px = -dz * e2y  # d x e2 = (dy*e2z - dz*e2y, dz*e2x - dx*e2z, dx*e2y - dy*e2x), dy=0
            py = dz * e2x - dx * e2z
            pz = dx * e2y
            det = e1x * px + e1y * py + e1z * pz
            if abs(det) < 1e-12:
                continue
            inv = 1.0 / det
            for row in range(r_lo, r_hi + 1):
                yy = y_top - (row + 0.5) * dy
                sx = -verts[a, 0]
                sy = yy - verts[a, 1]
                sz = -verts[a, 2]
                u = (sx * px + sy * py + sz * pz) * inv
                if u < -1e-9 or u > 1 + 1e-9:
                    continue
                qx = sy * e1z - sz * e1y
                qy = sz * e1x - sx * e1z
                qz = sx * e1y - sy * e1x
                v = (dx * qx + dz * qz) * inv
                if v < -1e-9 or u + v > 1 + 1e-9:
                    continue
                t = (e2x * qx + e2y * qy + e2z * qz) * inv
                if t > 0 and (np.isnan(radius[row, cw]) or t > radius[row, cw]):
                    radius[row, cw] = t
                    tri_id[row, cw] = f
                    bary[row, cw, 0] = u
                    bary[row, cw, 1] = v


def cast_rays(
    vertices: np.ndarray,
    triangles: np.ndarray,
    shape: tuple[int, int],
    y_top_mm: float,
    y_bottom_mm: float,
    axis_x_mm: float = 0.0,
    axis_z_mm: float = 0.0,
):
    """Cast the map's horizontal rays from the axis and keep the outermost hit per cell.

    Returns ``radius_mm`` (H, W) (NaN where nothing was hit), ``tri_id`` (H, W) int (-1 there) and
    ``bary`` (H, W, 2): the barycentric weights of the hit's 2nd and 3rd triangle vertex.
    """
    h, w = shape
    v = np.asarray(vertices, np.float64) - np.array([axis_x_mm, 0.0, axis_z_mm])
    tris = np.ascontiguousarray(triangles, dtype=np.int64)
    theta = np.arctan2(v[:, 0], v[:, 2])
    radius = np.full((h, w), np.nan)
    tri_id = np.full((h, w), -1, np.int64)
    bary = np.zeros((h, w, 2))
    dy = (y_top_mm - y_bottom_mm) / h
    _cast_kernel(np.ascontiguousarray(v), tris, theta, h, w, y_top_mm, dy, radius, tri_id, bary)
    return radius, tri_id, bary


def maps_from_mesh(
    face,
    shape: tuple[int, int] = CYBERWARE_SHAPE,
    *,
    axis_x_mm: float | None = None,
    axis_z_mm: float | None = None,
    margin_mm: float = 2.0,
) -> CylindricalMaps:
    """Range and colour maps of a head mesh by ray casting around a vertical axis.

    Parameters
    ----------
    face : FaceMesh — the head in the head frame (+y up); its texture and uv, if any, colour the
        RGB map (grey otherwise).
    shape : (H, W) — heights x angles (default the paper's 256 x 512).
    axis_x_mm, axis_z_mm : where the axis stands (default: the centre of the mesh's x/z bounds).
    margin_mm : extra height above and below the mesh.
    """
    v = face.vertices
    h, w = (int(s) for s in shape)
    if h < 8 or w < 8:
        raise MyofaceValueError(f"map shape must be at least 8 x 8; got {shape}")
    lo, hi = v.min(0), v.max(0)
    ax = 0.5 * (lo[0] + hi[0]) if axis_x_mm is None else float(axis_x_mm)
    az = 0.5 * (lo[2] + hi[2]) if axis_z_mm is None else float(axis_z_mm)
    y_top, y_bot = hi[1] + margin_mm, lo[1] - margin_mm
    radius, tri_id, bary = cast_rays(v, face.triangles, (h, w), y_top, y_bot, ax, az)
    rgb = np.zeros((h, w, 3), np.uint8)
    hit = tri_id >= 0
    if face.uv is not None and face.texture is not None and hit.any():
        t = face.triangles[tri_id[hit]]
        b1, b2 = bary[hit, 0:1], bary[hit, 1:2]
        uv = face.uv[t[:, 0]] * (1 - b1 - b2) + face.uv[t[:, 1]] * b1 + face.uv[t[:, 2]] * b2
        th, tw = face.texture.shape[:2]
        tex = face.texture.astype(np.float64)
        col = uv[:, 0] * tw - 0.5
        row = (1 - uv[:, 1]) * th - 0.5
        # texture images do not wrap: clamp both ways
        col = np.clip(col, 0, tw - 1.001)
        c = _bilinear(tex, row, col)
        rgb[hit] = np.clip(np.round(c), 0, 255).astype(np.uint8)
    else:
        rgb[hit] = 180
    return CylindricalMaps(radius.astype(np.float32), rgb, ax, az, y_top, y_bot)
