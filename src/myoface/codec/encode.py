"""A face video to a ``.myo`` stream (``myoface encode``): the analysis' 3-D fit
(:class:`~myoface.analysis.trackers.landmark_fit.FitTracker`: head pose, every contraction with
the jaw and the lids, the eyes' gaze) frame by frame, each frame's parameters quantised and
range-coded (:mod:`myoface.codec.entropy`) and written as soon as it is measured
(:class:`~myoface.codec.stream.StreamWriter`).

The header needs the calibration frame (its picture, its parameters), which the tracker picks
among the first seconds (the most neutral; :data:`~myoface.analysis.modelfit.CALIBRATION_WINDOW_S`):
the frames before it are held until it is measured, then the header and their packets are
written; from there each packet is written as its frame is measured.

:class:`VideoParams` is the analysis side (a video in, :class:`~myoface.codec.params.FrameParams`
out, and the :class:`Setup` the header is made of); :func:`encode_params` is the stream side
(any frames' parameters and a setup in, a stream out), so that parameters analysed once can be
coded at several qualities (the benchmark does).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from myoface.analysis.camera import PinholeCamera
from myoface.analysis.potentials import LUMA_601
from myoface.codec.entropy import DEFAULT_QUALITY, QUALITIES
from myoface.codec.params import FrameParams
from myoface.codec.stream import (
    SEGMENT_FRAMES,
    Header,
    StreamWriter,
    decode_image,
    encode_image,
    ids_checksum,
    image_codecs,
)
from myoface.errors import MyofaceValueError

#: the identity offsets' grid, in pixels of the picture at the face's distance: the
#: person's neutral differs from the default face's by a few mm, and what the receiver sees
#: of it is the warp of the picture, so the grid is set in its pixels (the offsets within a
#: fifth of a pixel). Measured at the default quality: the sample video (1.0 px a mm: a
#: 0.39 mm grid) 336 bytes where 0.1 mm took 668, the decoded face's PSNR-Y 26.65 dB against
#: 26.58; the head-motion renders (1.3 px a mm: 0.31 mm) 340 bytes fewer, 23.64 dB against
#: 23.72
IDENTITY_STEP_PX = 0.4
#: ... within these bounds (mm)
IDENTITY_STEP_RANGE_MM = (0.05, 1.0)


def identity_step_mm(camera: PinholeCamera, calibration: FrameParams) -> float:
    """The identity offsets' grid (mm) for a picture seen by ``camera`` with the head at
    ``calibration``'s pose: :data:`IDENTITY_STEP_PX` pixels at the head's distance."""
    depth = max(-float(calibration.translation[2]), 1.0)
    step = IDENTITY_STEP_PX * depth / float(camera.focal_px)
    return float(np.clip(step, *IDENTITY_STEP_RANGE_MM))


@dataclass
class Setup:
    """What the header is made of (:func:`make_header`).

    Attributes
    ----------
    width, height : px. fps : frames/s.
    camera : the analysis' camera.
    ids : the model's contraction ids.
    identity_mm : (V, 3) the person's neutral minus the default face's, head frame, mm.
    calibration_index : the calibration frame's index among the stream's frames.
    calibration : its parameters.
    picture : (H, W, 3) uint8, the calibration frame.
    n_frames_hint : the frames expected (0: not known).
    """

    width: int
    height: int
    fps: float
    camera: PinholeCamera
    ids: tuple
    identity_mm: np.ndarray
    calibration_index: int
    calibration: FrameParams
    picture: np.ndarray
    n_frames_hint: int = 0


def psnr_y(a: np.ndarray, b: np.ndarray, mask: np.ndarray | None = None) -> float:
    """PSNR (dB) of the luma (BT.601) of RGB images ``a`` against ``b``, over ``mask``
    (bool (H, W); None: the whole frame)."""
    w = np.asarray(LUMA_601)
    ya = np.asarray(a, dtype=np.float64) @ w
    yb = np.asarray(b, dtype=np.float64) @ w
    d = (ya - yb) ** 2
    mse = float(d[mask].mean() if mask is not None else d.mean())
    return float("inf") if mse == 0 else float(10 * np.log10(255.0**2 / mse))


def compress_picture(rgb: np.ndarray, target_db: float, codecs=None) -> tuple[str, bytes, dict]:
    """The smallest encoding of ``rgb`` whose PSNR-Y reaches ``target_db``, among ``codecs``
    (default: those Pillow has of WebP, AVIF, JPEG), each at the lowest quality (0-100,
    bisected) that reaches it (its highest when none does; then the best PSNR wins).
    Returns the codec, the bytes and, per codec tried, ``{"quality", "bytes", "psnr_db"}``."""
    tried: dict = {}
    for codec in codecs or image_codecs():
        lo, hi = 1, 100
        best = None
        while lo <= hi:
            q = (lo + hi) // 2
            data = encode_image(rgb, codec, q)
            db = psnr_y(decode_image(data, codec, rgb.shape[1::-1]), rgb)
            if db >= target_db:
                best = (q, data, db)
                hi = q - 1
            else:
                lo = q + 1
        if best is None:
            data = encode_image(rgb, codec, 100)
            best = (100, data, psnr_y(decode_image(data, codec, rgb.shape[1::-1]), rgb))
        tried[codec] = {"quality": best[0], "bytes": len(best[1]), "psnr_db": round(best[2], 2),
                        "data": best[1]}  # fmt: skip
    reached = [c for c, t in tried.items() if t["psnr_db"] >= target_db]
    if reached:
        codec = min(reached, key=lambda c: tried[c]["bytes"])
    else:
        codec = max(tried, key=lambda c: tried[c]["psnr_db"])
    data = tried[codec]["data"]
    report = {c: {k: v for k, v in t.items() if k != "data"} for c, t in tried.items()}
    return codec, data, report


def make_header(setup: Setup, quality: str = DEFAULT_QUALITY, image_codec: str | None = None,
                segment_frames: int = SEGMENT_FRAMES) -> tuple[Header, dict]:  # fmt: skip
    """The stream's header for ``setup`` at ``quality`` (:data:`QUALITIES`), its picture
    compressed by :func:`compress_picture` (``image_codec``: that codec only); and the
    picture's report."""
    if quality not in QUALITIES:
        raise MyofaceValueError(f"quality must be one of {tuple(QUALITIES)}; got {quality!r}")
    steps, target_db = QUALITIES[quality]
    codecs = None if image_codec is None else [image_codec]
    if image_codec is not None and image_codec not in image_codecs():
        raise MyofaceValueError(
            f"--image-codec {image_codec}: this Pillow has only {', '.join(image_codecs())}"
        )
    codec, data, report = compress_picture(setup.picture, target_db, codecs)
    ident_step = identity_step_mm(setup.camera, setup.calibration)
    h = Header(
        width=setup.width, height=setup.height, fps=float(setup.fps),
        n_frames_hint=int(setup.n_frames_hint), quality=quality, steps=steps,
        segment_frames=int(segment_frames), camera=setup.camera, face="default",
        ids_crc=ids_checksum(setup.ids), n_contractions=len(setup.ids),
        calibration_index=int(setup.calibration_index), calibration=setup.calibration,
        identity_mm=setup.identity_mm, identity_step_mm=ident_step, background=0,
        image_codec=codec, image=data,
    )  # fmt: skip
    parts = {"picture": len(data), "identity": identity_bytes(h)}
    return h, {"codec": codec, "target_psnr_db": target_db, "tried": report, "parts": parts}


