"""``myoface export``: the file's contents, its skin against the simulated skin, the morph
targets' fit, and the command line."""

from __future__ import annotations

import numpy as np
import pytest

from myoface.cli import main
from tests.export.conftest import DEMO_CSV

#: the export's promise (issue 33): every frame's skin within this RMS (mm) of the simulation
TARGET_MM = 0.5


def _gltf(path):
    import pygltflib

    g = pygltflib.GLTF2().load_binary(str(path))
    return g, g.binary_blob()


def _acc(g, blob, i):
    from myoface.export.gltf import _read

    return np.asarray(_read(g, blob, i), dtype=np.float64)


def _channels(g, blob):
    """{(node name, path): (times, values)} of the file's animation."""
    a = g.animations[0]
    out = {}
    for ch in a.channels:
        s = a.samplers[ch.sampler]
        out[(g.nodes[ch.target.node].name, ch.target.path)] = (
            _acc(g, blob, s.input),
            _acc(g, blob, s.output),
        )
    return out


def _quat(rot):
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(rot).as_quat()


def _same_rotation(q, rot, atol=1e-5):
    """A quaternion q (x, y, z, w) is the rotation matrix ``rot`` (q and -q are the same)."""
    r = _quat(rot)
    return min(np.abs(q - r).max(), np.abs(q + r).max()) < atol


# ---------------------------------------------------------------------------- the skin
def test_the_demo_csv_exports_within_half_a_millimetre_at_every_frame(csv_export):
    report, clip = csv_export
    assert report.n_frames == clip.n_frames == 72 and report.fps == pytest.approx(30.0, rel=2e-3)
    assert report.max_rms_mm <= TARGET_MM
    # the fit's own tolerance, plus what float32 metres add
    assert report.max_rms_mm <= 0.1 + 1e-3
    # the correctives only ever bring a frame closer than the muscles' linear sum
    assert np.all(report.frame_rms_mm <= report.linear_rms_mm + 1e-3)
    # the face really moves in this clip (the comparison is not of still faces)
    moved = np.sqrt(((report.sim.skin - report.sim.skin[0]) ** 2).sum(axis=2)).max()
    assert moved > 5.0


def test_each_expression_exports_within_half_a_millimetre(expression_exports):
    from myoface.control import list_expressions

    assert set(expression_exports) == set(list_expressions())
    for name, (report, _) in expression_exports.items():
        assert report.max_rms_mm <= TARGET_MM, (name, report.summary())
        assert report.n_muscle_targets > 0, name


def test_the_morph_fit_is_exact_on_a_linear_response_and_bounded_on_a_nonlinear_one():
    from myoface.export import fit_morph_animation, frame_rms_mm

    rng = np.random.default_rng(0)
    n_t, n_v, n_m = 40, 50, 4
    rest = rng.normal(size=(n_v, 3)) * 50
    resp = rng.normal(size=(n_m, n_v, 3)) * 3
    c = rng.uniform(0, 1, size=(n_t, n_m))
    c[:, 3] = 0  # a muscle that never contracts gets no target
    linear = rest + np.einsum("tm,mvc->tvc", c, resp)
    m = fit_morph_animation(linear, rest, c, resp, ["a", "b", "c", "d"], tol_mm=0.01)
    assert m.names == ["a", "b", "c"] and m.n_targets == 3
    assert frame_rms_mm(m.evaluate(), linear).max() < 1e-9
    # a response that stiffens (the squares of the contractions, crossed terms) needs correctives
    bend = rng.normal(size=(n_m, n_v, 3)) * 2
    skin = linear + np.einsum("tm,mvc->tvc", c**2 - c, bend) + (c[:, 0] * c[:, 1])[:, None, None]
    skin += rng.normal(size=skin.shape) * 0.05  # and a little of everything (a full rank)
    loose = fit_morph_animation(skin, rest, c, resp, list("abcd"), tol_mm=0.3)
    tight = fit_morph_animation(skin, rest, c, resp, list("abcd"), tol_mm=0.05)
    assert loose.linear_rms_mm.max() > 0.3
    assert loose.frame_rms_mm.max() <= 0.3 and tight.frame_rms_mm.max() <= 0.05
    assert tight.n_targets > loose.n_targets > 3
    assert all(n.startswith("corrective_") for n in tight.names[3:])
    assert tight.weights.min() >= 0.0 and tight.weights.max() <= 1.0 + 1e-12
    # too few correctives allowed for the tolerance: said, not hidden
    from myoface.errors import MyofaceWarning

    with pytest.warns(MyofaceWarning, match="above the 0.05 mm"):
        short = fit_morph_animation(skin, rest, c, resp, list("abcd"), tol_mm=0.05,
                                    max_correctives=1)  # fmt: skip
    assert short.frame_rms_mm.max() > 0.05


