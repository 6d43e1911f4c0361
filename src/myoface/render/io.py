"""Writing images (PNG) and videos (MP4), atomically, with a progress bar for long renders."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from myoface._io import atomic_output
from myoface.errors import MyofaceValueError

VIDEO_SUFFIXES = (".mp4", ".mov", ".mkv", ".avi")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


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


class VideoWriter:
    """Write frames to an MP4 (H.264 via PyAV) as a context manager; the file appears only when
    the block completes without error.

    >>> with VideoWriter("out.mp4", fps=30) as vw:   # doctest: +SKIP
    ...     vw.write(frame)
    """

    def __init__(self, path: str | os.PathLike, fps: float = 30.0, quality_crf: int = 18):
        self.path = Path(path)
        if self.path.suffix.lower() not in VIDEO_SUFFIXES:
            raise MyofaceValueError(
                f"video files must end in {', '.join(VIDEO_SUFFIXES)}; got {self.path.name}"
            )
        if not (np.isfinite(fps) and 0 < fps <= 240):
            raise MyofaceValueError(f"fps must be in (0, 240]; got {fps}")
        self.fps = float(fps)
        self.crf = int(quality_crf)
        self.n_frames = 0
        self._ctx = None
        self._container = None
        self._stream = None
        self._size = None

    def __enter__(self) -> VideoWriter:
        self._ctx = atomic_output(self.path)
        self._tmp = self._ctx.__enter__()
        return self

    def write(self, frame: np.ndarray) -> None:
        import av

        img = _check_image(frame)
        h, w = img.shape[:2]
        if self._container is None:
            # H.264 in yuv420p needs even sizes
            self._size = (w - w % 2, h - h % 2)
            if min(self._size) < 2:
                raise MyofaceValueError(f"frames must be at least 2x2 pixels; got {w}x{h}")
            from fractions import Fraction

            self._container = av.open(str(self._tmp), mode="w")
            rate = Fraction(self.fps).limit_denominator(1001)
            self._stream = self._container.add_stream("libx264", rate=rate)
            self._stream.width, self._stream.height = self._size
            self._stream.pix_fmt = "yuv420p"
            self._stream.options = {"crf": str(self.crf), "preset": "veryfast"}
        elif (w - w % 2, h - h % 2) != self._size:
            raise MyofaceValueError(
                f"all frames must have the same size; got {w}x{h} after {self._size}"
            )
        sw, sh = self._size
        vf = av.VideoFrame.from_ndarray(np.ascontiguousarray(img[:sh, :sw]), format="rgb24")
        for packet in self._stream.encode(vf):
            self._container.mux(packet)
        self.n_frames += 1

    def __exit__(self, exc_type, exc, tb):
        try:
            if self._container is not None:
                if exc_type is None:
                    for packet in self._stream.encode():
                        self._container.mux(packet)
                self._container.close()
            if exc_type is None and self.n_frames == 0:
                raise MyofaceValueError(f"no frames were written to {self.path}")
        except BaseException as err:
            self._ctx.__exit__(type(err), err, err.__traceback__)
            raise
        return self._ctx.__exit__(exc_type, exc, tb)


def progress(iterable, total: int | None = None, desc: str = "", enabled: bool = True):
    """A tqdm progress bar on stderr (silent when ``enabled`` is False)."""
    from tqdm.auto import tqdm

    return tqdm(
        iterable,
        total=total,
        desc=desc,
        disable=not enabled,
        unit="frame",
        leave=False,
        mininterval=0.5,
    )
