"""Automatic initialisation from a face landmark detector (optional: MediaPipe).

MediaPipe's legacy face mesh (``mediapipe==0.10.14``, ``solutions.face_mesh``; Kartynnik et al.
2019, "Real-time Facial Surface Geometry from Monocular Video on Mobile GPUs") ships its models
inside the wheel and runs offline. Its 468 points have the topology of myoface's default face
(both are the MediaPipe canonical face), so every section contour of
:data:`~myoface.analysis.sections.SECTIONS` is read off the detected points by the same vertex
indices as on the model. Install it with ``pip install "myoface[mediapipe]"``.

The hairline is left out of the automatic contours: the face mesh ends on the forehead, below
the real hairline, so its top row does not lie on an image edge.
"""

from __future__ import annotations

import copy

import numpy as np

from myoface.analysis.sections import section_vertices
from myoface.errors import MyofaceValueError
from myoface.facemesh import FaceMeshDetector
from myoface.render import progress

#: sections the automatic initialisation provides
AUTO_SECTIONS = (
    "eyebrow_r",
    "eyebrow_l",
    "nasolabial_r",
    "nasolabial_l",
    "nose",
    "lips",
    "chin",
)


def contours_from_landmarks(face, points, sections=AUTO_SECTIONS) -> dict[str, np.ndarray]:
    """Section contours (pixels) from detected points sharing ``face``'s topology."""
    p = np.asarray(points, dtype=np.float64)
    if p.ndim != 2 or p.shape[0] != face.n_vertices or p.shape[1] < 2:
        raise MyofaceValueError(
            f"the landmarks must be ({face.n_vertices}, 2|3) points of the face's topology; "
            f"got shape {p.shape}"
        )
    return {s: p[section_vertices(face, s), :2].copy() for s in sections}


def auto_init(
    frames,
    face,
    max_search: int | None = None,
    *,
    show_progress: bool = False,
    total: int | None = None,
):
    """Find the first frame (of at most ``max_search``; default: all of them) with a face
    whose contours lie inside the frame, and return ``(index, frame, contours, points)``; a
    clear error when no face is found. ``show_progress``: a progress bar on stderr while the
    search goes on (``total``: the number of frames, when known)."""
    seen = 0
    with FaceMeshDetector(video=False) as det:
        bar = progress(
            None, total=total, desc="searching for a face", enabled=show_progress, unit="frame"
        )
        try:
            for k, frame in enumerate(frames):
                if max_search is not None and k >= max_search:
                    break
                seen += 1
                bar.update(1)
                pts = det.detect(frame)
                if pts is None:
                    continue
                conts = contours_from_landmarks(face, pts)
                h, w = np.shape(frame)[:2]
                allp = np.concatenate(list(conts.values()))
                if (
                    (allp >= 0).all()
                    and (allp[:, 0] <= w - 1).all()
                    and (allp[:, 1] <= h - 1).all()
                ):
                    return k, frame, conts, pts
        finally:
            bar.close()
    raise MyofaceValueError(
        f"no face found in the {seen} frames of the video searched (MediaPipe face mesh); "
        "is there a frontal face in it?"
    )


# ------------------------------------------------------------------ landmark tracking (option 3)


def rigid_vertices(model, fraction: float = 0.05) -> np.ndarray:
    """Skin vertices that no muscle moves by more than ``fraction`` of the largest motion any
    unit contraction causes (the head frame is fitted to them). Computed once per model."""

    def compute():
        rest = model.skin_vertices()
        moved = np.zeros(len(rest))
        for mid in model.ids:
            skin = model.skin_vertices(model.relax({mid: 1.0}).state)
            moved = np.maximum(moved, np.linalg.norm(skin - rest, axis=1))
        out = np.flatnonzero(moved < fraction * moved.max())
        out.flags.writeable = False
        return out

    return model.memo(("rigid", fraction), compute)


def fit_similarity(src: np.ndarray, dst: np.ndarray):
    """Least-squares similarity (complex scale s = scale * e^{i theta}, translations) with
    ``dst ~ s (src - src_mean) + dst_mean`` for (N, 2) point sets."""
    ms, md = src.mean(axis=0), dst.mean(axis=0)
    za = (src[:, 0] - ms[0]) + 1j * (src[:, 1] - ms[1])
    zb = (dst[:, 0] - md[0]) + 1j * (dst[:, 1] - md[1])
    den = np.vdot(za, za).real
    if den <= 0:
        raise MyofaceValueError("degenerate point set for the head frame")
    return np.vdot(za, zb) / den, ms, md


