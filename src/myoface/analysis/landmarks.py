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

import contextlib
import os
import sys
import warnings

import numpy as np

from myoface.errors import MyofaceDependencyError, MyofaceValueError

PIP_HINT = 'pip install "myoface[mediapipe]"   (mediapipe==0.10.14)'
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


@contextlib.contextmanager
def _quiet_native_stderr():
    """Silence the native (C++) log lines MediaPipe and TensorFlow Lite print to the process's
    stderr while they set up (``INFO: Created TensorFlow Lite XNNPACK delegate``, ...)."""
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):  # no real stderr (e.g. captured): nothing to silence
        yield
        return
    try:
        with open(os.devnull, "w") as null:
            os.dup2(null.fileno(), 2)
            yield
    finally:
        os.dup2(saved, 2)
        os.close(saved)


def _import_mediapipe():
    os.environ.setdefault("GLOG_minloglevel", "2")
    os.environ.setdefault("TF_CPP_MIN_LOG_LEVEL", "2")
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            import mediapipe as mp
            from mediapipe.python.solutions import face_mesh
    except ImportError as exc:
        raise MyofaceDependencyError(
            f"automatic initialisation needs MediaPipe's face mesh, which is not installed "
            f"({exc}); install it with: {PIP_HINT}, or give the contours with --init"
        ) from None
    # MediaPipe 0.10 calls a protobuf API that protobuf deprecates, on every frame. The
    # per-call catch_warnings of FaceMeshDetector.detect does not hold while other threads
    # (decoding ahead, the deferred relax) change the warning filters: filter it for good
    warnings.filterwarnings(
        "ignore", message=r"SymbolDatabase\.GetPrototype\(\) is deprecated", category=UserWarning
    )
    return mp, face_mesh


def mediapipe_available() -> bool:
    try:
        _import_mediapipe()
    except MyofaceDependencyError:
        return False
    return True


class FaceMeshDetector:
    """MediaPipe's face mesh on RGB frames: :meth:`detect` gives (468, 3) points, x and y in
    pixels (column, row), z in pixels towards the camera negative; or None without a face.

    ``video=True`` tracks between successive frames (MediaPipe's own tracking mode), which is
    faster on a video; ``video=False`` detects on every frame independently.
    """

    def __init__(self, video: bool = False, min_confidence: float = 0.5):
        _, face_mesh = _import_mediapipe()
        with warnings.catch_warnings(), _quiet_native_stderr():
            warnings.simplefilter("ignore")
            self._fm = face_mesh.FaceMesh(
                static_image_mode=not video,
                max_num_faces=1,
                refine_landmarks=False,
                min_detection_confidence=min_confidence,
                min_tracking_confidence=min_confidence,
            )
            # start the graph now (its threads log as they start), inside the silenced window
            self._fm.process(np.zeros((64, 64, 3), dtype=np.uint8))

    def detect(self, frame) -> np.ndarray | None:
        img = np.asarray(frame)
        if img.ndim == 2:
            img = np.repeat(img[:, :, None], 3, axis=2)
        if img.ndim != 3 or img.shape[2] not in (3, 4):
            raise MyofaceValueError(f"a frame must be (H, W) or (H, W, 3); got {img.shape}")
        img = np.ascontiguousarray(img[:, :, :3])
        if img.dtype != np.uint8:
            scale = 255.0 if img.max() <= 1.0 else 1.0
            img = np.clip(img * scale, 0, 255).astype(np.uint8)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = self._fm.process(img)
        if not res.multi_face_landmarks:
            return None
        h, w = img.shape[:2]
        lm = res.multi_face_landmarks[0].landmark
        pts = np.array([(p.x, p.y, p.z) for p in lm], dtype=np.float64)[:468]
        return pts * np.array([w, h, w])

    def close(self) -> None:
        self._fm.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


#: frames the face mesh is run ahead of the analysis on a thread of its own
#: (:func:`detect_ahead`): MediaPipe works without the GIL (its graph runs on threads of its
#: own), so on a second core it tracks the next frames while this one is fitted; a few
#: frames absorb the jitter between the two (a frame's fit costs more where a relax of the
#: tissue is taken up)
DETECT_AHEAD_FRAMES = 8


