"""Reading face video: a movie file (mp4, mov, avi, mkv, webm ... through PyAV) or a folder of
images (png, jpg, bmp, tif; sorted by name), frame by frame, as (H, W, 3) uint8 RGB arrays."""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from myoface._threads import run_ahead
from myoface.errors import MyofaceFileNotFoundError, MyofaceFormatError, MyofaceValueError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
#: frame rate assumed for a folder of images (there is no clock in a folder)
FOLDER_FPS = 30.0


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
    """A video source. Iterate to get frames; ``fps``, ``size`` = (width, height) and
    ``n_frames`` (None when the container does not say) describe it."""

    path: Path
    fps: float
    size: tuple[int, int]
    n_frames: int | None
    _files: list[Path] | None = None

    def __iter__(self) -> Iterator[np.ndarray]:
        if self._files is not None:
            import imageio.v3 as iio

            for f in self._files:
                try:
                    img = iio.imread(f)
                except Exception as exc:  # imageio raises many types for a bad image
                    raise MyofaceFormatError(f"cannot read image {f}: {exc}") from None
                yield _rgb(img, str(f))
            return
        yield from run_ahead(self._decoded(), depth=PREFETCH_FRAMES, name="myoface-decode")

    def _decoded(self) -> Iterator[np.ndarray]:
        import av

        try:
            with av.open(str(self.path)) as container:
                stream = container.streams.video[0]
                stream.thread_type = "AUTO"
                for frame in container.decode(stream):
                    yield frame.to_ndarray(format="rgb24")
        except av.error.FFmpegError as exc:
            raise MyofaceFormatError(f"cannot decode video {self.path}: {exc}") from None

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
    except av.error.FFmpegError as exc:
        raise MyofaceFormatError(f"{p}: not a readable video ({exc})") from None
    if not fps > 0:
        raise MyofaceFormatError(f"{p}: the video has no frame rate")
    if size[0] <= 0 or size[1] <= 0:
        raise MyofaceFormatError(f"{p}: the video has no picture size")
    return Video(p, fps, size, n)


def check_frame(frame: np.ndarray, name: str = "frame") -> np.ndarray:
    """Validate one frame (H, W) or (H, W, 3|4), any numeric dtype -> (H, W, 3) uint8."""
    f = np.asarray(frame)
    if f.size == 0:
        raise MyofaceValueError(f"{name} is empty")
    return _rgb(f, name)
