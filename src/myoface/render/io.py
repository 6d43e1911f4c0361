"""Writing images (PNG) and videos (MP4), atomically, with a progress bar for long renders."""

from __future__ import annotations

import contextlib
import os
import queue
import threading
import time
from pathlib import Path

import numpy as np

from myoface._io import atomic_output
from myoface.errors import MyofaceValueError

VIDEO_SUFFIXES = (".mp4", ".mov", ".mkv", ".avi")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
#: libx264's presets, fastest first
X264_PRESETS = (
    "ultrafast",
    "superfast",
    "veryfast",
    "faster",
    "fast",
    "medium",
    "slow",
    "slower",
    "veryslow",
)
#: frames a background encoder holds at most (a 512x512 frame is 0.8 MB)
QUEUE_FRAMES = 4
_FLUSH = object()  # queue markers: finish the file / abandon it
_STOP = object()


def _cpu_has_avx512() -> bool:
    """Whether this CPU has the AVX-512 foundation that libx264 would use (numpy's own
    run-time CPU detection; False where numpy does not expose it or the CPU is not x86)."""
    try:
        from numpy._core._multiarray_umath import __cpu_features__
    except ImportError:  # an older or different numpy: leave x264's own detection alone
        return False
    return bool(__cpu_features__.get("AVX512F")) and bool(__cpu_features__.get("AVX2"))


def x264_params() -> dict[str, str]:
    """The libx264 options :class:`VideoWriter` adds to the rate control: on a CPU with
    AVX-512, x264's assembly is capped at AVX2 (``asm=AVX2``).

    Why: libx264's AVX-512 routines (x264 core 165, in the PyAV 17 and 18 wheels) make the
    bitstream depend on what was in memory before: in one process, encoding the same
    64x64 frames with the same settings 40 times gave 2-6 different files, more when other
    allocations came in between, while ``asm=AVX2``, ``asm=AVX`` and ``asm=SSE4.2`` gave one
    file every time (``ffmpeg``'s command line, a fresh process with fresh memory, was
    deterministic). The difference shows at small sizes (64x64, 96x64), which is what the
    tests encode. Capping costs about 1-4 % of the encoding time at 128-512 px. Any CPU
    with AVX-512 has AVX2, so the cap never asks for an instruction the CPU lacks."""
    return {"x264-params": "asm=AVX2"} if _cpu_has_avx512() else {}


def _check_image(image) -> np.ndarray:
    a = np.asarray(image)
    if a.ndim != 3 or a.shape[2] != 3 or a.dtype != np.uint8 or a.size == 0:
        raise MyofaceValueError(f"an image must be (H, W, 3) uint8; got {a.shape} {a.dtype}")
    return a


def write_image(path: str | os.PathLike, image: np.ndarray) -> Path:
    """Write an (H, W, 3) uint8 image (PNG or JPEG by suffix); nothing is left on failure."""
    import imageio.v3 as iio

    p = Path(path)
    if p.suffix.lower() not in IMAGE_SUFFIXES:
        raise MyofaceValueError(
            f"image files must end in {', '.join(IMAGE_SUFFIXES)}; got {p.name}"
        )
    img = _check_image(image)
    with atomic_output(p) as tmp:
        iio.imwrite(tmp, img)
    return p


def encoded_size(width: int, height: int) -> tuple[int, int]:
    """The (width, height) :class:`VideoWriter` encodes frames of this size at: the next even
    numbers (H.264 in yuv420p subsamples the colour 2 x 2)."""
    return _even_size(width, height)


def _even_size(w: int, h: int) -> tuple[int, int]:
    return (w + w % 2, h + h % 2)


def _pad_even(img: np.ndarray) -> np.ndarray:
    """``img`` (H, W, 3), contiguous, its last column and row repeated where W or H is odd."""
    h, w = img.shape[:2]
    if not (w % 2 or h % 2):
        return np.ascontiguousarray(img)
    ew, eh = _even_size(w, h)
    out = np.empty((eh, ew, 3), np.uint8)
    out[:h, :w] = img
    out[:h, w:] = img[:, -1:]
    out[h:] = out[h - 1 : h]
    return out


