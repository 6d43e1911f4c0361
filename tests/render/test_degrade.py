"""The camera degradation (render/degrade.py): each stage does what it says, measurably, and
the same seed gives the same frames. Bounds from runs on 2026-12-01 (the numbers measured are
beside each)."""

from dataclasses import replace

import numpy as np
import pytest

from myoface.errors import MyofaceValueError
from myoface.face import FaceMesh
from myoface.render import Camera, Renderer, SkinMaterial, to_srgb8
from myoface.render.degrade import (
    SRGB_TO_LINEAR,
    CameraDegradation,
    clutter,
    coverage,
    h264_round_trip,
    resample_texture,
    studio_background,
)

pytest.importorskip("cv2")

#: every stage off: the frames come back as they went in
OFF = CameraDegradation(
    light_amplitude=0.0,
    exposure_drift=0.0,
    background=False,
    blur_sigma_px=0.0,
    full_scale_electrons=None,
    read_noise_electrons=0.0,
    crf=None,
)
GREY = np.full((240, 320, 3), 128, np.uint8)  # mid-grey (linear 0.216)


def _white_noise(seed=1, shape=(120, 160, 3)) -> np.ndarray:
    return (np.random.default_rng(seed).random(shape) * 255).astype(np.uint8)


def _moving_disc(n=10, size=(320, 240)) -> list[np.ndarray]:
    """A disc moving over a cluttered room: frames a camera could see."""
    import cv2

    room = to_srgb8(clutter(size, 3))
    out = []
    for k in range(n):
        f = room.copy()
        cv2.circle(f, (100 + 8 * k, 120), 40, (200, 150, 120), -1)
        out.append(f)
    return out


def _hf(img: np.ndarray) -> float:
    """High-frequency energy: the mean squared Laplacian of the linear image."""
    import cv2

    return float((cv2.Laplacian(SRGB_TO_LINEAR[img], cv2.CV_32F) ** 2).mean())


def _psnr(a, b) -> float:
    mse = np.mean([np.mean((x.astype(float) - y) ** 2) for x, y in zip(a, b, strict=True)])
    return float(10 * np.log10(255**2 / mse))


def test_every_stage_off_gives_the_frames_back_and_the_srgb_tables_invert():
    assert np.array_equal(to_srgb8(SRGB_TO_LINEAR[np.arange(256, dtype=np.uint8)]),
                          np.arange(256))  # fmt: skip
    img = _white_noise()
    assert np.array_equal(OFF.apply([img])[0], img)


def test_the_same_seed_gives_the_same_frames_another_seed_others():
    frames = _moving_disc(4)
    alpha = [np.zeros(frames[0].shape[:2])] * 4
    cam = CameraDegradation(motion_blur_px=3.0)
    a, b = cam.apply(frames, alpha), cam.apply(frames, alpha)
    c = replace(cam, seed=1).apply(frames, alpha)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
    assert not any(np.array_equal(x, y) for x, y in zip(a, c, strict=True))


def test_sensor_noise_on_mid_grey_is_two_to_three_percent_of_full_scale():
    """Measured: 5.9 of 255 levels (2.3 %) with the defaults; shot noise alone 5.7."""
    cam = replace(OFF, full_scale_electrons=500.0, read_noise_electrons=2.5)
    out = cam.apply([GREY])[0].astype(float)
    assert 0.02 * 255 <= out.std() <= 0.03 * 255
    assert abs(out.mean() - 128) < 0.5  # zero-mean noise
    brighter = replace(cam, full_scale_electrons=5000.0).apply([GREY])[0].astype(float)
    assert brighter.std() < 0.5 * out.std()  # 10x the electrons: sqrt(10) less shot noise


def test_blur_lowers_the_high_frequencies():
    """Laplacian energy of white noise: x0.006 for the 1 px Gaussian (measured); the 5 px
    horizontal motion blur flattens the x-differences (x0.04) more than the y ones (x0.21)."""
    img = _white_noise()
    assert _hf(replace(OFF, blur_sigma_px=1.0).apply([img])[0]) < 0.05 * _hf(img)
    moved = replace(OFF, motion_blur_px=5.0).apply([img])[0]
    lin0, lin1 = SRGB_TO_LINEAR[img], SRGB_TO_LINEAR[moved]

    def energy(a, axis):
        return float((np.diff(a, axis=axis) ** 2).mean())

    gx, gy = energy(lin1, 1) / energy(lin0, 1), energy(lin1, 0) / energy(lin0, 0)
    assert gx < 0.5 * gy < 0.5


def test_the_light_field_stays_within_its_amplitude_and_turns():
    """On mid-grey: brightness max/min over a frame 1.27-1.51 as the gradient turns (1.5 at
    the diagonals; sRGB rounding adds < 1 %)."""
    a = 0.2
    cam = replace(OFF, light_amplitude=a)
    f0, f45 = cam.light_field(0, (320, 240)), cam.light_field(45, (320, 240))
    for f in (f0, f45):
        assert f.min() >= 1 - a - 1e-6 and f.max() <= 1 + a + 1e-6
    assert np.abs(f0 - f45).max() > 0.2  # it turned (90 deg in 1.5 s at 60 deg/s)
    out = cam.apply([GREY] * 40)
    ratios = [SRGB_TO_LINEAR[o].mean(2).max() / SRGB_TO_LINEAR[o].mean(2).min() for o in out]
    assert 1.2 < min(ratios) and max(ratios) <= (1 + a) / (1 - a) * 1.01
    assert max(ratios) > 1.45  # the field reaches near its bounds when it points at a corner


