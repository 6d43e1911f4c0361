"""The viewer's scene and exports on the server, without a browser: what is drawn follows the
physics, the camera presets frame the face, images and videos are written, presets apply."""

import json

import numpy as np
import pytest

from myoface.errors import MyofaceValueError
from myoface.model import build_face_model
from myoface.viewer.state import ViewerState
from tests.conftest import REPO

pytest.importorskip("viser")


@pytest.fixture(scope="module")
def viewer():
    from myoface.viewer.app import FaceViewer

    v = FaceViewer(build_face_model(), port=0)
    yield v
    v.close()


def test_textured_skin_glb_carries_the_new_positions_and_normals():
    import trimesh

    from myoface.render import dressing
    from myoface.viewer.scene import TexturedSkinGLB, read_glb_positions

    fm = build_face_model()
    face = fm.face
    glb = TexturedSkinGLB(
        face.vertices, face.triangles, face.uv, dressing.default_skin_texture(face)
    )
    moved = face.vertices + np.array([0.0, 5.0, 0.0]) * (face.vertices[:, 1:2] > 0)
    data = glb.data(moved)
    np.testing.assert_allclose(read_glb_positions(data) / 1e-3, moved, atol=1e-4)
    # a glTF reader sees the same mesh, with its texture coordinates and texture
    mesh = trimesh.load(trimesh.util.wrap_as_stream(data), file_type="glb", force="mesh")
    assert mesh.vertices.shape == moved.shape and len(mesh.faces) == len(face.triangles)
    np.testing.assert_allclose(np.sort(mesh.vertices[:, 1]), np.sort(moved[:, 1] * 1e-3), atol=1e-7)
    assert mesh.visual.uv.shape == (len(moved), 2)
    assert mesh.visual.material.baseColorTexture.size == (512, 512)


def test_scene_follows_the_physics(viewer):
    fm, sc = viewer.model, viewer.scene
    assert sc.eyes is not None and len(sc.fans) == 2  # two eye sockets
    assert sc.cavity is not None and sc.jaw is not None  # the mouth: cavity, lower teeth
    sc.set_layer("fat", True)
    sc.set_bones(True)
    try:
        chin = int(fm.face.landmark("chin")[0])
        bones0 = sc.bones.points.copy()
        skin = viewer.apply(fm.validate({"jaw": 0.8, "zygomaticus_major_l": 1.0}))
        assert skin[chin, 1] < fm.face.vertices[chin, 1] - 3.0  # the jaw opened
        np.testing.assert_allclose(sc.skin.vertices, skin * 1e-3, atol=1e-6)
        # the mouth's cavity keeps its rim on the lips' inner margin
        loop, _first = viewer.renderer.scene.cavity
        np.testing.assert_allclose(sc.cavity.vertices[: len(loop)], skin[loop] * 1e-3, atol=1e-6)
        # the lower teeth and tongue follow the jaw's rotation
        rot, shift = fm.jaw_pose(viewer.worker.current)
        w, *xyz = sc.jaw.wxyz
        assert np.isclose(abs(w), np.cos(0.5 * np.arccos((np.trace(rot) - 1) / 2)), atol=1e-6)
        assert abs(w) < 1.0 - 1e-4  # rotated
        np.testing.assert_allclose(sc.jaw.position, shift * 1e-3, atol=1e-9)
        # the lattice layer and the bone nodes moved with the tissue
        handle, sel = sc.layers["fat"]
        x = viewer.worker.current.x
        t = fm.tissue
        np.testing.assert_allclose(handle.points[:, 0], x[t.spring_i[sel]] * 1e-3, atol=1e-6)
        moved = np.linalg.norm(sc.bones.points - bones0, axis=1)
        assert moved.max() > 3e-3  # the jaw's bone nodes rotated by millimetres
        assert np.median(moved) == 0.0  # the skull's did not
    finally:
        sc.set_layer("fat", False)
        sc.set_bones(False)
        viewer.apply(fm.validate({}))


def _glb_normal_map(glb: bytes) -> np.ndarray:
    """The normal texture of a GLB's first material, decoded (H, W, 3) uint8."""
    import io
    import json
    import struct

    from PIL import Image

    (json_len,) = struct.unpack_from("<I", glb, 12)
    doc = json.loads(glb[20 : 20 + json_len])
    tex = doc["textures"][doc["materials"][0]["normalTexture"]["index"]]
    view = doc["bufferViews"][doc["images"][tex["source"]]["bufferView"]]
    o = 20 + json_len + 8 + view.get("byteOffset", 0)
    return np.asarray(Image.open(io.BytesIO(glb[o : o + view["byteLength"]])).convert("RGB"))


def test_textured_view_follows_the_physics(viewer):
    from myoface.viewer.scene import read_glb_positions

    fm, sc = viewer.model, viewer.scene
    sc.set_textured(True)
    try:
        assert sc.textured.visible and not sc.skin.visible
        flat = _glb_normal_map(sc.textured.glb_data)
        assert (np.abs(flat.astype(int) - (128, 128, 255)) <= 1).all()  # at rest: no furrows
        skin = viewer.apply(fm.validate({"frontalis_major_l": 1.0, "frontalis_major_r": 1.0}))
        np.testing.assert_allclose(read_glb_positions(sc.textured.glb_data), skin * 1e-3, atol=1e-6)
        # a smile: the wrinkles' normal map goes with the skin (cheeks, crow's feet)
        viewer.apply(fm.validate({"zygomaticus_major_l": 1.0, "zygomaticus_major_r": 1.0}))
        folded = _glb_normal_map(sc.textured.glb_data)
        assert sc._glb.wrinkled
        assert (np.abs(folded.astype(int) - (128, 128, 255)).max(axis=2) > 8).sum() > 500
    finally:
        sc.set_textured(False)
        viewer.apply(fm.validate({}))
    assert sc.skin.visible and not sc.textured.visible