def detect_ahead(items, detect, depth: int = DETECT_AHEAD_FRAMES):
    """Yield ``(item, detect(item))`` for the items of ``items`` in order, ``detect`` run on
    a worker thread up to ``depth`` items ahead of the consumer (the thread calls it
    in order: a detector in video mode tracks from one frame to the next). Its exceptions are
    raised here, in order. Closing the generator (stopping early, an exception in the
    consumer) stops the thread and waits for it, and closes ``items`` if it is a generator.
    """
    import queue
    import threading

    if depth < 1:
        raise MyofaceValueError(f"depth must be >= 1; got {depth}")
    q: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()
    done = object()

    def put(entry) -> bool:
        while not stop.is_set():
            try:
                q.put(entry, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def produce():
        it = iter(items)
        try:
            for item in it:
                if stop.is_set() or not put((True, (item, detect(item)))):
                    return
            put((True, done))
        except BaseException as exc:  # handed to the consumer
            put((False, exc))
        finally:
            close = getattr(it, "close", None)
            if close is not None:
                close()

    worker = threading.Thread(target=produce, name="myoface-detect", daemon=True)
    worker.start()
    try:
        while True:
            ok, entry = q.get()
            if not ok:
                raise entry
            if entry is done:
                return
            yield entry
    finally:
        stop.set()
        worker.join()


def contours_from_landmarks(face, points, sections=AUTO_SECTIONS) -> dict[str, np.ndarray]:
    """Section contours (pixels) from detected points sharing ``face``'s topology."""
    from myoface.analysis.sections import section_vertices

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
    from myoface.render import progress

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


class LandmarkAnalyzer:
    """The analysis loop with MediaPipe's face mesh as the feature tracker instead of snakes.

    Beyond the paper: the detector gives every frame the 468 points of the default face's
    topology, so the fiducials are read at the very vertices the estimator's forward model
    uses (no sliding along contours). The head frame is the similarity (translation, scale,
    in-plane rotation) that best maps the current frame's rigid points (vertices that no
    muscle moves, :func:`rigid_vertices`) onto the calibration frame's. Frames without a face
    are reported (``quality="no_face"``) with empty values; the calibration frame is the first
    frame with a face.

    ``measure(frame, index, time_s)`` returns the same
    :class:`~myoface.analysis.tracker.FrameMeasurement` as the snake
    :class:`~myoface.analysis.pipeline.Analyzer`; its contours are the sections read off the
    detected points (for the overlay).
    """

    tracker = "landmarks"

    def __init__(self, model, muscle_ids=None, refine: int = 1, detector=None):
        from myoface.analysis.estimate import ContractionEstimator
        from myoface.analysis.sections import PAPER_MUSCLES, SECTIONS, model_fiducials

        if model.face.n_vertices != 468:
            raise MyofaceValueError(
                "the landmark tracker needs a face model with MediaPipe's 468-point topology "
                f"(the default face); this one has {model.face.n_vertices} vertices"
            )
        self.model = model
        self.refine = int(refine)
        self.ids = tuple(PAPER_MUSCLES if muscle_ids is None else muscle_ids)
        self.sections = [s for s in SECTIONS if s != "hairline"]
        self.fiducials = [
            f for f in model_fiducials(model.face) if not f.name.startswith(("hairline", "nose"))
        ]
        self.estimator = ContractionEstimator(model, self.fiducials, self.ids)
        self.rigid = rigid_vertices(model)
        self.detector = detector if detector is not None else FaceMeshDetector(video=True)
        self.mm_per_px = None
        self._ref = None  # calibration points (468, 2)
        self._p0 = None

    def measure(self, frame, index: int = 0, time_s: float = 0.0):
        from myoface.analysis.tracker import FrameMeasurement

        pts = self.detector.detect(frame)
        nan = np.full(len(self.ids), np.nan)
        if pts is None:  # (before a face is seen, calibration waits for the first face)
            return FrameMeasurement(index, time_s, "no_face", nan, np.full(2, np.nan), {}, 0)
        xy = pts[:, :2]
        contours = contours_from_landmarks(self.model.face, xy, self.sections)
        if self._ref is None:
            self._ref = xy.copy()
            model_xy = self.model.face.vertices[:, :2] * np.array([1.0, -1.0])
            s, _, _ = fit_similarity(xy, model_xy)
            self.mm_per_px = float(abs(s))
            self._p0 = self.estimator.weights @ xy
        # the current frame mapped into the calibration frame by its rigid points
        s, ms, md = fit_similarity(xy[self.rigid], self._ref[self.rigid])
        cal = _apply_similarity(s, ms, md, xy)
        d_mm = (self.estimator.weights @ cal - self._p0) * self.mm_per_px * np.array([1.0, -1.0])
        c = self.estimator.estimate(d_mm, refine=self.refine)
        # head motion (calibration -> current): the rigid points' centroid shift, and the
        # scale and rotation of the inverse map
        inv = 1.0 / s
        head_t = ms - md
        return FrameMeasurement(
            index,
            time_s,
            "ok",
            c,
            np.asarray(head_t, dtype=np.float64),
            contours,
            0,
            float(abs(inv)),
            float(np.angle(inv)),
        )

    def close(self) -> None:
        self.detector.close()
