"""What a webcam does to a rendered face: a moving light, a cluttered room, a lens, a sensor
and H.264 (:class:`CameraDegradation`).

Why: a benchmark that renders its truth with the renderer and the texture the tracker then
assumes, and hands the tracker those very pixels, measures the tracker on images no camera
makes (an *inverse crime*: the model that made the data is the model that reads it). A camera
adds what the renderer leaves out, in this order (:meth:`CameraDegradation.apply`):

1. the scene: the head composited over a procedural cluttered room (:func:`clutter`) wherever
   the render drew nothing (the render's coverage, :func:`coverage`, not a colour key: the
   renderer's studio background is a gradient), and lit by a light that moves (a shading field
   whose gradient turns across the frame) with the camera's auto-exposure hunting
   (a slow global gain drift);
2. the optics: a Gaussian blur (lens and defocus), and optionally a line (motion) blur;
3. the sensor: shot noise (Poisson, in the Gaussian limit) and read noise, in linear light;
4. the camera's output: sRGB 8 bits, H.264 (libx264, yuv420p) at a webcam stream's quality,
   decoded back (:func:`h264_round_trip`).

Everything is in linear light up to the sensor (light adds and multiplies there), then sRGB.
Deterministic for a given ``seed``: each stage draws from its own stream of
:class:`numpy.random.SeedSequence`, so turning one stage off leaves the others' draws alone.

Measured on 2026-12-01: the defaults add noise of 5.9 sRGB levels (2.3 % of full scale) on a
flat mid-grey frame before H.264 (tests/render/test_degrade.py); on the head-motion
benchmark's 90 frames (640x480, :mod:`myoface.bench.headmotion`) the H.264 stream runs at
0.9-1.05 Mbit/s and leaves 31.1 dB PSNR against the frames before it (it drops most of the
noise), and the whole degradation takes 4-6 s (2 cores).

OpenCV (``cv2``, which comes with MediaPipe) does the image work; it is imported when needed.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from myoface.errors import MyofaceValueError
from myoface.render.io import VideoWriter
from myoface.render.renderer import load_texture, to_srgb8

#: sRGB code (0-255) -> linear light, by the renderer's own conversion (:func:`load_texture`)
SRGB_TO_LINEAR = load_texture(np.arange(256, dtype=np.uint8).reshape(1, 256, 1))[0, :, 0]


def _cv2():
    from myoface.facemesh import import_opencv

    return import_opencv("the camera degradation (myoface.render.degrade)")


def _finite(name: str, value, lo: float, hi: float, hi_open: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise MyofaceValueError(f"{name} must be a number; got {value!r}") from None
    if not np.isfinite(v) or v < lo or v > hi or (hi_open and v == hi):
        bracket = ")" if hi_open else "]"
        raise MyofaceValueError(f"{name} must be in [{lo}, {hi}{bracket}; got {value!r}")
    return v


@dataclass(frozen=True)
class CameraDegradation:
    """A webcam's view of rendered frames; :meth:`apply` degrades a sequence.

    Parameters (defaults: a laptop webcam at 640x480, 30 fps, indoors)
    ----------
    light_amplitude : float, in [0, 0.5)
        Half range of the moving light's multiplicative shading field across the frame: the
        brightness runs from ``1 - a`` to ``1 + a`` (0.2: +-20 %, the brightness difference
        between the lit and the shadowed side of a frame under a desk lamp or a window, the
        range the head-motion issue asks for, +-15-25 %). 0: no shading field.
    light_turn_deg_per_s : float
        How fast the field's gradient turns (60: half a turn in 3 s, the 90 frames of the
        head-motion benchmark: a light, or the head in it, that moves slowly).
    exposure_drift : float, in [0, 0.5)
        Half range of a slow global gain, ``1 + e sin(2 pi t / period + phase)`` (0.08: a
        webcam's auto-exposure hunting, a few per cent to a tenth of the brightness). 0: none.
    exposure_period_s : float
        Period (s) of that drift (4 s: auto-exposure reacts over seconds, not frames).
    background : bool
        Composite the render over a procedural cluttered room (:func:`clutter`) where it drew
        nothing; :meth:`apply` then needs the renders' coverage (``alpha``).
    blur_sigma_px : float, in [0, 5]
        Gaussian blur (px): 1.0, a webcam's lens and its fixed focus at 640x480 (their edges
        spread over 2-3 px). 0: none.
    motion_blur_px : float, in [0, 20]
        Length (px) of a line blur along ``motion_blur_deg`` (camera shake during the
        exposure). 0 (default): none, the renders already move.
    motion_blur_deg : float
        Its direction in the image (deg, 0 = along x).
    full_scale_electrons : float or None
        Electrons at full scale after the sensor's gain (shot noise ``sqrt(n)``; None: no shot
        noise). 500: a small-pixel webcam sensor indoors runs at a high analogue gain, so
        full scale is a few hundred electrons; with the read noise below, the noise at
        mid-grey is 2.3 % of full scale in sRGB (measured: 5.9 of 255 levels), in the
        2-3 % the head-motion issue asks for.
    read_noise_electrons : float, >= 0
        Read noise (electrons RMS, at the same gain): 2.5, that of small CMOS pixels.
    crf : int or None
        libx264's constant rate factor for the H.264 round trip (None: no compression). 22: a
        webcam stream's bitrate, about 1 Mbit/s at 640x480 and 30 fps (measured on the
        head-motion benchmark's degraded frames: 0.9-1.05 Mbit/s; CRF 23 gave 0.44, 21 gave
        1.6, 28 gave 0.15 Mbit/s, the sensor's noise costing most of the bits below 23).
    fps : float, in (0, 240]
        The sequence's frame rate (time for the drifts, and the H.264 stream's rate).
    seed : int, >= 0
        The random streams' seed (clutter, light direction, exposure phase, noise).
    """

    light_amplitude: float = 0.2
    light_turn_deg_per_s: float = 60.0
    exposure_drift: float = 0.08
    exposure_period_s: float = 4.0
    background: bool = True
    blur_sigma_px: float = 1.0
    motion_blur_px: float = 0.0
    motion_blur_deg: float = 0.0
    full_scale_electrons: float | None = 500.0
    read_noise_electrons: float = 2.5
    crf: int | None = 22
    fps: float = 30.0
    seed: int = 0

    def __post_init__(self):
        _finite("light_amplitude", self.light_amplitude, 0.0, 0.5, hi_open=True)
        _finite("light_turn_deg_per_s", self.light_turn_deg_per_s, -3600.0, 3600.0)
        _finite("exposure_drift", self.exposure_drift, 0.0, 0.5, hi_open=True)
        if _finite("exposure_period_s", self.exposure_period_s, 0.0, 1e6) <= 0:
            raise MyofaceValueError(
                f"exposure_period_s must be positive; got {self.exposure_period_s!r}"
            )
        if not isinstance(self.background, bool | np.bool_):
            raise MyofaceValueError(f"background must be True or False; got {self.background!r}")
        _finite("blur_sigma_px", self.blur_sigma_px, 0.0, 5.0)
        _finite("motion_blur_px", self.motion_blur_px, 0.0, 20.0)
        _finite("motion_blur_deg", self.motion_blur_deg, -360.0, 360.0)
        if self.full_scale_electrons is not None:
            if _finite("full_scale_electrons", self.full_scale_electrons, 0.0, 1e9) < 1.0:
                raise MyofaceValueError(
                    "full_scale_electrons must be at least 1 (or None for no shot noise); "
                    f"got {self.full_scale_electrons!r}"
                )
        _finite("read_noise_electrons", self.read_noise_electrons, 0.0, 1e6)
        if self.read_noise_electrons > 0 and self.full_scale_electrons is None:
            raise MyofaceValueError(
                "read_noise_electrons is in electrons at full scale: it needs "
                "full_scale_electrons (or set it to 0)"
            )
        if self.crf is not None and not (
            isinstance(self.crf, int | np.integer)
            and not isinstance(self.crf, bool)
            and 0 <= self.crf <= 51
        ):
            raise MyofaceValueError(
                f"crf must be an integer in [0, 51] (or None: no H.264); got {self.crf!r}"
            )
        fps = _finite("fps", self.fps, 0.0, 240.0)
        if fps <= 0:
            raise MyofaceValueError(f"fps must be in (0, 240]; got {self.fps!r}")
        if not isinstance(self.seed, int | np.integer) or isinstance(self.seed, bool):
            raise MyofaceValueError(f"seed must be a non-negative integer; got {self.seed!r}")
        if self.seed < 0:
            raise MyofaceValueError(f"seed must be a non-negative integer; got {self.seed!r}")

    # ------------------------------------------------------------------ the stages
    def _streams(self) -> dict[str, np.random.Generator]:
        names = ("clutter", "light", "exposure", "noise")
        seqs = np.random.SeedSequence(int(self.seed)).spawn(len(names))
        return {n: np.random.default_rng(s) for n, s in zip(names, seqs, strict=True)}

    def light_field(self, k: int, size: tuple[int, int], angle0: float = 0.0) -> np.ndarray:
        """The multiplicative light (H, W) float32 of frame ``k`` for a frame of ``size`` =
        (width, height): ``1 + a (u cos t + v sin t)``, (u, v) the pixel's offset from the
        centre over the half diagonal (so the field stays in [1 - a, 1 + a]), its direction
        ``t = angle0 + turn * k / fps``, times the exposure gain (:meth:`exposure`) is what
        :meth:`apply` multiplies the linear frame by."""
        w, h = size
        half_diag = 0.5 * np.hypot(w - 1, h - 1) or 1.0
        u = ((np.arange(w) - (w - 1) / 2) / half_diag).astype(np.float32)
        v = ((np.arange(h) - (h - 1) / 2) / half_diag).astype(np.float32)
        t = angle0 + np.deg2rad(self.light_turn_deg_per_s) * k / self.fps
        a = np.float32(self.light_amplitude)
        return 1 + a * (np.cos(t) * u[None, :] + np.sin(t) * v[:, None])

    def exposure(self, k: int, phase: float = 0.0) -> float:
        """The global gain of frame ``k``: ``1 + e sin(2 pi k / (fps period) + phase)``."""
        t = k / self.fps
        return 1.0 + self.exposure_drift * np.sin(2 * np.pi * t / self.exposure_period_s + phase)

    def _blur(self, lin: np.ndarray) -> np.ndarray:
        cv2 = _cv2()
        if self.motion_blur_px > 0:
            n = int(np.ceil(self.motion_blur_px)) | 1
            kern = np.zeros((n, n), np.float32)
            c = (n - 1) / 2
            d = np.array([np.cos(np.deg2rad(self.motion_blur_deg)),
                          -np.sin(np.deg2rad(self.motion_blur_deg))])  # fmt: skip
            # a line of the given length through the centre, sampled finely
            for s in np.linspace(-self.motion_blur_px / 2, self.motion_blur_px / 2, 8 * n):
                x, y = c + s * d
                kern[int(round(y)), int(round(x))] += 1
            kern /= kern.sum()
            lin = cv2.filter2D(lin, -1, kern, borderType=cv2.BORDER_REFLECT)
        if self.blur_sigma_px > 0:
            lin = cv2.GaussianBlur(lin, (0, 0), self.blur_sigma_px, borderType=cv2.BORDER_REFLECT)
        return lin

    def _noise(self, lin: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        if self.full_scale_electrons is None:
            return lin
        fs = np.float32(self.full_scale_electrons)
        # Poisson in its Gaussian limit (n >> 1 electrons but in the deepest shadows), + read
        var = np.maximum(lin, 0) * fs + np.float32(self.read_noise_electrons) ** 2
        n = rng.standard_normal(lin.shape, dtype=np.float32)
        return lin + np.sqrt(var) / fs * n

    def apply(
        self,
        frames: Iterable[np.ndarray],
        alpha: Sequence[np.ndarray] | None = None,
        studio: np.ndarray | None = None,
        reader: Callable[[Path], Iterable[np.ndarray]] | None = None,
    ) -> list[np.ndarray]:
        """The frames (each (H, W, 3) uint8 sRGB, all one size) as the camera gives them.

        ``alpha``: per frame, the render's coverage (H, W) in [0, 1] (:func:`coverage`),
        needed with :attr:`background`: the clutter shows through ``1 - alpha``. ``studio``:
        the renderer's own background (H, W, 3) linear (:func:`studio_background`), taken out
        of the pixels at the silhouette that mix it with the head (without it those pixels
        keep a trace of it). ``reader``: decodes the H.264 file back (a path -> frames;
        default: PyAV), e.g. the analysis' own reader."""
        frames = [_check_frame(f, k) for k, f in enumerate(frames)]
        if not frames:
            raise MyofaceValueError("no frames to degrade")
        h, w = frames[0].shape[:2]
        for k, f in enumerate(frames):
            if f.shape[:2] != (h, w):
                raise MyofaceValueError(
                    f"all frames must have one size; frame {k} is {f.shape[1]}x{f.shape[0]}, "
                    f"frame 0 {w}x{h}"
                )
        if self.background:
            if alpha is None:
                raise MyofaceValueError(
                    "background=True needs the renders' coverage (alpha, see "
                    "myoface.render.degrade.coverage) to know where the room shows; "
                    "or set background=False"
                )
            alpha = list(alpha)
            if len(alpha) != len(frames):
                raise MyofaceValueError(
                    f"alpha must have one mask per frame; got {len(alpha)} for {len(frames)}"
                )
            if studio is not None:
                studio = np.asarray(studio, np.float32)
                if studio.shape != (h, w, 3):
                    raise MyofaceValueError(
                        f"studio must be ({h}, {w}, 3) linear RGB; got {studio.shape}"
                    )
        rng = self._streams()
        room = clutter((w, h), rng["clutter"]) if self.background else None
        angle0 = float(rng["light"].uniform(0, 2 * np.pi))
        phase = float(rng["exposure"].uniform(0, 2 * np.pi))
        out = []
        for k, f in enumerate(frames):
            lin = SRGB_TO_LINEAR[f]
            if room is not None:
                a = _check_alpha(alpha[k], (h, w), k)[:, :, None]
                if studio is not None:  # the render = a head + (1 - a) studio, head <= 1
                    lin = np.clip(lin - (1 - a) * studio, 0, a) + (1 - a) * room
                else:
                    lin = a * lin + (1 - a) * room
            gain = self.exposure(k, phase)
            if self.light_amplitude > 0 or gain != 1.0:
                lin = lin * (np.float32(gain) * self.light_field(k, (w, h), angle0))[:, :, None]
            lin = self._blur(np.ascontiguousarray(lin, np.float32))
            lin = self._noise(lin, rng["noise"])
            out.append(to_srgb8(lin))
        if self.crf is not None:
            out, _ = h264_round_trip(out, self.crf, self.fps, reader)
        return out