def identity_bytes(h: Header) -> int:
    """The bytes of ``h``'s identity field (its range-coded offsets)."""
    from myoface.codec.stream import _pack_identity

    q = np.clip(np.round(h.identity_mm / h.identity_step_mm), -32767, 32767).astype(np.int64)
    return len(_pack_identity(q, h.face))


@dataclass
class EncodeStats:
    """What an encode wrote: header and body bytes, frames, the decoder's parameters of each
    frame (``decoded``, when kept), the picture's report and the wall time."""

    header_bytes: int = 0
    body_bytes: int = 0
    n_frames: int = 0
    picture: dict = field(default_factory=dict)
    decoded: list = field(default_factory=list)
    seconds: float = 0.0
    interrupted: bool = False
    #: the packets' bits by group of channels (:meth:`~myoface.codec.entropy.ParamCoder.channel_bits`)
    channel_bits: dict = field(default_factory=dict)

    @property
    def bits_per_frame(self) -> float:
        return 8.0 * self.body_bytes / max(1, self.n_frames)

    @property
    def total_bytes(self) -> int:
        return self.header_bytes + self.body_bytes + 12  # (the trailer)


def encode_params(fh, frames, setup_of, quality: str = DEFAULT_QUALITY,
                  image_codec: str | None = None, keep_decoded: bool = False,
                  stats: EncodeStats | None = None, images=None) -> EncodeStats:  # fmt: skip
    """Write a stream of ``frames`` (an iterable of FrameParams) to ``fh``.

    ``setup_of()`` gives the :class:`Setup` (None while it is not known yet: the frames
    before it are held, then written after the header). ``images``: the frames' pictures
    ((H, W, 3) uint8, an iterable read in step with ``frames``): each measured frame's
    appearance terms (the inside of the mouth, the face's shading:
    :data:`~myoface.codec.params.APPEARANCE_FIELDS`) are then fitted on its picture against
    what the decoder renders from its quantised parameters
    (:meth:`~myoface.codec.picture.PictureModel.estimate_appearance`); None: the frames' own
    (zeros: the calibration picture's look); a :class:`VideoParams` given as ``frames`` gives
    its own (:meth:`VideoParams.pictures`). The stream is closed (end marker, trailer) when
    ``frames`` ends, and also when it is interrupted (KeyboardInterrupt: the stream is then
    complete with the frames written; ``stats.interrupted``)."""
    from myoface._signals import deferred, held, interrupt_in

    stats = stats or EncodeStats()
    t0 = time.perf_counter()
    held_frames: list = []
    writer: StreamWriter | None = None
    receiver = None
    if images is None and isinstance(frames, VideoParams):
        images = frames.pictures()
    pictures = None if images is None else iter(images)

    def start():
        nonlocal writer, receiver
        setup = setup_of()
        header, report = make_header(setup, quality, image_codec)
        writer = StreamWriter(fh, header)
        stats.header_bytes = writer.header_bytes
        stats.picture = report
        if pictures is not None:
            from myoface.codec.decode import picture_model_of

            receiver = picture_model_of(writer.header)[2]

    def put(p, img):
        fit = None
        if receiver is not None and img is not None:

            def fit(base):
                return receiver.estimate_appearance(receiver.render(base), img)

        with deferred():  # (a frame's packet is written whole)
            out = writer.write(p, fit)
        if keep_decoded:
            stats.decoded.append(out)

    def picture_of(p):
        img = None if pictures is None else next(pictures, None)
        return img if p.measured else None

    try:
        for p in frames:
            img = picture_of(p)
            if writer is None:
                held_frames.append((p, None if img is None else np.array(img, copy=True)))
                if setup_of() is None:
                    continue
                start()
                for q, qi in held_frames:
                    put(q, qi)
                held_frames = []
            else:
                put(p, img)
    except BaseException as err:
        # (a stop signal, also one wrapped in a SystemError by a C callback it landed in)
        if interrupt_in(err) is None:
            raise
        stats.interrupted = True
        if writer is None:
            raise
        with held():
            writer.close()
            stats.body_bytes, stats.n_frames = writer.body_bytes, writer.n_frames
            stats.seconds = time.perf_counter() - t0
        raise
    if writer is None:
        if setup_of() is None:
            raise MyofaceValueError("the analysis measured no calibration frame")
        start()
        for q, qi in held_frames:
            put(q, qi)
    writer.close()
    stats.body_bytes, stats.n_frames = writer.body_bytes, writer.n_frames
    stats.channel_bits = writer.coder.channel_bits()
    stats.seconds = time.perf_counter() - t0
    return stats