def similarity_affine(src: np.ndarray, dst: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`fit_similarity` as a matrix and an offset: ``dst ~ matrix @ src + offset``."""
    z, ms, md = fit_similarity(src, dst)
    mat = np.array([[z.real, -z.imag], [z.imag, z.real]])
    return mat, md - mat @ ms


def _apply_similarity(s, ms, md, pts):
    z = ((pts[:, 0] - ms[0]) + 1j * (pts[:, 1] - ms[1])) * s
    return np.stack([z.real + md[0], z.imag + md[1]], axis=1)


# ------------------------------------------------------------------ the tracker's offsets


#: the view directions of :class:`TrackerOffsets`' table: azimuth (the head turned left and
#: right) and elevation (up and down), degrees, of the camera seen from the head
OFFSET_AZIMUTHS_DEG = np.arange(-60.0, 60.1, 10.0)
OFFSET_ELEVATIONS_DEG = np.arange(-40.0, 40.1, 10.0)
#: the views over which :meth:`TrackerOffsets.spread` measures how far each point's offset
#: moves: a head turned as far as a person at a webcam turns it (the head-motion benchmark's
#: yaw +-30 and pitch +-15 deg)
SPREAD_AZIMUTH_DEG = 30.0
SPREAD_ELEVATION_DEG = 20.0


def view_angles(pose) -> tuple[float, float]:
    """The camera's direction seen from the head (``pose``: :class:`~myoface.analysis.camera.HeadPose`)
    as (azimuth, elevation) degrees in the head frame: (0, 0) frontal; the azimuth positive
    toward the head's +x, the elevation toward its +y."""
    u = pose.rotation.T @ (-np.asarray(pose.translation_mm, dtype=np.float64))
    u = u / max(float(np.linalg.norm(u)), 1e-9)
    return float(np.degrees(np.arctan2(u[0], u[2]))), float(np.degrees(np.arcsin(u[1])))


def view_rotation(azimuth_deg: float, elevation_deg: float) -> np.ndarray:
    """The head's rotation (head frame -> camera frame) that shows the camera at
    (``azimuth_deg``, ``elevation_deg``) (:func:`view_angles`), without roll: the head's
    +y as near the image's up as the view allows."""
    a, e = np.radians(azimuth_deg), np.radians(elevation_deg)
    u = np.array([np.cos(e) * np.sin(a), np.sin(e), np.cos(e) * np.cos(a)])
    x = np.cross([0.0, 1.0, 0.0], u)
    x /= np.linalg.norm(x)
    return np.array([x, np.cross(u, x), u])


def head_frame_offsets(err_px, pose, shape, camera) -> np.ndarray:
    """Image offsets ``err_px`` (V, 2+) px of the points ``shape`` (V, 3) mm, head frame,
    seen at ``pose`` through ``camera``, as offsets (V, 3) mm in the head frame, each
    perpendicular to the view at its point's depth (what :meth:`TrackerOffsets.correct`
    projects back)."""
    err = np.asarray(err_px, dtype=np.float64)
    depth = -pose.apply(shape)[:, 2:3]
    mm = err[:, :2] * depth / camera.focal_px
    cam = np.column_stack([mm[:, 0], -mm[:, 1], np.zeros(len(mm))])
    return cam @ pose.rotation  # camera frame -> head frame


class TrackerOffsets:
    """Where the landmark detector puts the points of *this* face relative to its true
    vertices, as a function of the view: measured once per view direction on the person's
    model (its own texture), rendered neutral by the fit's camera and read by the detector
    (``synthesis``: :class:`~myoface.analysis.synthesis.LandmarkSynthesis`), stored in the
    head frame (mm, perpendicular to the view) on a grid of view directions
    (:data:`OFFSET_AZIMUTHS_DEG` x :data:`OFFSET_ELEVATIONS_DEG`; a cell is rendered the first
    time a frame's view needs it, so a frontal video renders four), interpolated bilinearly
    and taken off each frame's points before the fit (:meth:`correct`).

    Why (issue 30, measured 2026-12-02 on the head-motion loop's degraded renders): given the
    true 3-D skin of every frame, the head pose that best fits MediaPipe's points is off by
    4.5 deg in pitch with the head still and 2.7 deg RMS with it moving (yaw read at 0.88 of
    the truth, pitch at 0.82): MediaPipe's points sit up to 9 mm from the true vertices
    (the forehead's top row read 6-8 mm low, the chin and the jaw's sides 5-9 mm high,
    2.7 mm RMS over the face, constant to 0.8 mm while the head is still), and no choice of
    landmark weights removes it (face oval left out: 4.5 deg; the nose alone: 4.8). Its
    offsets differ from face to face (the default face's: pitch bias 0.8 deg, pitch read at
    0.89), so a table learned on other faces cannot carry this face's; the person's own
    model, seen from each direction, can. With this table the pose from the true skin is
    off 1.3 deg (still) and 1.7 deg RMS (moving); on the clean render of the neutral frame
    the pitch goes from 3.1 to 0.4 deg. What it cannot see: the expression's own offsets
    (the table is of the neutral; analysis by synthesis measures those, at a render a
    frame), and whatever the camera's degradation adds (the degraded still frames keep about
    2 deg of pitch). Of the degradations, it is the room behind the head (measured
    2026-12-03, ``tools/headmotion_background.py``: the still head's calibration pitched 2.45
    deg off with every degradation, 1.05 with none but the texture's resampling, 2.49 with the
    room alone, 0.26-1.27 with blur, noise, H.264 or the moving light alone): MediaPipe places
    its points differently over another background. This table rendered over the same room
    takes the calibration's pitch to 1.25 deg (and the moving head's yaw from -1.69 to -0.88);
    over the video's first frame with the face inpainted (what an analysis could know), only
    part of it (the still head's pose 1.46 -> 1.14-1.29 deg RMS for hull margins 0-0.3), while
    the moving head's worst muscle got worse (0.287 -> 0.31-0.33): not adopted. What is
    done instead (2026-12-06, :attr:`~myoface.analysis.weights.FitSettings.detector_context`):
    the model laid over the calibration frames themselves, where the video's surroundings
    are what the detector sees around it, and the excess of its error there over the table's
    added to every view (:meth:`with_context`, measured by
    :meth:`~myoface.analysis.modelfit.ModelFit.measure_detector_context`, where the numbers
    are).

    This is the table of analysis by synthesis (:attr:`FitSettings.synthesis_rounds`) at the
    neutral, paid once per view instead of once per frame.
    """

    def __init__(self, synthesis, shape, camera, azimuths=OFFSET_AZIMUTHS_DEG,
                 elevations=OFFSET_ELEVATIONS_DEG):  # fmt: skip
        self.synthesis = synthesis
        self.shape = np.asarray(shape, dtype=np.float64)
        self.camera = camera
        self.azimuths = np.asarray(azimuths, dtype=np.float64)
        self.elevations = np.asarray(elevations, dtype=np.float64)
        #: {(i, j): (V, 3) head-frame offsets mm} of the cells rendered so far
        self.cells: dict[tuple[int, int], np.ndarray] = {}
        #: the distance (mm) the cells are rendered at: the first frame's
        self.depth_mm: float | None = None
        #: cells the detector found no face in (their offsets taken as zero)
        self.missed = 0
        #: (V, 3) mm, head frame, or None: the detector's offsets on the video's own frames
        #: beyond the table's, added at every view (:meth:`with_context`)
        self.context_mm: np.ndarray | None = None

    def with_context(self, context_mm) -> TrackerOffsets:
        """This table with ``context_mm`` (V, 3) mm, head frame (None: none), added to its
        offsets at every view: what the detector does on the video's frames that it does not on the table's
        renders (the room, hair and neck around the face; measured at the calibration by
        :meth:`~myoface.analysis.modelfit.ModelFit.measure_detector_context`). The new table
        shares this one's cells and detector."""
        out = copy.copy(self)
        out.context_mm = (
            None
            if context_mm is None
            else np.asarray(context_mm, dtype=np.float64).reshape(self.shape.shape)
        )
        return out

    @classmethod
    def of_textured_face(cls, face, shape, camera, size, tracking) -> TrackerOffsets | None:
        """The table for ``face`` (its own texture; None without one) seen through ``camera``
        in images of ``size`` (w, h) px, read by MediaPipe in ``tracking`` mode
        (:attr:`FitSettings.tracking`); ``shape``: the neutral (V, 3) mm, head frame. None
        where the renderer cannot take the camera (a principal point off the centre)."""
        from myoface.analysis.synthesis import LandmarkSynthesis

        if face.texture is None:
            return None
        try:
            syn = LandmarkSynthesis(face, camera, size, tracking=tracking)
        except MyofaceValueError:
            return None
        return cls(syn, shape, camera)

    def close(self) -> None:
        """Let the detector that reads the renders go."""
        self.synthesis.close()

    def _cell(self, i: int, j: int) -> np.ndarray:
        if (i, j) not in self.cells:
            from myoface.analysis.camera import HeadPose

            rot = view_rotation(self.azimuths[i], self.elevations[j])
            centre = self.shape.mean(axis=0)
            pose = HeadPose(rot, np.array([0.0, 0.0, -self.depth_mm]) - rot @ centre)
            err = self.synthesis.tracker_error(self.shape, pose)
            if err is None:
                self.missed += 1
                self.cells[(i, j)] = np.zeros_like(self.shape)
            else:
                self.cells[(i, j)] = head_frame_offsets(err, pose, self.shape, self.camera)
        return self.cells[(i, j)]

    def offsets(self, pose) -> np.ndarray:
        """(V, 3) mm, head frame: the detector's points less the true vertices at ``pose``'s
        view direction (clamped to the table's range)."""
        if self.depth_mm is None:
            self.depth_mm = float(np.linalg.norm(pose.translation_mm))
        az, el = view_angles(pose)
        fi = float(np.interp(az, self.azimuths, np.arange(len(self.azimuths))))
        fj = float(np.interp(el, self.elevations, np.arange(len(self.elevations))))
        i0 = min(int(fi), len(self.azimuths) - 2)
        j0 = min(int(fj), len(self.elevations) - 2)
        a, b = fi - i0, fj - j0
        out = np.zeros_like(self.shape)
        for di, dj, w in ((0, 0, (1 - a) * (1 - b)), (1, 0, a * (1 - b)), (0, 1, (1 - a) * b),
                          (1, 1, a * b)):  # fmt: skip
            if w > 1e-9:
                out += w * self._cell(i0 + di, j0 + dj)
        if self.context_mm is not None:
            out += self.context_mm
        return out

    def spread(self, pose, azimuth_deg: float = SPREAD_AZIMUTH_DEG,
               elevation_deg: float = SPREAD_ELEVATION_DEG) -> np.ndarray:  # fmt: skip
        """(V,) mm: how far the detector's offset at each point moves as the view changes,
        the RMS about their mean of :meth:`offsets`, each less its rigid part (the small
        rotation and translation of the face that fits it best), over the table's views within
        ``azimuth_deg`` and ``elevation_deg`` of frontal (rendered now where not yet; 35
        views by default, ~0.6 s at 640x480), at ``pose``'s distance. A point whose offset
        moves far with the view (the jaw line and the chin, which MediaPipe slides along the
        face's outline as the head turns) is one whose correction is only as good as the
        table at the frame's view (its grid, its interpolation, the one read per cell, and
        the camera the table does not see): :func:`~myoface.analysis.weights.offset_spread_weights`."""
        if self.depth_mm is None:
            self.depth_mm = float(np.linalg.norm(pose.translation_mm))
        from myoface.analysis.camera import HeadPose

        centre = self.shape.mean(axis=0)
        # a small rigid motion of the face (rotation w, translation t): w x X + t = A (w, t)
        x = self.shape - centre
        a = np.zeros((len(x), 3, 6))
        a[:, :, 3:] = np.eye(3)
        a[:, 0, 1], a[:, 0, 2] = x[:, 2], -x[:, 1]
        a[:, 1, 0], a[:, 1, 2] = -x[:, 2], x[:, 0]
        a[:, 2, 0], a[:, 2, 1] = x[:, 1], -x[:, 0]
        a = a.reshape(-1, 6)
        offs = []
        for az in self.azimuths[np.abs(self.azimuths) <= azimuth_deg + 1e-9]:
            for el in self.elevations[np.abs(self.elevations) <= elevation_deg + 1e-9]:
                rot = view_rotation(az, el)
                view = HeadPose(rot, np.array([0.0, 0.0, -self.depth_mm]) - rot @ centre)
                off = self.offsets(view)
                # less its rigid part (the face read turned or shifted as a whole: the pose
                # takes it, it is no point's own)
                rigid = a @ np.linalg.lstsq(a, off.ravel(), rcond=None)[0]
                offs.append(off - rigid.reshape(-1, 3))
        offs = np.asarray(offs)
        return np.sqrt(((offs - offs.mean(axis=0)) ** 2).sum(axis=2).mean(axis=0))

    def correct(self, points, pose, shape) -> np.ndarray:
        """``points`` (V, 3; x, y px) with the detector's offsets at ``pose`` taken off x, y:
        each offset projected by the camera at ``shape`` (V, 3) mm, head frame, seen at
        ``pose``. z is left as it is."""
        off = self.offsets(pose)
        out = np.array(points, dtype=np.float64, copy=True)
        shift = self.camera.project(pose.apply(shape + off)) - self.camera.project(
            pose.apply(shape)
        )
        out[:, :2] -= shift
        return out