def _check_frame(f, k: int) -> np.ndarray:
    a = np.asarray(f)
    if a.ndim != 3 or a.shape[2] != 3 or a.dtype != np.uint8 or min(a.shape[:2]) < 2:
        raise MyofaceValueError(f"frame {k} must be (H, W, 3) uint8; got {a.shape} {a.dtype}")
    return a


def _check_alpha(a, shape, k: int) -> np.ndarray:
    m = np.asarray(a, np.float32)
    if m.shape != shape or not np.isfinite(m).all() or m.min() < 0 or m.max() > 1:
        raise MyofaceValueError(f"alpha {k} must be {shape} with values in [0, 1]; got {m.shape}")
    return m


def clutter(size: tuple[int, int], rng: np.random.Generator | int = 0) -> np.ndarray:
    """A procedural cluttered room (H, W, 3) float32 linear RGB for a frame of ``size`` =
    (width, height): a wall's gradient, shelves and frames (rectangles), lamps and plants
    (ellipses), cables and edges (lines), a fine fabric/wallpaper grain, slightly out of focus
    (the room is farther than the head: Gaussian sigma 1.2 px). Seeded (``rng``: a generator
    or a seed); no image is shipped."""
    cv2 = _cv2()
    rng = np.random.default_rng(rng) if not isinstance(rng, np.random.Generator) else rng
    w, h = size
    scale = np.hypot(w, h) / 800.0  # the shapes' sizes follow the frame's (800: 640x480)
    top, bottom = rng.uniform(0.08, 0.3) * rng.uniform(0.8, 1.2, 3), rng.uniform(0.03, 0.15, 3)
    rows = np.linspace(0, 1, h, dtype=np.float32)[:, None, None]
    img = np.ascontiguousarray(
        np.broadcast_to(top * (1 - rows) + bottom * rows, (h, w, 3)), np.float32
    )

    def colour():
        # a room's muted colours: a grey level, a little hue (indoor paint, wood, fabric)
        hue = rng.dirichlet((2, 2, 2)) * 3
        return tuple(float(c) for c in rng.uniform(0.01, 0.45) * (0.6 + 0.4 * hue))

    for _ in range(40):  # shelves, books, frames, posters, a window
        x0, y0 = int(rng.uniform(-0.1, 1) * w), int(rng.uniform(-0.1, 1) * h)
        x1 = x0 + int(rng.uniform(8, 160) * scale)
        y1 = y0 + int(rng.uniform(8, 160) * scale)
        cv2.rectangle(img, (x0, y0), (x1, y1), colour(), -1 if rng.random() < 0.7 else 3)
    for _ in range(15):  # lamps, plants, mugs
        c = (int(rng.uniform(0, w)), int(rng.uniform(0, h)))
        axes = (int(rng.uniform(5, 60) * scale), int(rng.uniform(5, 60) * scale))
        cv2.ellipse(img, c, axes, float(rng.uniform(0, 180)), 0, 360, colour(), -1)
    for _ in range(20):  # cables, edges of furniture
        p = (int(rng.uniform(0, w)), int(rng.uniform(0, h)))
        q = (int(rng.uniform(0, w)), int(rng.uniform(0, h)))
        cv2.line(img, p, q, colour(), int(rng.integers(1, 4)))
    grain = rng.standard_normal((h, w, 1), dtype=np.float32)
    img *= 1 + 0.08 * cv2.GaussianBlur(grain, (0, 0), 0.7)[:, :, None]
    img = cv2.GaussianBlur(img, (0, 0), 1.2)
    return np.clip(img, 0.0, 1.0).astype(np.float32)