# ---------------------------------------------------------------------------- the file
def test_the_file_holds_the_face_in_metres_y_up_with_its_parts(export_model, csv_export):
    report, clip = csv_export
    g, blob = _gltf(report.path)
    names = [n.name for n in g.nodes]
    assert names[0] == "myoface_head"
    assert {"skin", "eye_l", "eye_r", "teeth_upper", "teeth_lower", "tongue"} <= set(names)
    assert set(g.nodes[0].children) == set(range(1, len(names)))
    skin_mesh = g.meshes[g.nodes[names.index("skin")].mesh]
    prim = skin_mesh.primitives[0]
    pos = _acc(g, blob, prim.attributes.POSITION)
    face = export_model.face
    # metres: the model's millimetres over 1000; glTF's axes are the model's (+Y up, +Z front)
    np.testing.assert_allclose(pos, export_model.skin_vertices() * 1e-3, atol=1e-8)
    assert 0.1 < np.ptp(pos[:, 1]) < 0.3
    chin, brow = face.landmark("chin")[0], face.landmark("eyebrow_l")[0]
    assert pos[brow, 1] > pos[chin, 1]  # +Y up
    nose = face.landmark("nose_tip")[0]
    assert pos[nose, 2] == pytest.approx(pos[:, 2].max(), abs=0.01)  # +Z the face's front
    eye_l = g.nodes[names.index("eye_l")]
    assert eye_l.translation[0] > 0  # the subject's left on +X
    # the UVs (glTF's v down the image) and the texture
    uv = _acc(g, blob, prim.attributes.TEXCOORD_0)
    np.testing.assert_allclose(uv[:, 0], face.uv[:, 0], atol=1e-6)
    np.testing.assert_allclose(uv[:, 1], 1 - face.uv[:, 1], atol=1e-6)
    assert len(g.images) == 1 and g.images[0].mimeType == "image/png"
    mat = g.materials[prim.material]
    assert mat.pbrMetallicRoughness.baseColorTexture.index == 0
    # the morph targets: the muscles' names first, then the correctives; every weight in [0, 1]
    tn = skin_mesh.extras["targetNames"]
    assert len(tn) == len(prim.targets) == report.n_muscle_targets + report.n_corrective_targets
    assert set(tn[: report.n_muscle_targets]) <= set(export_model.ids)
    ch = _channels(g, blob)
    times, w = ch[("skin", "weights")]
    np.testing.assert_allclose(times, np.arange(clip.n_frames) / clip.fps, atol=1e-6)
    assert w.min() >= 0 and w.max() <= 1


def test_the_jaw_gaze_and_head_pose_are_animated_on_their_nodes(export_model, csv_export):
    from myoface.render.renderer import gaze_rotation

    report, clip = csv_export
    sim = report.sim
    g, blob = _gltf(report.path)
    ch = _channels(g, blob)
    for k in range(0, clip.n_frames, 7):
        rot, shift = sim.jaw[k]
        for node in ("teeth_lower", "tongue"):
            assert _same_rotation(ch[(node, "rotation")][1][k], rot)
            np.testing.assert_allclose(ch[(node, "translation")][1][k], shift * 1e-3, atol=1e-8)
        for node in ("eye_l", "eye_r"):
            assert _same_rotation(ch[(node, "rotation")][1][k], gaze_rotation(clip.gaze[k]))
        head_rot, head_shift = clip.poses[k]
        assert _same_rotation(ch[("myoface_head", "rotation")][1][k], head_rot)
        np.testing.assert_allclose(
            ch[("myoface_head", "translation")][1][k], head_shift * 1e-3, atol=1e-7
        )
    # the clip moves them: the jaw opens, the eyes turn, the head turns
    assert min(r[1, 1] for r, _ in sim.jaw) < 0.999
    assert np.abs(clip.gaze).max() > np.deg2rad(3)
    assert max(np.arccos(min(1.0, (np.trace(r) - 1) / 2)) for r, _ in clip.poses) > 0.02
    assert ("teeth_upper", "rotation") not in ch  # the upper teeth are fixed in the head


def test_the_sockets_and_mouth_cavity_follow_the_skin_as_the_renderer_places_them(
    export_model, csv_export
):
    from myoface.render import Renderer
    from myoface.synth import make_camera

    report, _ = csv_export
    g, blob = _gltf(report.path)
    mesh = g.meshes[[n.name for n in g.nodes].index("skin") - 1]
    assert mesh.name == "skin" and len(mesh.primitives) == 2
    prim = mesh.primitives[1]
    base = _acc(g, blob, prim.attributes.POSITION)
    targets = np.array([_acc(g, blob, t["POSITION"]) for t in prim.targets])
    w = _channels(g, blob)[("skin", "weights")][1].reshape(report.n_frames, -1)
    face = export_model.face
    r = Renderer(face, make_camera(face.vertices, "front", 16, 16), ssaa=1)
    lo, hi = r.scene.n_face, r.scene.n_dynamic
    for k in (0, 30, report.n_frames - 1):
        want = r.positions(report.sim.skin[k])[lo:hi]
        got = (base + np.einsum("k,kvc->vc", w[k], targets)) * 1e3
        # the dressing is affine in the skin: its error is the skin's, no more
        err = np.sqrt(((got - want) ** 2).sum(axis=1).mean())
        assert err <= TARGET_MM