def test_exposure_drifts_slowly_within_its_range():
    """Measured: mean linear brightness 0.918-1.087 of the frame's over 4 s for +-8 %, one
    sRGB level (1.6 %) at a time."""
    out = replace(OFF, exposure_drift=0.08).apply([GREY] * 120)
    gain = np.array([SRGB_TO_LINEAR[o].mean() for o in out]) / SRGB_TO_LINEAR[128]
    assert 0.91 <= gain.min() < 0.94 and 1.06 < gain.max() <= 1.09
    drift = np.array([OFF.exposure(k) for k in range(120)])  # amplitude 0: no drift
    assert np.array_equal(drift, np.ones(120))
    drift = np.array([replace(OFF, exposure_drift=0.08).exposure(k) for k in range(120)])
    assert np.abs(np.diff(drift)).max() < 0.005  # slow: under 0.5 % a frame
    # the frames move one sRGB level at a time (levels 120-136: 1.6-1.8 % of mid-grey)
    step = np.diff(SRGB_TO_LINEAR[120:137]).max() / SRGB_TO_LINEAR[128]
    assert np.abs(np.diff(gain)).max() <= step + 1e-6


def _small_render():
    """A renderer of two triangles in a 48x40 orthographic view (ssaa 2) and its frame."""
    cam = Camera((0, 0, 100.0), (0, 0, 0), (0, 1, 0), 48, 40, None, 40.0)
    v = np.array([[-15, -12, 0], [15, -12, 0], [0, 14, 0], [-5, -18, 5], [18, 0, 5],
                  [-10, 10, 5.0]])  # fmt: skip
    r = Renderer(FaceMesh(v, np.array([[0, 1, 2], [3, 4, 5]])), cam, [],
                 SkinMaterial(albedo=(0.9, 0.5, 0.3), ambient=(1, 1, 1), specular=0.0),
                 ssaa=2, dress=False)  # fmt: skip
    return r, r.render()


def test_coverage_and_the_studio_background_read_the_render():
    r, frame = _small_render()
    a = coverage(r)
    assert a.shape == (40, 48) and a.min() == 0 and a.max() == 1
    assert 0 < ((a > 0) & (a < 1)).sum() < 0.3 * (a > 0).sum()  # soft only at the edges
    bg = a == 0
    studio = to_srgb8(studio_background(r))
    assert np.abs(studio[bg].astype(int) - frame[bg]).max() <= 1  # the renderer's background


def test_the_room_replaces_the_background_and_keeps_the_face_before_noise():
    r, frame = _small_render()
    a = coverage(r)
    cam = replace(OFF, background=True)
    out = cam.apply([frame], [a], studio_background(r))[0]
    room = to_srgb8(clutter((48, 40), np.random.SeedSequence(0).spawn(4)[0]))
    face, bg = a == 1, a == 0
    assert np.array_equal(out[face], frame[face])
    assert np.array_equal(out[bg], room[bg])
    assert np.abs(out[bg].astype(int) - frame[bg]).mean() > 10  # the room is not the studio
    with pytest.raises(MyofaceValueError, match="alpha"):
        cam.apply([frame])


def test_h264_changes_the_frames_within_a_webcams_quality():
    """CRF 22 on a moving disc over the room: 36.7 dB (measured); with the sensor's noise
    before it, 34.9 dB against the clean frames."""
    frames = _moving_disc()
    back, n_bytes = h264_round_trip(frames, 22, 30.0)
    assert len(back) == len(frames) and n_bytes > 0
    assert not np.array_equal(back[5], frames[5])
    assert 28 <= _psnr(frames, back) <= 45
    noisy = replace(OFF, full_scale_electrons=500.0, read_noise_electrons=2.5, crf=22)
    assert 28 <= _psnr(frames, noisy.apply(frames)) < _psnr(frames, back)


def test_a_resampled_texture_loses_its_fine_detail_not_its_colour():
    tex = _white_noise(2, (64, 96, 3))
    half = resample_texture(tex, 0.5)
    assert half.shape == tex.shape and half.dtype == np.uint8
    assert _hf(half) < 0.3 * _hf(tex)
    assert np.abs(half.astype(float).mean((0, 1)) - tex.mean((0, 1))).max() < 2


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"light_amplitude": 0.5}, "light_amplitude"),
        ({"light_amplitude": -0.1}, "light_amplitude"),
        ({"exposure_drift": float("nan")}, "exposure_drift"),
        ({"exposure_period_s": 0}, "exposure_period_s"),
        ({"blur_sigma_px": 6}, "blur_sigma_px"),
        ({"motion_blur_px": -1}, "motion_blur_px"),
        ({"full_scale_electrons": 0.5}, "full_scale_electrons"),
        ({"full_scale_electrons": None}, "read_noise_electrons"),
        ({"crf": 52}, "crf"),
        ({"crf": 22.5}, "crf"),
        ({"fps": 0}, "fps"),
        ({"seed": -1}, "seed"),
        ({"background": "yes"}, "background"),
    ],
)
def test_bad_parameters_are_refused_with_their_name(kwargs, match):
    with pytest.raises(MyofaceValueError, match=match):
        CameraDegradation(**kwargs)


def test_bad_frames_and_textures_are_refused():
    with pytest.raises(MyofaceValueError, match="no frames"):
        OFF.apply([])
    with pytest.raises(MyofaceValueError, match="uint8"):
        OFF.apply([GREY.astype(float)])
    with pytest.raises(MyofaceValueError, match="one size"):
        OFF.apply([GREY, GREY[:100]])
    with pytest.raises(MyofaceValueError, match="one mask per frame"):
        replace(OFF, background=True).apply([GREY, GREY], [np.ones((240, 320))])
    with pytest.raises(MyofaceValueError, match="factor"):
        resample_texture(GREY, 1.0)