def coverage(renderer) -> np.ndarray:
    """The last render's coverage (H, W) float32 in [0, 1] of a
    :class:`~myoface.render.Renderer`: the fraction of each pixel's supersamples on which it
    drew the head (skin, eyes, mouth; :meth:`~myoface.render.Renderer.triangle_ids`), 0
    where it drew only its background."""
    s = renderer.ssaa
    h, w = renderer.camera.height, renderer.camera.width
    drawn = renderer.triangle_ids() >= 0
    return drawn.reshape(h, s, w, s).mean(axis=(1, 3), dtype=np.float32)


def studio_background(renderer) -> np.ndarray:
    """The background (H, W, 3) float32 linear RGB a :class:`~myoface.render.Renderer`
    draws where there is no head (its studio gradient, averaged over each pixel's
    supersamples as its resolve does)."""
    s = renderer.ssaa
    h, w = renderer.camera.height, renderer.camera.width
    rows = np.asarray(renderer._background, np.float32).reshape(h, s, 3).mean(axis=1)
    return np.ascontiguousarray(np.broadcast_to(rows[:, None, :], (h, w, 3)))


def resample_texture(texture: np.ndarray, factor: float = 0.5) -> np.ndarray:
    """``texture`` (H, W, 3) uint8 at another resolution than the one it is stored at: down
    to ``factor`` of its size (area average) and back up (bilinear), same size, its detail
    finer than ``factor`` of its Nyquist frequency gone: what a tracker that assumes the
    stored texture sees when the face it watches has a coarser texture."""
    cv2 = _cv2()
    t = np.asarray(texture)
    if t.ndim != 3 or t.shape[2] != 3 or t.dtype != np.uint8:
        raise MyofaceValueError(f"texture must be (H, W, 3) uint8; got {t.shape} {t.dtype}")
    f = _finite("factor", factor, 0.0, 1.0)
    h, w = t.shape[:2]
    small = (max(1, int(round(w * f))), max(1, int(round(h * f))))
    if f <= 0 or small == (w, h):
        raise MyofaceValueError(
            f"factor must be in (0, 1) and change the size of a {w}x{h} texture; got {factor!r}"
        )
    down = cv2.resize(t, small, interpolation=cv2.INTER_AREA)
    return cv2.resize(down, (w, h), interpolation=cv2.INTER_LINEAR)