@pytest.mark.parametrize(
    "name, direction",
    [("front", (0, 0, 1)), ("profile left", (1, 0, 0)), ("profile right", (-1, 0, 0))],
)
def test_camera_presets_look_at_the_face_from_their_side(viewer, name, direction):
    cam = viewer.camera_preset(name, 600, 400, 50.0)
    d = cam.eye - cam.target
    np.testing.assert_allclose(d / np.linalg.norm(d), direction, atol=1e-9)
    px = cam.project(viewer.model.face.vertices)
    assert px[:, 0].min() > 0 and px[:, 0].max() < 600  # the whole face in the picture
    assert px[:, 1].min() > 0 and px[:, 1].max() < 400
    with pytest.raises(MyofaceValueError, match="camera preset"):
        viewer.camera_preset("top", 600, 400, 50.0)


def test_cpu_render_of_the_current_face(viewer):
    img = viewer.render_image(viewer.camera_preset("front", 200, 160, 30.0))
    assert img.shape == (160, 200, 3) and img.dtype == np.uint8
    center = img[70:90, 90:110].astype(int)
    corner = img[:10, :10].astype(int)
    assert np.abs(center.mean(axis=(0, 1)) - corner.mean(axis=(0, 1))).max() > 40


def test_playback_video_leaves_the_live_face_alone(viewer, tmp_path):
    import imageio.v3 as iio

    fm = viewer.model
    live = viewer.apply(fm.validate({"zygomaticus_major_l": 0.5}))
    viewer.state.load_playback(REPO / "examples" / "talk.toml")
    try:
        seen = []
        out = viewer.playback_video(
            tmp_path / "p.mp4",
            viewer.camera_preset("front", 96, 96, 30.0),
            fps=10.0,
            on_frame=lambda k, n: seen.append((k, n)),
        )
        times = viewer.state.playback[0]
        n = int(np.floor((times[-1] - times[0]) * 10.0)) + 1
        assert seen[-1] == (n, n)
        frames = iio.imread(out, plugin="pyav")
        assert frames.shape == (n, 96, 96, 3)
        assert np.abs(frames.astype(int) - frames[0]).max() > 30  # the face moves
        np.testing.assert_array_equal(fm.skin_vertices(viewer.worker.current), live)
    finally:
        viewer.state.playback = None
    with pytest.raises(MyofaceValueError, match="load a contractions.csv"):
        viewer.playback_video(tmp_path / "q.mp4")
    assert not (tmp_path / "q.mp4").exists()


def test_play_plays_from_the_click_and_once(viewer, monkeypatch):
    import threading
    import time
    import types

    import myoface.viewer.app as app

    # the playback's thread held back until released: what a busy machine does to it
    go, started = threading.Event(), []

    class Held(threading.Thread):
        def run(self):
            go.wait(10)
            super().run()

        def start(self):
            started.append(self)
            super().start()

    # (the viewer module's own threads only: a namespace in place of its threading module)
    monkeypatch.setattr(app, "threading", types.SimpleNamespace(Thread=Held, Event=threading.Event))
    viewer.state.load_playback(REPO / "examples" / "talk.toml")
    viewer._time.max, viewer._time.value = 0.4, 0.0
    try:
        viewer._play()
        assert viewer._playing  # from the click on, not once the loop's thread runs
        viewer._play()  # a second click meanwhile starts no second loop
        assert len(started) == 1
        go.set()
        deadline = time.time() + 10
        while time.time() < deadline and viewer._playing:
            time.sleep(0.05)
        assert not viewer._playing
        assert viewer._time.value > 0.2  # it ran to (about) the playback's end
    finally:
        go.set()
        viewer.state.playback = None


def test_presets_save_apply_and_load(tmp_path):
    fm = build_face_model()
    st = ViewerState(fm)
    assert {"neutral", "happiness", "surprise", "anger"} <= set(st.presets)
    st.apply_preset("surprise")
    surprise = st.contractions()
    assert surprise.max() > 0.5
    st.set_au(12, 0.5)
    st.save_preset("mine")
    st.reset()
    st.apply_preset("mine")
    assert st.contractions()[fm.ids.index("zygomaticus_major_l")] > 0.3
    assert not st.aus and st.expression is None  # a preset replaces the face
    good = tmp_path / "grin.json"
    good.write_text(json.dumps({"zygomaticus_major": 0.7, "jaw": 0.2}))
    assert st.load_preset_file(good) == "grin"
    c = st.contractions()
    assert c[fm.ids.index("zygomaticus_major_r")] == pytest.approx(0.7)
    assert c[fm.ids.index("jaw")] == pytest.approx(0.2)
    for text, match in [
        ("{not json", "not JSON"),
        ("[1, 2]", "object"),
        ('{"nose_muscle": 0.5}', "unknown muscle"),
        ('{"jaw": 2}', r"\[0, 1\]"),
    ]:
        bad = tmp_path / "bad.json"
        bad.write_text(text)
        with pytest.raises(MyofaceValueError, match=match):
            st.load_preset_file(bad)
        np.testing.assert_array_equal(st.contractions(), c)  # unchanged
    with pytest.raises(MyofaceValueError, match="unknown preset"):
        st.apply_preset("nope")
    with pytest.raises(MyofaceValueError, match="name"):
        st.save_preset("  ")
