"""The frame synthesizer of analysis by synthesis: the model rendered as a frame showed it."""

import numpy as np
import pytest

from myoface.analysis.synthesis import FrameSynthesizer
from myoface.errors import MyofaceValueError
from myoface.face import load_default_face
from myoface.render import Camera, Renderer, to_srgb8
from myoface.render.dressing import default_skin_texture


@pytest.fixture(scope="module")
def scene():
    face = load_default_face()
    cam = Camera.front(face.vertices, width=160, height=160, fov_deg=None)
    tex = to_srgb8(default_skin_texture(face, 256, makeup=True))
    return face, cam, Renderer(face, cam, texture=tex)


def test_the_rest_shape_renders_back_to_the_calibration_frame(scene):
    """The frame's colours, divided by the renderer's shading, make the texture: at rest the
    synthetic frame is the frame up to the resampling of the texture (measured when written
    at 256 px: mean 0.07 levels, 99th percentile 2)."""
    face, cam, r = scene
    frame = r.render()
    out = FrameSynthesizer(face, cam, frame).render(face.vertices)
    d = np.abs(out.astype(int) - frame).max(axis=2)
    assert d.mean() < 0.5 and np.percentile(d, 99) <= 6, (d.mean(), np.percentile(d, 99))


def test_the_texture_moves_with_the_skin(scene):
    """Deformed, the synthetic frame follows the true render of the deformed face, much
    closer than the rest frame is to it."""
    from myoface.model import build_face_model

    face, cam, r = scene
    model = build_face_model()
    frame = r.render()
    synth = FrameSynthesizer(face, cam, frame)
    res = model.relax({"jaw": 0.6, "zygomaticus_major_l": 0.7, "zygomaticus_major_r": 0.7})
    skin = model.skin_vertices(res.state)
    truth = r.render(skin).astype(int)
    err_synth = np.abs(synth.render(skin) - truth).mean()
    err_rest = np.abs(frame - truth).mean()
    assert err_synth < 0.3 * err_rest, (err_synth, err_rest)


def test_a_camera_of_another_size_is_refused(scene):
    face, cam, r = scene
    with pytest.raises(MyofaceValueError, match="the camera is 160x160 px but the frame"):
        FrameSynthesizer(face, cam, np.zeros((100, 120, 3), np.uint8))


def test_the_lower_teeth_follow_the_estimates_jaw(scene):
    """With the mouth open, the synthetic frame shows the lower teeth where the jaw put them
    (``render(skin, jaw)``, as the video's renderer does): closer to the true render than
    the same skin with the teeth left closed, which show in the opening (measured at 160 px:
    mean 0.36 levels against 1.43)."""
    from myoface.model import build_face_model

    face, cam, r = scene
    model = build_face_model()
    synth = FrameSynthesizer(face, cam, r.render())
    state = model.relax({"jaw": 0.6, "depressor_labii_inferioris_l": 0.6}).state
    skin, jaw = model.skin_vertices(state), model.jaw_pose(state)
    truth = r.render(skin, jaw=jaw).astype(int)
    err_jaw = np.abs(synth.render(skin, jaw) - truth).mean()
    err_closed = np.abs(synth.render(skin) - truth).mean()
    assert err_jaw < 0.5 * err_closed, (err_jaw, err_closed)