def _decode(path: Path) -> list[np.ndarray]:
    import av

    with av.open(str(path)) as container:
        return [f.to_ndarray(format="rgb24") for f in container.decode(video=0)]


def h264_round_trip(
    frames: Sequence[np.ndarray],
    crf: int = 28,
    fps: float = 30.0,
    reader: Callable[[Path], Iterable[np.ndarray]] | None = None,
) -> tuple[list[np.ndarray], int]:
    """The frames encoded as H.264 (libx264, yuv420p, constant rate factor ``crf``, by
    :class:`~myoface.render.io.VideoWriter`: deterministic) and decoded back by ``reader``
    (a path -> frames; default PyAV), and the stream's size in bytes."""
    with tempfile.TemporaryDirectory(prefix="myoface-degrade-") as tmp:
        path = Path(tmp) / "camera.mp4"
        with VideoWriter(path, fps=fps, quality_crf=int(crf)) as vw:
            for f in frames:
                vw.write(f)
        size = os.path.getsize(path)
        back = [np.asarray(f) for f in (reader or _decode)(path)]
    h, w = frames[0].shape[:2]
    back = [np.ascontiguousarray(b[:h, :w]) for b in back]  # odd sizes were padded
    if len(back) != len(frames):
        raise MyofaceValueError(f"the H.264 round trip gave {len(back)} frames for {len(frames)}")
    return back, size