class VideoParams:
    """A video's frames' parameters by the analysis' 3-D fit (iterate them, in order); its
    :attr:`setup` once the calibration frame is measured (None before).

    ``calibration_frame``: the frame to calibrate on, where the stream then starts (None: the
    most neutral of the first seconds, the stream starting at frame 0); ``max_frames``: at
    most that many frames from the first."""

    def __init__(self, video, *, calibration_frame: int | None = None,
                 max_frames: int | None = None, show_progress: bool = False):  # fmt: skip
        from myoface.analysis.pipeline import Tracking, make_analyzer
        from myoface.analysis.video import open_video
        from myoface.model import build_face_model

        self.video = open_video(video) if not hasattr(video, "fps") else video
        self.model = build_face_model()
        self.tracker, first = make_analyzer(
            self.model, self.video, "landmarks", calibration_frame=calibration_frame
        )
        if calibration_frame is not None:
            # (the stream starts at its calibration frame: the decoder's header is that
            # frame's, and the frames before it would be held until it is measured)
            first = int(calibration_frame)
        self.run = Tracking(self.video, self.tracker, first, max_frames)
        self.max_frames = max_frames
        self.show_progress = show_progress
        self.setup: Setup | None = None
        self.start: int | None = None
        self.qualities: dict[str, int] = {}
        self.analysis_seconds = 0.0
        self._frame = None

    def pictures(self):
        """The picture of each frame, read in step with iterating this: each is the frame
        whose parameters were given last (an endless iterator; the encoder's fit of the
        appearance reads it, :func:`encode_params`)."""
        while True:
            yield self._frame

    def calibrate(self) -> int:
        self.start = self.run.calibrate()
        return self.start

    def __iter__(self):
        from myoface.render import progress

        tr = self.tracker
        t0 = time.perf_counter()
        try:
            self.calibrate()
            cal = tr.calibration_frame
            n = self.video.n_frames
            total = None if n is None else n - self.start
            if self.max_frames is not None and total is not None:
                total = min(total, self.max_frames)
            last = None
            it = progress(self.run, total=total, desc="encoding", enabled=self.show_progress)
            for frame, m in it:
                self._frame = frame
                p = FrameParams.from_measurement(m, last)
                self.qualities[m.quality] = self.qualities.get(m.quality, 0) + 1
                last = p
                if m.index == cal and self.setup is None:
                    self._set_up(frame, m, p)
                self.analysis_seconds = time.perf_counter() - t0
                yield p
        finally:
            tr.close()

    def _set_up(self, frame, m, p: FrameParams) -> None:
        tr = self.tracker
        fit = tr.fit
        h, w = np.shape(frame)[:2]
        calib = p.copy()
        if not p.measured:  # (the calibration frame was not measured: its fit's pose)
            pose = tr.calibration.pose
            calib = FrameParams(pose.rotation, pose.translation_mm,
                                np.zeros(len(tr.ids)), np.full(4, np.nan))  # fmt: skip
        n = self.video.n_frames
        self.setup = Setup(
            width=int(w), height=int(h),
            fps=float(self.video.fps) if self.video.fps else 30.0,
            camera=fit.camera, ids=tuple(tr.ids),
            identity_mm=np.asarray(fit.identity_mm, dtype=np.float64).copy(),
            calibration_index=int(m.index - self.start), calibration=calib,
            picture=np.ascontiguousarray(frame, dtype=np.uint8),
            n_frames_hint=_hint(n, self.start, self.max_frames),
        )  # fmt: skip


def _hint(n_video: int | None, start: int, max_frames: int | None) -> int:
    """The frames a stream expects: the video's from ``start``, at most ``max_frames``
    (0: not known)."""
    n = None if n_video is None else n_video - start
    if max_frames is not None:
        n = max_frames if n is None else min(n, max_frames)
    return 0 if n is None else int(n)