class VideoWriter:
    """Write frames to an MP4 (H.264 via PyAV) as a context manager; the file appears only when
    the block completes without error.

    >>> with VideoWriter("out.mp4", fps=30) as vw:   # doctest: +SKIP
    ...     vw.write(frame)

    Parameters
    ----------
    path : str or PathLike — ``.mp4``, ``.mov``, ``.mkv`` or ``.avi``.
    fps : float — frames per second, in (0, 240].
    quality_crf : int — libx264's constant rate factor (0-51; 18 is visually lossless).
    preset : str — libx264's speed/size trade-off (:data:`X264_PRESETS`); the default
        ``"veryfast"`` encodes a 512x512 frame in a few ms at about a third of the size
        ``"superfast"`` gives at the same ``quality_crf``.
    background : bool
        Encode in a background thread, so that the caller makes the next frame while this one
        is encoded (libx264 and the colour conversion run without the GIL). :meth:`write`
        then only copies the frame (the caller may reuse its array at once) and queues it; at
        most :data:`QUEUE_FRAMES` frames wait. An encoder error is raised by the next
        :meth:`write` or on leaving the block.

    The same frames always give the same file, whatever the process did before (libx264's
    AVX-512 code does not: :func:`x264_params`).

    H.264 (yuv420p) needs an even width and height: a frame of odd width or height is padded
    to the next even size by repeating its last column or row (nothing is cut off; the file
    is then one pixel wider or taller than the frames, :func:`encoded_size`).

    Attributes
    ----------
    n_frames : int — frames written so far.
    frame_size : (width, height) of the frames written (None before the first).
    encode_ms : list of float — per frame, the wall time (ms) its conversion to YUV and
        encoding took (in the background thread when ``background``).
    wait_ms : float — how long (ms) :meth:`write` waited for the background encoder in all
        (time the encoder, not the caller, was the bottleneck).
    """

    def __init__(
        self,
        path: str | os.PathLike,
        fps: float = 30.0,
        quality_crf: int = 18,
        *,
        preset: str = "veryfast",
        background: bool = False,
    ):
        self.path = Path(path)
        if self.path.suffix.lower() not in VIDEO_SUFFIXES:
            raise MyofaceValueError(
                f"video files must end in {', '.join(VIDEO_SUFFIXES)}; got {self.path.name}"
            )
        if not (np.isfinite(fps) and 0 < fps <= 240):
            raise MyofaceValueError(f"fps must be in (0, 240]; got {fps}")
        if not (isinstance(quality_crf, int | np.integer) and 0 <= quality_crf <= 51):
            raise MyofaceValueError(
                f"quality_crf must be an integer in [0, 51]; got {quality_crf!r}"
            )
        if preset not in X264_PRESETS:
            raise MyofaceValueError(f"preset must be one of {X264_PRESETS}; got {preset!r}")
        self.fps = float(fps)
        self.crf = int(quality_crf)
        self.preset = preset
        self.background = bool(background)
        self.n_frames = 0
        self.encode_ms: list[float] = []
        self.wait_ms = 0.0
        self._ctx = None
        self._container = None
        self._stream = None
        self._size = None
        self.frame_size = None
        self._queue = None
        self._thread = None
        self._error: BaseException | None = None

    def __enter__(self) -> VideoWriter:
        self._ctx = atomic_output(self.path)
        self._tmp = self._ctx.__enter__()
        return self

    def _open(self, w: int, h: int) -> None:
        import av

        if min(w, h) < 2:
            raise MyofaceValueError(f"frames must be at least 2x2 pixels; got {w}x{h}")
        self.frame_size = (w, h)
        self._size = _even_size(w, h)
        from fractions import Fraction

        self._container = av.open(str(self._tmp), mode="w")
        rate = Fraction(self.fps).limit_denominator(1001)
        self._stream = self._container.add_stream("libx264", rate=rate)
        self._stream.width, self._stream.height = self._size
        self._stream.pix_fmt = "yuv420p"
        # deterministic output: the same frames give the same file (see x264_params)
        self._stream.options = {"crf": str(self.crf), "preset": self.preset, **x264_params()}
        if self.background:
            self._queue = queue.Queue(maxsize=QUEUE_FRAMES)
            self._thread = threading.Thread(
                target=self._encode_loop, name="myoface-video-encoder", daemon=True
            )
            self._thread.start()

    def _encode(self, vf) -> None:
        """Encode one frame (``None``: flush the encoder) and mux its packets."""
        t0 = time.perf_counter()
        for packet in self._stream.encode(vf):
            self._container.mux(packet)
        if vf is not None:
            self.encode_ms.append((time.perf_counter() - t0) * 1e3)

    def _encode_loop(self) -> None:
        while True:
            vf = self._queue.get()
            if vf is _STOP or vf is _FLUSH:
                if vf is _FLUSH and self._error is None:
                    try:
                        self._encode(None)
                    except BaseException as err:  # handed to the caller's thread
                        self._error = err
                return
            if self._error is None:  # after an error, drain the queue so write() never blocks
                try:
                    self._encode(vf)
                except BaseException as err:
                    self._error = err

    def _raise_encoder_error(self) -> None:
        if self._error is not None:
            raise self._error

    def write(self, frame: np.ndarray) -> None:
        import av

        img = _check_image(frame)
        h, w = img.shape[:2]
        if self._container is None:
            self._open(w, h)
        elif (w, h) != self.frame_size:
            fw, fh = self.frame_size
            raise MyofaceValueError(
                f"all frames must have the same size; got {w}x{h} after {fw}x{fh}"
            )
        self._raise_encoder_error()
        # from_ndarray copies the pixels: the caller may reuse its array
        vf = av.VideoFrame.from_ndarray(_pad_even(img), format="rgb24")
        if self._queue is None:
            self._encode(vf)
        else:
            t0 = time.perf_counter()
            self._queue.put(vf)
            self.wait_ms += (time.perf_counter() - t0) * 1e3
        self.n_frames += 1

    def _finish_thread(self, ok: bool) -> None:
        if self._thread is not None:
            self._queue.put(_FLUSH if ok else _STOP)
            self._thread.join()
            self._thread = None

    def __exit__(self, exc_type, exc, tb):
        try:
            if self._container is not None:
                ok = exc_type is None
                if self._thread is not None:
                    self._finish_thread(ok)
                    if ok:
                        self._raise_encoder_error()
                elif ok:
                    self._encode(None)
                self._container.close()
            if exc_type is None and self.n_frames == 0:
                raise MyofaceValueError(f"no frames were written to {self.path}")
        except BaseException as err:
            self._finish_thread(False)
            if self._container is not None:
                with contextlib.suppress(Exception):
                    self._container.close()
            self._ctx.__exit__(type(err), err, err.__traceback__)
            raise
        return self._ctx.__exit__(exc_type, exc, tb)


def progress(
    iterable,
    total: int | None = None,
    desc: str = "",
    enabled: bool = True,
    unit: str = "frame",
):
    """A tqdm progress bar on stderr (silent when ``enabled`` is False); ``iterable`` None
    for a bar moved by its ``update()``."""
    from tqdm.auto import tqdm

    return tqdm(
        iterable,
        total=total,
        desc=desc,
        disable=not enabled,
        unit=unit,
        leave=False,
        mininterval=0.5,
    )