def test_an_expression_export_has_no_head_pose_and_eyes_ahead(expression_exports):
    report, clip = expression_exports["surprise"]
    g, blob = _gltf(report.path)
    ch = _channels(g, blob)
    assert ("myoface_head", "rotation") not in ch and clip.poses is None
    q = ch[("eye_l", "rotation")][1]
    np.testing.assert_allclose(np.abs(q[:, 3]), 1.0, atol=1e-6)
    assert g.asset.extras["fps"] == 15.0 and report.duration_s == pytest.approx(2.0)


# ---------------------------------------------------------------------------- the command
def test_the_command_exports_a_timeline_at_its_frame_rate(tmp_path, capsys):
    tl = tmp_path / "blink.toml"
    tl.write_text(
        "fps = 12\n[[event]]\nkind = 'blink'\nstart = 0.1\n"
        "[[event]]\nkind = 'gaze'\nstart = 0.0\nduration = 0.5\nyaw_deg = 20\n"
    )
    out = tmp_path / "blink.glb"
    assert main(["export", "--timeline", str(tl), "-o", str(out), "--quiet"]) == 0
    said = capsys.readouterr().out
    assert f"wrote {out}" in said and "mm RMS" in said
    g, blob = _gltf(out)
    times = _channels(g, blob)[("eye_l", "rotation")][0]
    assert np.diff(times) == pytest.approx(1 / 12) and g.asset.extras["frames"] == len(times)
    # the gaze event turns the eyes towards the subject's left
    q = _channels(g, blob)[("eye_l", "rotation")][1]
    assert np.abs(q[:, 1]).max() > np.sin(np.deg2rad(8))


@pytest.mark.parametrize(
    ("argv", "code", "match"),
    [
        ([], 2, "give one of"),
        ([str(DEMO_CSV), "--expression", "anger"], 2, "give one of"),
        ([str(DEMO_CSV), "--fps", "24"], 2, "a CSV keeps its own"),
        (["--timeline", "x.toml", "--duration", "2"], 2, "--duration"),
        (["--expression", "joy"], 1, "unknown expression 'joy'"),
        (["--expression", "anger=1.5"], 1, "anger"),
        (["--expression", "anger", "--fps", "0"], 2, "--fps"),
    ],
)
def test_the_command_says_what_is_wrong_in_one_line(tmp_path, capsys, argv, code, match):
    assert main(["export", *argv, "-o", str(tmp_path / "a.glb")]) == code
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[-1], err
    assert not (tmp_path / "a.glb").exists()


def test_the_command_refuses_another_suffix_and_its_own_input(tmp_path, capsys):
    assert main(["export", "--expression", "anger", "-o", str(tmp_path / "a.gltf")]) == 1
    assert ".glb" in capsys.readouterr().err
    csv = tmp_path / "c.glb"
    csv.write_bytes(DEMO_CSV.read_bytes())
    assert main(["export", str(csv), "-o", str(csv)]) == 2
    assert csv.read_bytes() == DEMO_CSV.read_bytes()


def test_a_csv_without_head_pose_and_gaze_exports_a_still_head_looking_ahead(
    export_model, tmp_path
):
    import csv

    from myoface.analysis.contractions_csv import POSE_COLUMNS
    from myoface.export import clip_from_csv, export_glb

    rows = list(csv.DictReader(DEMO_CSV.read_text().splitlines()))[:12]
    drop = set(POSE_COLUMNS) | {c for c in rows[0] if c.startswith("gaze_")}
    keep = [c for c in rows[0] if c not in drop]
    path = tmp_path / "contractions.csv"
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, keep, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    clip = clip_from_csv(path, export_model)
    assert clip.poses is None and clip.gaze is None and clip.n_frames == 12
    report = export_glb(export_model, clip, tmp_path / "still.glb")
    assert report.max_rms_mm <= TARGET_MM
    g, blob = _gltf(report.path)
    ch = _channels(g, blob)
    assert ("myoface_head", "rotation") not in ch
    np.testing.assert_allclose(np.abs(ch[("eye_r", "rotation")][1][:, 3]), 1.0, atol=1e-6)
    with pytest.raises(ValueError, match="tol_mm"):
        export_glb(export_model, clip, tmp_path / "x.glb", tol_mm=0.0)


@pytest.mark.shared_data
def test_waters_face_exports_its_own_expressions(tmp_path):
    """Waters' geoface (no UVs, no lip landmarks: no texture, no teeth) with his own
    expression macros, as ``myoface synth --expression`` plays them."""
    from myoface.export import clip_from_expressions, export_glb
    from myoface.model import load_face_model
    from tests.conftest import shared_path

    model = load_face_model(shared_path("waters-geoface"))
    clip = clip_from_expressions([("happiness", 1.0)], model, fps=10.0)
    apex = clip.contractions[len(clip.contractions) // 2]
    np.testing.assert_allclose(apex, np.clip(model.expressions["happiness"], 0, 1), atol=1e-9)
    report = export_glb(model, clip, tmp_path / "waters.glb")
    assert report.max_rms_mm <= TARGET_MM
    g, _ = _gltf(report.path)
    names = {n.name for n in g.nodes}
    assert {"skin", "eye_l", "eye_r"} <= names and "teeth_lower" not in names
    assert not g.images
