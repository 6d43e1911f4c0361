"""The fidelity measure (``myoface.analysis.fidelity``): how much of the input's expression
motion the analysed model reproduces; the model's side read exactly from its vertices, the
input's by the validated motion reader (DIS), and MediaPipe on both (the measure of earlier
reports) beside it."""

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from myoface.analysis.fidelity import (
    JUDGED_REGIONS,
    REGIONS,
    RIGID_POINTS,
    align_sequence,
    displacements,
    measure_fidelity,
    plot_fidelity,
    scores,
)
from myoface.errors import MyofaceValueError
from tests.conftest import needs_mediapipe, shared_path

EXPRESSIVE = sorted({i for idx in REGIONS.values() for i in idx})


def _sequence(face, n=20, amplitude_mm=3.0, seed=0):
    """(T, 468, 3) points: the face, its expressive points (and others, not the rigid ones)
    moving smoothly, each in its own direction, the rigid points still."""
    rng = np.random.default_rng(seed)
    v = face.vertices
    movers = np.setdiff1d(np.arange(len(v)), RIGID_POINTS)
    direction = rng.normal(size=(len(v), 3))
    direction[RIGID_POINTS, :] = 0.0
    direction /= np.linalg.norm(direction, axis=1, keepdims=True) + 1e-12
    phase = rng.uniform(0, np.pi, len(v))
    t = np.linspace(0, 1, n)
    env = np.sin(np.pi * t[:, None] * 1.5 + phase[None, :]) - np.sin(phase)[None, :]
    out = np.repeat(v[None], n, axis=0)
    out[:, movers] += amplitude_mm * env[:, movers, None] * direction[None, movers]
    return out


def _rigidly_moved(seq, seed=1):
    """Each frame turned, scaled and shifted by its own similarity."""
    rng = np.random.default_rng(seed)
    out = np.empty_like(seq)
    for k, f in enumerate(seq):
        r = Rotation.from_rotvec(rng.normal(scale=0.25, size=3)).as_matrix()
        out[k] = rng.uniform(0.8, 1.3) * f @ r.T + rng.normal(scale=30, size=3)
    return out


def test_identical_sequences_explain_everything(default_face):
    seq = _sequence(default_face)
    res = measure_fidelity(seq, seq.copy())
    for s in [res.overall, *res.regions.values()]:
        assert s.explained == pytest.approx(1.0, abs=1e-9)
        assert s.gain == pytest.approx(1.0, abs=1e-9)
        assert s.corr == pytest.approx(1.0, abs=1e-9)
    assert set(res.regions) == set(REGIONS)
    assert res.reference == 0 and res.n_frames == len(seq)


def test_a_still_face_explains_nothing(default_face):
    seq = _sequence(default_face)
    still = np.repeat(seq[:1], len(seq), axis=0)
    res = measure_fidelity(seq, still)
    for s in [res.overall, *res.regions.values()]:
        assert s.explained == pytest.approx(0.0, abs=1e-9)
        assert s.gain == pytest.approx(0.0, abs=1e-9)
        assert s.rms_out == pytest.approx(0.0, abs=1e-12)
    assert res.overall.rms_in > 0.01  # the input did move (IOD units)


@pytest.mark.parametrize("k", [0.5, 0.8, 1.3])
def test_a_scaled_output_gives_its_gain(default_face, k):
    """The output makes the same motion k times as large: gain k, correlation 1, explained
    1 - (1 - k)^2."""
    seq = _sequence(default_face)
    out = seq[:1] + k * (seq - seq[:1])
    res = measure_fidelity(seq, out)
    for s in [res.overall, *res.regions.values()]:
        assert s.gain == pytest.approx(k, abs=1e-6)
        assert s.corr == pytest.approx(1.0, abs=1e-6)
        assert s.explained == pytest.approx(1 - (1 - k) ** 2, abs=1e-6)


def test_the_alignment_removes_a_rigid_motion(default_face):
    """A copy of the input whose frames are each turned, scaled and moved (a head that moves,
    seen at another size) reproduces the input's expression motion exactly."""
    seq = _sequence(default_face)
    moved = _rigidly_moved(seq)
    res = measure_fidelity(seq, moved)
    assert res.overall.explained == pytest.approx(1.0, abs=1e-9)
    for s in res.regions.values():
        assert s.explained == pytest.approx(1.0, abs=1e-9)
    # and a still face that moves rigidly has no expression motion at all
    still = _rigidly_moved(np.repeat(seq[:1], len(seq), axis=0), seed=2)
    a = align_sequence(still)
    np.testing.assert_allclose(a, np.repeat(still[:1], len(seq), axis=0), atol=1e-9)
    d = displacements(still)
    assert all(np.abs(x).max() < 1e-12 for x in d.values())


def test_the_depth_is_left_out_unless_asked_for(default_face):
    """An output that differs only in depth (towards the camera) agrees in the image plane
    (dims=2, the default) and not in 3-D."""
    seq = _sequence(default_face)
    out = seq.copy()
    out[:, EXPRESSIVE, 2] = seq[:1, EXPRESSIVE, 2]  # the expressive points never move in depth
    assert measure_fidelity(seq, out).overall.explained == pytest.approx(1.0, abs=1e-3)
    assert measure_fidelity(seq, out, dims=3).overall.explained < 0.95


def test_frames_without_a_face_are_left_out(default_face):
    seq = _sequence(default_face)
    out = seq.copy()
    out[0] = np.nan  # no face in the first frame of the output: the reference moves on
    out[5] = np.nan
    seq2 = seq.copy()
    seq2[7] = np.nan
    res = measure_fidelity(seq2, out)
    assert res.reference == 1 and res.n_frames == len(seq) - 3
    assert res.overall.explained == pytest.approx(1.0, abs=1e-9)


def test_scores_edge_cases():
    z = np.zeros((4, 2, 2))
    s = scores(z, z)
    assert np.isnan(s.explained) and np.isnan(s.gain)  # the input did not move: undefined
    with pytest.raises(MyofaceValueError, match="shape"):
        scores(z, np.zeros((4, 3, 2)))
    with pytest.raises(MyofaceValueError, match="468"):
        measure_fidelity(np.zeros((3, 10, 3)), np.zeros((3, 10, 3)))
    with pytest.raises(MyofaceValueError, match="length"):
        measure_fidelity(np.zeros((3, 468, 3)), np.zeros((4, 468, 3)))
    with pytest.raises(MyofaceValueError, match="fewer than 2"):
        measure_fidelity(np.full((3, 468, 3), np.nan), np.zeros((3, 468, 3)))


def test_rigid_and_expressive_points_are_the_faces_named_ones(default_face):
    lm = default_face.landmarks
    assert set(REGIONS["mouth_corners"]) == {*lm["mouth_corner_r"], *lm["mouth_corner_l"]}
    assert set(REGIONS["brows"]) == {*lm["eyebrow_r"], *lm["eyebrow_l"]}
    assert set(REGIONS["chin"]) <= set(lm["chin"])
    assert {33, 133} <= set(lm["eye_r"]) and {362, 263} <= set(lm["eye_l"])
    eyelids = set(REGIONS["eyelids"])
    assert eyelids <= set(lm["eye_r"]) | set(lm["eye_l"])
    assert not set(RIGID_POINTS) & set(EXPRESSIVE)


def test_plot_has_a_panel_per_region(default_face, tmp_path):
    import imageio.v3 as iio

    seq = _sequence(default_face)
    res = measure_fidelity(seq, seq[:1] + 0.5 * (seq - seq[:1]))
    plot_fidelity(res, tmp_path / "f.png", times=np.arange(len(seq)) / 30)
    img = iio.imread(tmp_path / "f.png")
    assert img.shape[0] > 100 * len(REGIONS)  # one panel per region


# ------------------------------------------------------------------ on rendered video


def _smile_clip(d, size):
    """A short clip of the default face (skin texture, perspective camera, ``size`` pixels)
    smiling and opening its mouth: (path, frames, model, true contractions)."""
    from myoface.model import build_face_model
    from myoface.render import Camera, Renderer, VideoWriter, to_srgb8
    from myoface.render.dressing import default_skin_texture

    fm = build_face_model()
    cam = Camera.front(fm.face.vertices, width=size, height=size, fov_deg=30)
    r = Renderer(fm.face, cam, texture=to_srgb8(default_skin_texture(fm.face, size)))
    state = fm.rest_state()
    frames, truth = [], []
    for c in (0.0, 0.0, 0.4, 0.8, 1.0, 0.8, 0.4, 0.0):
        ctl = {"zygomaticus_major_l": c, "zygomaticus_major_r": c, "jaw": 0.3 * c}
        truth.append(fm.validate(ctl))
        state = fm.relax(truth[-1], state).state
        frames.append(r.render(fm.skin_vertices(state)))
    with VideoWriter(d / "smile.mp4", fps=10) as vw:
        for f in frames:
            vw.write(f)
    return d / "smile.mp4", frames, fm, truth


@pytest.fixture(scope="module")
def smile_clip(tmp_path_factory):
    """The clip at 256 pixels, which MediaPipe's face mesh finds in every frame."""
    return _smile_clip(tmp_path_factory.mktemp("fidelity"), 256)


@pytest.fixture(scope="module")
def smile_clip_384(tmp_path_factory):
    """The clip at 384 pixels: the face's inter-ocular distance about 95 px, as the sample
    video's (99 px), on which the motion reader is validated."""
    return _smile_clip(tmp_path_factory.mktemp("fidelity384"), 384)


@pytest.mark.parametrize("alignment", ["2d", "3d"])
def test_the_model_side_is_its_vertices(alignment):
    """The model's side of the measure is the model's skin vertices at each row's contractions
    (x, y of the head frame, y up) from the neutral's over its inter-ocular distance, the head
    motion the rigid points show taken out as on the input's side (their 2-D similarity, or
    the 3-D pose with the neutral's depths): against each row relaxed from rest on its own and read from
    ``skin_vertices`` here (within 1e-3 IOD: the relaxation's tolerance is 0.02 mm, 2e-4 of
    the 89 mm IOD, and the rows here are warm-started); the lids along the eye's vertical
    (the face's y) alone; unmeasured rows NaN, the neutral row 0; the smile moves the corners up and outwards by well over the tolerance."""
    from myoface.analysis.fidelity import POINTS, model_displacements
    from myoface.analysis.motionreader import HeadPose3D, aligned_displacements
    from myoface.model import build_face_model

    fm = build_face_model()
    rows = [{}, {"zygomaticus_major_l": 0.5, "zygomaticus_major_r": 0.5}, {"jaw": 0.5},
            {"zygomaticus_major_l": 1.0, "frontalis_inner_l": 1.0}]  # fmt: skip
    table = np.array([fm.validate(c) for c in rows])
    ok = np.array([True, True, False, True])
    d, side = model_displacements(fm, table, ok, alignment=alignment)
    assert set(d) == set(REGIONS) and side["unconverged"] == 0
    idx = list(POINTS)
    rest = fm.skin_vertices(fm.rest_state())[idx, :2] * [1, -1]
    rigid = [idx.index(i) for i in RIGID_POINTS]
    eyes = (idx.index(33), idx.index(263))
    np.testing.assert_allclose(side["neutral_points"], rest, atol=1e-12)
    for k, c in enumerate(table):
        for name, pts in REGIONS.items():
            if not ok[k]:
                assert np.isnan(d[name][k]).all()
                continue
            skin = fm.skin_vertices(fm.relax(c).state)[idx, :2] * [1, -1]
            if alignment == "2d":
                want = aligned_displacements(rest, skin, rigid, eyes) * [1, -1]
            else:
                head = HeadPose3D(rest, side["neutral_3d"], rigid, eyes)
                want = head.displacements(skin)
            want = want[[idx.index(i) for i in pts]]
            if name == "eyelids":
                want = want * [0.0, 1.0]  # the lids along the eye's vertical alone
            np.testing.assert_allclose(d[name][k], want, atol=1e-3, err_msg=name)
    assert np.abs(np.concatenate([v[0] for v in d.values()])).max() < 1e-12
    mc = d["mouth_corners"][1]  # 61 (the subject's right), 291 (left): out and up
    assert mc[0, 0] < -0.02 and mc[1, 0] > 0.02 and (mc[:, 1] > 0.02).all(), mc
    left_brow = d["brows"][3][5:, 1]  # 336 (inner) ... 300 (outer): the inner frontalis
    assert left_brow[0] > 0.03 and left_brow[0] > left_brow[-1] + 0.03, left_brow


def test_the_models_reach_finds_what_the_model_can_make():
    """:func:`model_reach` on a known answer: the input is the model's own motion at known
    contractions (a smile with the jaw a little open, the upper lip raised, a brow raised), so
    the model can reproduce it exactly; the reach explains it (>= 0.97 overall and in every
    region that moves) at a gain within 5 % of 1. And a motion no contraction makes (every
    point pushed 0.05 IOD to the subject's left, which the rigid points' similarity does not
    take out because they do not move) is not explained."""
    from myoface.analysis.fidelity import model_displacements, model_reach
    from myoface.model import build_face_model

    fm = build_face_model()
    rows = [{}, {"zygomaticus_major_l": 0.4, "zygomaticus_major_r": 0.5, "jaw": 0.1},
            {"levator_labii_superioris_l": 0.6, "frontalis_inner_r": 0.8}]  # fmt: skip
    table = np.array([fm.validate(c) for c in rows])
    d_in, _ = model_displacements(fm, table)
    reach, _ = model_reach(fm, d_in)
    assert reach.overall.explained >= 0.97, reach.overall
    assert abs(reach.overall.gain - 1.0) < 0.05, reach.overall
    for name, sc in reach.regions.items():
        if np.isfinite(sc.explained) and (d_in[name] ** 2).sum() > 1e-4:
            assert sc.explained >= 0.97, (name, sc)
    sideways = {k: v + np.array([0.05, 0.0]) * (np.arange(len(v)) > 0)[:, None, None]
                for k, v in d_in.items()}  # fmt: skip
    worse, _ = model_reach(fm, sideways)
    assert worse.overall.explained < 0.8, worse.overall


@needs_mediapipe
def test_identical_videos_and_a_still_face(smile_clip):
    """MediaPipe on a video and on the same video: 1. On the video and on its first frame held
    (a still face): 0 (each frame is detected on its own, so a held frame gives the same
    points)."""
    from myoface.analysis.fidelity import detect_landmarks

    frames = smile_clip[1]
    lm = detect_landmarks(frames)
    assert np.isfinite(lm).all()
    same = measure_fidelity(lm, detect_landmarks(frames))
    assert same.overall.explained == pytest.approx(1.0, abs=1e-6)
    still = measure_fidelity(lm, detect_landmarks([frames[0]] * len(frames)))
    assert still.overall.explained == pytest.approx(0.0, abs=1e-9)
    assert still.regions["mouth_corners"].gain == pytest.approx(0.0, abs=1e-9)
    assert still.overall.rms_in > 0.01  # while the input moved


def _write_csv(path, ids, table, fps=10):
    lines = [",".join(["frame", "time_s", "quality", *ids])]
    for k, row in enumerate(table):
        lines.append(",".join([str(k), f"{k / fps:.4f}", "ok", *(f"{v:.5f}" for v in row)]))
    path.write_text("\n".join(lines) + "\n")


@needs_mediapipe
def test_the_true_contractions_read_from_their_own_render(smile_clip_384, tmp_path, monkeypatch):
    """The clip's own contractions on the same model against its render read as the video: the
    model's side is its vertices, so the gain is what the reader reads of the render's motion,
    expected 1 within the reader's validated bounds (it reads 0.96-1.04 of known warps of a
    real face of this size, [0.9, 1.1] at the chin; the perspective camera at 30 degrees
    enlarges the mouth, 11 mm nearer than the eye corners, by about 2 %; at the mouth corners
    [0.8, 1.1], its bounds on renders, :func:`test_the_reader_on_renders_at_known_contractions`:
    the face rests with its lips together, and as the smile opens them the mouth's dark
    inside comes out at the corners: gain 0.86 since 2026-12-02, 1.03 with the lips apart;
    correlation above 0.9: the chin's 0.93, above 0.95 with the lips apart; read at their pixel
    the corners sat on the lips' slit, where DIS's flow is the upper lip's or the lower lip's by
    a few pixels of the render: the depressor labii inferioris made a sheet, moving the corners
    by 0.03 mm, moved that 0.86 to 0.79; read over their support
    (:data:`~myoface.analysis.fidelity.CORNER_SUPPORT_IOD`) 0.91 and 0.90, explained 0.95 and
    0.93),
    and no motion where the model moved none (brows, lids). The lips are left out: the mouth
    opens, and at its inner edge (points 13, 14) the render's inside of the mouth comes out
    of the edge the flow follows (measured 2026-12-01: corners gain 1.03, explained 0.97, chin
    gain 1.00). MediaPipe on both is beside it. A table of zeros (a still face) explains none
    of the motion. When no face can be made from the calibration frame, the fallback model is
    used and the reason is given."""
    from myoface.analysis import fidelity

    video, frames, fm, truth = smile_clip_384
    _write_csv(tmp_path / "true.csv", fm.ids, truth)
    res, how = fidelity.fidelity_of_analysis(video, tmp_path / "true.csv", model=fm)
    assert res.n_frames == len(frames) and res.reference == 0
    assert how["input_reader"]["method"] == "dis" and "DIS" in res.reader
    for region, (lo, hi) in (("mouth_corners", (0.8, 1.1)), ("chin", (0.9, 1.1))):
        s = res.regions[region]
        assert lo <= s.gain <= hi and s.corr > 0.9, (region, res.as_dict())
    assert res.regions["mouth_corners"].explained > 0.9
    for region in ("brows", "eyelids"):
        assert res.regions[region].rms_in < 0.002 and res.regions[region].rms_out < 0.002
    old = res.mediapipe_on_both
    assert old is not None and old.n_frames == len(frames)
    assert how["mediapipe_on_both_how"]["frames_without_face_in_resynthesis"] == 0
    _write_csv(tmp_path / "still.csv", fm.ids, np.zeros_like(truth))
    still, _ = fidelity.fidelity_of_analysis(
        video, tmp_path / "still.csv", model=fm, mediapipe_on_both=False
    )
    assert still.mediapipe_on_both is None
    assert still.overall.explained == pytest.approx(0.0, abs=1e-9)
    assert still.overall.gain == pytest.approx(0.0, abs=1e-9)
    assert still.overall.rms_in > 0.01  # while the input moved

    def no_face(*a):
        raise MyofaceValueError("no face found in the photo")

    monkeypatch.setattr(fidelity, "person_model", no_face)
    with pytest.raises(MyofaceValueError, match="no face"):
        fidelity.fidelity_of_analysis(video, tmp_path / "still.csv")
    _, how = fidelity.fidelity_of_analysis(
        video, tmp_path / "still.csv", fallback_model=fm, mediapipe_on_both=False
    )
    assert "no face found" in how["face"]


#: renders of the person's own face at known contractions: a smile baring the upper teeth, a
#: mouth opening with raised inner brows, and two of the expressions (0.9)
_RENDERED = {
    "smile_teeth": {"zygomaticus_major_l": 0.8, "zygomaticus_major_r": 0.8,
                    "levator_labii_superioris_l": 0.5, "levator_labii_superioris_r": 0.5,
                    "orbicularis_oculi_l": 0.4, "orbicularis_oculi_r": 0.4, "jaw": 0.08},
    "open_mouth": {"jaw": 0.35, "frontalis_inner_l": 0.6, "frontalis_inner_r": 0.6,
                   "depressor_labii_inferioris_l": 0.4, "depressor_labii_inferioris_r": 0.4},
    "happiness": None,
    "surprise": None,
}  # fmt: skip


@needs_mediapipe
@pytest.mark.slow
@pytest.mark.shared_data
def test_the_reader_on_renders_at_known_contractions(tmp_path):
    """The reader against a second known answer, where appearance changes with the motion:
    the person's own face (``face_from_photo`` on the sample video's first frame, its photo as
    texture) rendered at known contractions rising and falling (:data:`_RENDERED`), read as a
    video, its readings compared with the model's own vertices. Where a judged region moves by
    0.015 IOD RMS or more, the reader reads the mouth corners at 0.8-1.1 of it and the lower
    lip, chin and brows at 0.85-1.15, the head's motion taken out by either alignment (2-D, and
    3-D on both sides) (measured 2026-12-01, 2-D: corners 0.84-1.02, the others 0.91-1.09;
    2026-12-02, 3-D: corners 0.81-1.01, the others 0.90-1.08; sadness' and anger's corners,
    moving down and in, 0.67-0.68, not tested here; the corners read over their support
    (:data:`~myoface.analysis.fidelity.CORNER_SUPPORT_IOD`, 2026-12-02): 0.82-0.94 with the
    bundled muscles, 0.84-0.93 with the depressor labii inferioris a sheet, either alignment);
    the lips' centres, which the measure does not judge, are misread where the teeth come
    out (inner lips 0.27-0.81 of their motion, explained below 0.75)."""
    from myoface.analysis import fidelity
    from myoface.analysis.motionreader import explained, gain
    from myoface.control import expression_contractions

    path = shared_path("video", "single_face.mp4")
    if not path.exists():
        pytest.skip("../shared/data/video/single_face.mp4 is not here")
    fm, _ = fidelity.person_model(path, 0)
    regions = {**JUDGED_REGIONS, "inner_lips": (13, 14)}
    ramp = (0.0, 0.0, 0.3, 0.6, 0.9, 1.0, 1.0, 0.9, 0.6, 0.3, 0.0)
    misread_inner = False
    for name, apex in _RENDERED.items():
        if apex is None:
            c = expression_contractions(name, 0.9, fm.ids)
            apex = {i: float(x) for i, x in zip(fm.ids, c, strict=True) if x > 0}
        truth, ref, pts, _ = _render_ramp(fm, apex, ramp, tmp_path / f"{name}.mp4")
        for alignment in fidelity.ALIGNMENTS:
            d_out, side = fidelity.model_displacements(fm, truth, None, regions, alignment)
            d_in = fidelity.input_displacements(ref, pts, side, regions, alignment)
            for region in JUDGED_REGIONS:
                if region == "eyelids":
                    continue  # (the lids move by less than 0.015 IOD in all four)
                a, b = d_in[region], d_out[region]
                if np.sqrt(np.mean((b**2).sum(-1))) < 0.015:
                    continue
                lo, hi = (0.8, 1.1) if region == "mouth_corners" else (0.85, 1.15)
                assert lo <= gain(a, b) <= hi, (name, alignment, region, gain(a, b))
            a, b = d_in["inner_lips"], d_out["inner_lips"]
            misread_inner |= np.sqrt(np.mean((b**2).sum(-1))) >= 0.015 and explained(a, b) < 0.75
    assert misread_inner


@needs_mediapipe
def test_frames_before_the_calibration_frame_are_read_back_from_it(smile_clip_384):
    """The reader follows the points from the calibration frame forward and back: reading the
    clip from its frame 4 (the apex), frames k and 8 - k (the same contractions, one read
    back from the apex, one forward) read the same points (median over the points within
    0.1 px, the mouth corners within 1.5 px; measured 2026-12-02: median 0.004 px or less,
    corners up to 1.30 px (0.39 px while the face rested with its lips apart: now the smile
    opens them and the mouth's inside comes out at the corners), while they moved 11-12 px; the largest differences, 0.6-2.1 px, are at the inner lower lip, where the
    mouth opens, and the menton, on the render's silhouette), and the apex its own reference
    points; a frame the video does not have is an error."""
    from myoface.analysis.fidelity import POINTS, read_video_points

    video = smile_clip_384[0]
    ref, pts, unsure, _ = read_video_points(video, list(range(8)), 4, "dis")
    np.testing.assert_array_equal(pts[4], ref)
    corners = [POINTS.index(i) for i in REGIONS["mouth_corners"]]
    for k in (1, 2, 3):
        e = np.linalg.norm(pts[k] - pts[8 - k], axis=1)  # pixels
        assert np.median(e) < 0.1 and e[corners].max() < 1.5, (k, e)
    assert np.linalg.norm(pts[1] - ref, axis=1)[corners].min() > 3.0  # while the face moved
    assert unsure.shape == (8, len(POINTS))
    with pytest.raises(MyofaceValueError, match="no frame 20"):
        read_video_points(video, [0, 20], 0, "dis")


@pytest.mark.slow  # about 35 s: the analysis, a face from the calibration frame, MediaPipe
@needs_mediapipe
def test_cli_report_and_openface(smile_clip_384, tmp_path, capsys):
    """``myoface analyze --tracker landmarks --report --format openface`` writes
    fidelity.json, fidelity.png and openface.csv beside the analysis, and prints the measure
    and, labelled, MediaPipe on both; on the model's own smile, analysed and driving a face
    made from its calibration frame, the mouth corners' motion is reproduced in its direction
    (correlation) and much of its size. (Loose bounds: the measure must see that the loop
    works, not grade the fit.)"""
    import csv

    import imageio.v3 as iio

    from myoface.analysis.openface import MYOFACE_COLUMNS, OPENFACE_COLUMNS
    from myoface.cli import main

    video, frames = smile_clip_384[:2]
    out = tmp_path / "out"
    argv = ["analyze", str(video), "--tracker", "landmarks", "-o", str(out), "--quiet"]
    assert main([*argv, "--report", "--format", "openface"]) == 0
    text = capsys.readouterr().out
    assert "fidelity: " in text and "the video read by DIS dense optical flow" in text, text
    assert "fidelity, MediaPipe's face mesh on both (earlier reports' measure" in text, text
    doc = json.loads((out / "fidelity.json").read_text())
    assert set(doc["regions"]) == set(JUDGED_REGIONS)
    assert doc["frames_compared"] == len(frames)
    assert "face_from_photo" in doc["face"]
    assert doc["input_reader"]["method"] == "dis"
    assert doc["input_reader"]["validation"]["bounds"]["gain"] == [0.9, 1.1]
    assert set(doc["mediapipe_on_both"]["regions"]) == set(JUDGED_REGIONS)
    mc = doc["regions"]["mouth_corners"]
    assert mc["corr"] > 0.8 and mc["gain"] > 0.4, doc
    assert iio.imread(out / "fidelity.png").shape[0] > 100 * len(JUDGED_REGIONS)
    with open(out / "openface.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == [*OPENFACE_COLUMNS, *MYOFACE_COLUMNS]  # (the expressions last)
    assert len(rows) == len(frames) and all(r["success"] == "1" for r in rows)
    au12 = [float(r["AU12_r"]) for r in rows]
    assert au12[4] > au12[0] + 1.0  # the smile's apex against the neutral start


@needs_mediapipe
def test_a_video_against_itself_and_against_a_still_one(smile_clip_384, tmp_path):
    """fidelity_of_video (what a decoder makes of a video, the codec's measure): a video
    against itself explains all of its motion at gain 1; against its first frame held (a
    still reconstruction) none of it."""
    from myoface.analysis.fidelity import fidelity_of_video
    from myoface.render import VideoWriter

    video, frames, _, _ = smile_clip_384
    same = fidelity_of_video(video, video, 0)
    assert same.n_frames == len(frames) and same.overall.rms_in > 0.01
    assert same.overall.explained == pytest.approx(1.0, abs=1e-9)
    assert same.overall.gain == pytest.approx(1.0, abs=1e-9)
    still_path = tmp_path / "still.mp4"
    with VideoWriter(still_path, fps=10) as vw:
        for _ in frames:
            vw.write(frames[0])
    still = fidelity_of_video(video, still_path, 0)
    assert abs(still.overall.gain) < 0.05 and abs(still.overall.explained) < 0.05, still.overall
    assert "dis" in still.method


def _head_poses(n, yaw, pitch, roll, pivot=(0.0, -60.0, -10.0)):
    """``n`` head poses (rotation, translation mm) turning by up to ``yaw``, ``pitch`` and
    ``roll`` degrees about a point behind the chin (the neck), out of phase with each other
    and with the expression's ramp, the first frame front on."""
    pivot = np.asarray(pivot)
    out = []
    for j in range(n):
        a, b, c = (
            np.sin(2 * np.pi * j / (n - 1) + 0.3),
            np.sin(3 * np.pi * j / (n - 1)),
            np.cos(2 * np.pi * j / (n - 1)),
        )
        if j == 0:
            a = b = c = 0.0
        r = Rotation.from_euler("yxz", [yaw * a, pitch * b, roll * c], degrees=True).as_matrix()
        out.append((r, pivot - r @ pivot + np.array([2.0 * a, 1.5 * b, 0.0])))
    return out


@needs_mediapipe
@pytest.mark.slow
@pytest.mark.shared_data
def test_the_reader_under_3d_head_motion(tmp_path):
    """The reader against renders of the person's own face (as in
    :func:`test_the_reader_on_renders_at_known_contractions`) whose head turns in 3-D about
    the neck: a yaw of 5 degrees, a nod (pitch) of 5, and all three at once (4, 4 and 3), 13
    frames. Without an expression the judged regions must read still: the 3-D alignment (the
    measure's, :class:`~myoface.analysis.motionreader.HeadPose3D`) reads at most 0.012
    inter-ocular distances RMS in any region, where the rigid points' 2-D similarity reads the
    nod as more than 0.015 of chin motion (measured 2026-12-02: 2-D 0.005-0.019, the chin's in
    the nod 0.019, the mouth corners' 0.012, the brows' in the yaw 0.010; 3-D 0.004-0.010).
    With surprise at 0.9 on top of all three turns, the 3-D alignment (on both sides, as the
    measure does) reads every judged region that moves at 0.88-1.12 of its motion (measured
    0.92-1.07)."""
    from myoface.analysis import fidelity
    from myoface.analysis.motionreader import gain
    from myoface.analysis.resynthesis import resynthesis_frames
    from myoface.control import expression_contractions
    from myoface.render import VideoWriter

    path = shared_path("video", "single_face.mp4")
    if not path.exists():
        pytest.skip("../shared/data/video/single_face.mp4 is not here")
    fm, _ = fidelity.person_model(path, 0)
    n = 13
    ramp = np.sin(np.pi * np.arange(n) / (n - 1))
    surprise = expression_contractions("surprise", 0.9, fm.ids)
    heads = {"yaw": (5, 0, 0), "nod": (0, 5, 0), "all": (4, 4, 3)}
    leak2d_nod_chin = 0.0
    for expr in ("none", "surprise"):
        for head, ypr in heads.items():
            if expr == "surprise" and head != "all":
                continue
            truth = np.zeros((n, len(fm.ids))) if expr == "none" else ramp[:, None] * surprise
            video = tmp_path / f"{expr}_{head}.mp4"
            with VideoWriter(video, fps=10) as vw:
                for f in resynthesis_frames(fm, truth, 384, poses=_head_poses(n, *ypr)):
                    vw.write(f)
            ref, pts, _, _ = fidelity.read_video_points(video, list(range(n)), 0)
            d_out, side = fidelity.model_displacements(fm, truth, None, JUDGED_REGIONS, "3d")
            d3 = fidelity.input_displacements(ref, pts, side, JUDGED_REGIONS, "3d")
            for region in JUDGED_REGIONS:
                a, b = d3[region], d_out[region]
                err = np.sqrt(np.mean(((a - b) ** 2).sum(-1)))
                if expr == "none":
                    assert err <= 0.012, (head, region, err)
                elif np.sqrt(np.mean((b**2).sum(-1))) >= 0.015:
                    assert 0.88 <= gain(a, b) <= 1.12, (head, region, gain(a, b))
            if expr == "none" and head == "nod":
                d2 = fidelity.input_displacements(ref, pts, side, JUDGED_REGIONS, "2d")
                leak2d_nod_chin = np.sqrt(np.mean((d2["chin"] ** 2).sum(-1)))
    assert leak2d_nod_chin > 0.015


def _blinking(video, n, first, poses=None):
    """The person's own face (made from the sample video's first frame) rendered over ``n``
    frames to ``video``, its lids closing over four from ``first`` (the palpebral orbicularis
    oculi at 0.5, 1, 1, 0.5), nothing else moving but the head's ``poses``, and read by the
    judge's reader: (model, contractions table, (reference points, points, unsure))."""
    from myoface.analysis import fidelity
    from myoface.analysis.resynthesis import resynthesis_frames
    from myoface.render import VideoWriter

    path = shared_path("video", "single_face.mp4")
    if not path.exists():
        pytest.skip("../shared/data/video/single_face.mp4 is not here")
    fm, _ = fidelity.person_model(path, 0)
    ids = list(fm.ids)
    table = np.zeros((n, len(ids)))
    for m in ("orbicularis_oculi_palpebralis_l", "orbicularis_oculi_palpebralis_r"):
        table[first : first + 4, ids.index(m)] = (0.5, 1.0, 1.0, 0.5)
    with VideoWriter(video, fps=10) as vw:
        for f in resynthesis_frames(fm, table, 384, poses=poses):
            vw.write(f)
    ref, pts, unsure, _ = fidelity.read_video_points(video, list(range(n)), 0)
    return fm, table, (ref, pts, unsure)


@needs_mediapipe
@pytest.mark.slow
@pytest.mark.shared_data
def test_a_blink_does_not_move_the_other_regions(tmp_path):
    """A known answer for the alignment in a blink: the person's own face (as in
    :func:`test_the_reader_on_renders_at_known_contractions`) closing its lids (the palpebral
    orbicularis oculi at 0.5, 1, 1, 0.5 over four frames of twelve; the lids close to 0.13 of
    their opening, read at 0.52-0.69), nothing else moving, its eye corners still in the model. The closing lid drags the flow at the eye corners, and an
    alignment on them reads the head as moving: the measure's alignment fits the pose to the
    nose ridge while the eyes close, and reads at most 0.002 IOD RMS in the mouth corners,
    lower lip, brows and chin in the closed frames (measured 2026-12-02: 0.0001-0.0002), where
    the rigid points' 3-D pose read 0.004-0.013 (held here above 0.003); the lids' own motion
    stays, read at a gain of 0.75 (DIS follows a closing lid only partway; held above 0.5)."""
    from myoface.analysis import fidelity
    from myoface.analysis.motionreader import gain

    fm, table, (ref, pts, unsure) = _blinking(tmp_path / "blink.mp4", 12, 5)
    lids_out = fidelity.lids_unread(unsure)
    d_out, side = fidelity.model_displacements(fm, table, None, JUDGED_REGIONS, "3d", lids_out)
    d_in = fidelity.input_displacements(ref, pts, side, JUDGED_REGIONS, "3d", unsure)
    always = fidelity._region_displacements(ref, pts, JUDGED_REGIONS)  # (2-D, for the axes)
    head = fidelity.HeadPose3D(ref, side["neutral_3d"], fidelity._RIGID, fidelity._EYES)
    closed = [5, 6, 7, 8]
    for region in ("mouth_corners", "lower_lip", "brows", "chin"):
        idx = [fidelity._POS[i] for i in JUDGED_REGIONS[region]]
        for k in closed:
            assert np.sqrt((d_in[region][k] ** 2).sum(-1).mean()) <= 0.002, (region, k)
            assert np.abs(d_out[region][k]).max() < 1e-3  # the model's do not move
        rigid_fit = np.array([head.displacements(pts[k])[idx] for k in closed])
        assert np.sqrt((rigid_fit**2).sum(-1).mean()) > 0.003, region
        assert np.isfinite(always[region]).all()
    seen = ~lids_out
    g = gain(d_in["eyelids"][seen], d_out["eyelids"][seen])
    assert 0.5 <= g <= 1.1, g  # the lids' own motion stays (read partway by the flow)


@needs_mediapipe
@pytest.mark.slow
@pytest.mark.shared_data
def test_a_blink_with_the_head_turned_is_not_read_as_a_turn_back(tmp_path):
    """A known answer for the alignment in a blink with the head away from the calibration
    frame's pose: the person's own face nods 4 degrees over four frames and holds it, then
    blinks (frames 7-10 of 14), nothing else moving. In the blink the pose is fitted to the
    nose ridge, which tells a nod poorly; its prior held it towards the calibration frame's
    pose, so the held nod read as a nod back, 0.037-0.055 IOD RMS in the mouth corners, lower
    lip and chin in the closed frames against 0.005-0.013 in the open frames around them
    (2026-12-02, the sample video's blink showed the same: its chin 0.08-0.09 on the nose
    ridge against 0.02-0.03 on the rigid points in the frames around it). Now the prior holds
    the turn towards the rotation between the nearest open frames' poses: the closed frames
    read within 0.002 of the open frames with the same head (measured 0.005-0.012; the open
    frames' own 0.005-0.013 is the prior's share of an exact turn, as in
    :func:`test_the_reader_under_3d_head_motion`). On renders whose eye corners are no longer
    black (``myoface.render.dressing.SOCKET``, 2026-12-04: the conjunctiva's pink there, as
    in a real eye) the closed frames read 0.013, 0.015 and 0.022 IOD against the open
    frames' 0.005, 0.007 and 0.014 (mouth corners, lower lip, chin): the judge's alignment in
    a blink leaned on the black wedges' contrast at the eyes' corners; it is held within
    0.01 of the open frames here, a quarter of the turn back read before."""
    from scipy.spatial.transform import Rotation

    from myoface.analysis import fidelity

    n = 14
    pivot = np.array([0.0, -60.0, -10.0])  # the neck, as _head_poses
    poses = []
    for j in range(n):
        r = Rotation.from_euler("x", 4.0 * min(j / 4, 1.0), degrees=True).as_matrix()
        poses.append((r, pivot - r @ pivot))
    fm, table, (ref, pts, unsure) = _blinking(tmp_path / "nod_blink.mp4", n, 7, poses)
    d_out, side = fidelity.model_displacements(fm, table, None, JUDGED_REGIONS, "3d")
    d_in = fidelity.input_displacements(ref, pts, side, JUDGED_REGIONS, "3d", unsure)
    closed, held = [7, 8, 9, 10], [4, 5, 6, 11, 12, 13]
    assert all(fidelity._eyes_closing(ref, pts[k], unsure[k]) for k in closed)
    assert not any(fidelity._eyes_closing(ref, pts[k], unsure[k]) for k in held)
    for region in ("mouth_corners", "lower_lip", "chin"):
        rms = [float(np.sqrt((d_in[region][k] ** 2).sum(-1).mean())) for k in range(n)]
        assert max(rms[k] for k in closed) <= max(rms[k] for k in held) + 0.01, (region, rms)


@pytest.fixture(scope="module")
def blink_render(tmp_path_factory):
    """:func:`_blinking` over 12 frames, the lids closing from frame 5 (half, closed, closed,
    half)."""
    return _blinking(tmp_path_factory.mktemp("blink") / "blink.mp4", 12, 5)


@needs_mediapipe
@pytest.mark.slow
@pytest.mark.shared_data
def test_the_eyelids_reader_on_renders_at_known_contractions(blink_render):
    """The judge's lids against a known answer: the person's own face blinking
    (:func:`_blinking`: the palpebral orbicularis oculi at 0.5, 1, 1, 0.5), its readings against
    the model's own vertices. Where the lid covers the eye (the two closed frames) the flow at
    its margin mixes the lid with the still eyeball: there the reader read the upper lids at
    0.76 of their motion, the lower lids the wrong way and 0.03-0.045 IOD sideways, and the
    forward-backward check failed at every lid; those frames are left out of the eyelids region
    on both sides (:func:`~myoface.analysis.fidelity.lids_unread`), the half-closed ones (the
    check passed) are read along the eye's vertical. There each lid is read the right way, at
    a gain of 0.80 (2-D alignment) and 0.82 (3-D) over the lids (2026-12-03; each lid 0.68-0.98,
    the right lower lid least). Not 1: the rendered lid is a mesh whose skin 7 px above the
    margin (vertex 27 over 159) moves 0.53 of the margin's 0.045 IOD, so the texture a reader
    sees near the margin moves 0.5-1 of the margin vertex; a 1-D match of the intensity
    profile across the margin (lash line, lid side) read 0.79-0.84 of it too. Held at
    0.75-1.1."""
    from myoface.analysis import fidelity

    fm, table, (ref, pts, unsure) = blink_render
    lids_out = fidelity.lids_unread(unsure)
    assert lids_out[[6, 7]].all()  # closed: left out
    assert not lids_out[[0, 1, 2, 3, 4, 5, 8, 9, 10, 11]].any()  # open or half-closed: read
    for alignment in fidelity.ALIGNMENTS:
        d_out, side = fidelity.model_displacements(
            fm, table, None, JUDGED_REGIONS, alignment, lids_out
        )
        d_in = fidelity.input_displacements(ref, pts, side, JUDGED_REGIONS, alignment, unsure)
        a, b = d_in["eyelids"], d_out["eyelids"]
        assert np.isnan(a[lids_out]).all() and np.isnan(b[lids_out]).all()
        seen = ~lids_out
        a, b = a[seen], b[seen]
        read_gain = float((a * b).sum() / (b * b).sum())
        assert 0.75 <= read_gain <= 1.1, (alignment, read_gain)
        moving = np.abs(b[..., 1]) > 0.005  # the half-closed frames' lids
        assert moving.sum() == 8
        assert (np.sign(a[..., 1][moving]) == np.sign(b[..., 1][moving])).all(), alignment
        upper, lower = b[:, [0, 2], 1], b[:, [1, 3], 1]
        assert (upper <= 1e-4).all() and (lower >= -1e-4).all()  # lids close: upper down


@needs_mediapipe
@pytest.mark.slow
@pytest.mark.shared_data
def test_the_exact_model_scores_near_one_on_its_own_blink(blink_render):
    """A perfect analysis of a blink (the model's own contractions, its skin as the
    "analysis") scores near 1 in the eyelids region: explained 0.936 (2-D alignment) and 0.948
    (3-D), measured 2026-12-03, where the lids were read at every frame, closed ones included,
    it scored 0.615. A model that blinks a frame late scores well below it."""
    from myoface.analysis import fidelity

    fm, table, (ref, pts, unsure) = blink_render
    lids_out = fidelity.lids_unread(unsure)
    late = np.roll(table, 1, axis=0)
    for alignment in fidelity.ALIGNMENTS:
        d_out, side = fidelity.model_displacements(
            fm, table, None, JUDGED_REGIONS, alignment, lids_out
        )
        d_in = fidelity.input_displacements(ref, pts, side, JUDGED_REGIONS, alignment, unsure)
        s = scores(d_in["eyelids"], d_out["eyelids"])
        assert s.explained >= 0.9, (alignment, s)
        d_late, _ = fidelity.model_displacements(
            fm, late, None, JUDGED_REGIONS, alignment, lids_out
        )
        assert scores(d_in["eyelids"], d_late["eyelids"]).explained < 0.6, alignment


@needs_mediapipe
@pytest.mark.slow
@pytest.mark.shared_data
def test_the_chin_reader_on_renders_of_its_muscles(tmp_path):
    """The chin against known answers, one muscle at a time: the person's own face (as in
    :func:`test_the_reader_on_renders_at_known_contractions`) with the jaw opening to 0.3, the
    depressor labii inferioris or the mentalis to 0.9 and back over 11 frames, its chin read
    against the model's vertices, either alignment. The jaw's and the depressor's chin motion
    are read at 0.90 (explained 0.978-0.985), the mentalis' push of the chin boss up at 0.69
    (explained 0.79): held at 0.85-1.1 (explained 0.95) and 0.6-1.1 (0.7) (2026-12-03). The
    judge is no cause of the sample video's low chin score (0.17, the model's reach 0.55):
    there 58 % of the chin's motion is sideways, which no muscle of the model makes."""
    from myoface.analysis import fidelity

    path = shared_path("video", "single_face.mp4")
    if not path.exists():
        pytest.skip("../shared/data/video/single_face.mp4 is not here")
    fm, _ = fidelity.person_model(path, 0)
    ramp = (0.0, 0.0, 0.3, 0.6, 0.9, 1.0, 1.0, 0.9, 0.6, 0.3, 0.0)
    cases = {
        "jaw": ({"jaw": 0.3}, (0.85, 1.1), 0.95),
        "depressor_labii_inferioris": (
            {"depressor_labii_inferioris_l": 0.9, "depressor_labii_inferioris_r": 0.9},
            (0.85, 1.1),
            0.95,
        ),
        "mentalis": ({"mentalis_l": 0.9, "mentalis_r": 0.9}, (0.6, 1.1), 0.7),
    }
    for name, (apex, (lo, hi), least) in cases.items():
        truth, ref, pts, unsure = _render_ramp(fm, apex, ramp, tmp_path / f"{name}.mp4")
        for alignment in fidelity.ALIGNMENTS:
            d_out, side = fidelity.model_displacements(fm, truth, None, JUDGED_REGIONS, alignment)
            d_in = fidelity.input_displacements(ref, pts, side, JUDGED_REGIONS, alignment, unsure)
            s = scores(d_out["chin"], d_in["chin"])  # the reading over the truth
            assert s.rms_in > 0.01, (name, s)  # the chin moved
            assert lo <= s.gain <= hi and s.explained >= least, (name, alignment, s)


def _render_ramp(fm, apex, ramp, video):
    """The contractions ``apex`` ({muscle: contraction}) scaled by each of ``ramp``, the
    person's face ``fm`` rendered so (384 px, 10 frames/s) to ``video`` and read by the judge's
    reader from frame 0: (the contractions (T, M), reference points, points, unsure)."""
    from myoface.analysis import fidelity

    truth = np.array([fm.validate({k: x * a for k, x in apex.items()}) for a in ramp])
    ref, pts, unsure = fidelity.render_and_read(fm, truth, video)
    return truth, ref, pts, unsure


def test_the_stages_score_mediapipe_against_the_reader():
    """fidelity.json's ``stages`` (:func:`~myoface.analysis.fidelity._stages`): MediaPipe's
    points read like the input's side and scored against the judge's reading. Given the
    judge's own points, MediaPipe scores gain 1 and explains all of it; given half of their
    motion, gain 0.5 (explained 0.75); the model against MediaPipe's points is the model
    against that reading."""
    from myoface.analysis.fidelity import (
        POINTS,
        _stages,
        input_displacements,
        model_displacements,
    )
    from myoface.model import build_face_model

    fm = build_face_model()
    table = np.zeros((3, fm.n_muscles))
    for k, c in ((1, 0.5), (2, 1.0)):
        table[k, fm.ids.index("zygomaticus_major_l")] = c
        table[k, fm.ids.index("zygomaticus_major_r")] = c
    ok = np.ones(3, dtype=bool)
    d_out, side = model_displacements(fm, table, ok, JUDGED_REGIONS)
    # the judge's reading: the model's own points, frontal, as pixels (image axes already)
    from myoface.analysis.fidelity import model_points

    pts, _, _ = model_points(fm, table, ok)
    px = pts * 2.0 + 300.0
    d_in = input_displacements(px[0], px, side, JUDGED_REGIONS)

    def mediapipe(points):
        lm = np.zeros((3, 468, 3))
        lm[:, list(POINTS), :2] = points
        return lm

    same = _stages(mediapipe(px), [0, 1, 2], ok, 0, side, d_in, d_out, None)
    mc = same["mediapipe_vs_judge"]["mouth_corners"]
    assert mc["gain"] == pytest.approx(1.0, abs=1e-6) and mc["explained"] == pytest.approx(1.0)
    half = _stages(mediapipe(px[0] + 0.5 * (px - px[0])), [0, 1, 2], ok, 0, side, d_in, d_out, None)
    mc = half["mediapipe_vs_judge"]["mouth_corners"]
    assert mc["gain"] == pytest.approx(0.5, abs=0.02) and mc["explained"] == pytest.approx(
        0.75, abs=0.03
    )
    assert half["model_vs_mediapipe"]["mouth_corners"]["gain"] == pytest.approx(2.0, rel=0.05)
    assert _stages(mediapipe(px) * np.nan, [0, 1, 2], ok, 0, side, d_in, d_out, None) is None


@needs_mediapipe
@pytest.mark.slow
@pytest.mark.parametrize(
    "turn",
    [
        0.0,
        pytest.param(
            0.1,
            marks=pytest.mark.xfail(
                strict=True,
                reason="known limit of the judge (myoface.bench.judge): its 3-D alignment "
                "fits eight rigid points with a prior on the turn out of the image plane and "
                "leaves part of a turn's parallax; with the head turning +-3 deg in yaw and "
                "+-1.5 in pitch and roll it scores the exact truth 0.93 overall on these 30 "
                "frames (0.93 on 90), the brows 0.88 and the eyelids 0.66 (0.68, 0.53 and "
                "0.39 before 2026-12-06's forward-backward check in proportion to the face)",
            ),
        ),
    ],
)
def test_the_judge_scores_the_exact_truth_near_one_as_the_head_turns(turn):
    """The judge on renders of the person's face playing known contractions, the head
    following the head-motion benchmark's trajectory scaled by ``turn``, the model side driven
    by the true contractions: near 1 overall and in the regions the judge scores best (the
    eyelids' reader reads renders short, READER_VALIDATION)."""
    from myoface.bench.judge import judge_on_turning_renders

    res, _ = judge_on_turning_renders(turn, n_frames=30)
    assert res.overall.explained >= 0.9 and 0.9 <= res.overall.gain <= 1.1, res.overall
    for region in ("lower_lip", "brows", "chin"):
        assert res.regions[region].explained >= 0.9, (region, res.regions[region])


@needs_mediapipe
def test_the_judge_on_a_resynthesis_scores_its_known_answer(tmp_path):
    """:func:`~myoface.analysis.fidelity.judge_on_resynthesis` renders a face at given
    contractions, reads the render with the judge's reader and scores it against the model's
    own vertices: on a smile with the brows raised (a motion the reader is validated on) it
    scores near 1 where the face moves, every region has its share of unsure readings, and a
    face that does not move has no score (nothing to explain)."""
    from myoface.analysis.fidelity import judge_on_resynthesis
    from myoface.model import build_face_model

    fm = build_face_model()
    apex = {m: 0.8 for m in ("zygomaticus_major_l", "zygomaticus_major_r")}
    apex.update({f"frontalis_{p}_{s}": 0.7 for p in ("inner", "outer") for s in "lr"})
    ramp = (0.0, 0.3, 0.6, 0.9, 0.9, 0.6, 0.3, 0.0)
    table = np.array([fm.validate({k: v * a for k, v in apex.items()}) for a in ramp])
    out = judge_on_resynthesis(fm, table, tmp_path / "smile.mp4")
    assert set(out) == {*JUDGED_REGIONS, "overall"}
    assert out["overall"]["explained"] >= 0.9, out
    for region in ("mouth_corners", "brows"):
        assert 0.85 <= out[region]["gain"] <= 1.1 and out[region]["explained"] >= 0.9, out
    assert all(0.0 <= out[r]["unsure"] <= 1.0 for r in JUDGED_REGIONS)
    still = judge_on_resynthesis(fm, np.zeros((3, fm.n_muscles)), tmp_path / "still.mp4")
    assert still["overall"]["explained"] is None and still["brows"]["gain"] is None, still


def _encoded(path, frames, size=None):
    """``frames`` written as H.264 (crf 18), resized to ``size`` (w, h) first if given."""
    import cv2

    from myoface.render import VideoWriter

    with VideoWriter(path, fps=30, quality_crf=18, preset="medium") as vw:
        for f in frames:
            vw.write(f if size is None else cv2.resize(f, size, interpolation=cv2.INTER_CUBIC))
    return path


@needs_mediapipe
@pytest.mark.shared_data
def test_a_large_face_is_read_at_the_readers_scale(tmp_path):
    """``single_face.mp4`` filmed at three times the resolution (1920 x 1080, as a phone
    films; its face 298 px between the outer eye corners) is read as its 640 x 360 frames are
    (both encoded alike), the measure's way (the head's motion taken out in 3-D, the frames
    whose readings fail the forward-backward check about the eyes fitted to the nose ridge,
    :func:`input_displacements`): about as many readings fail that check, and each judged
    region's displacements are within 0.02 inter-ocular distances RMS of the 640 x 360
    reading's, the mouth corners' (read on the lips' slit) within 0.07 (the 640 x 360 frames
    encoded again move them by up to 0.007, the corners 0.028). Measured 2026-12-06: read at
    the video's own resolution with a 1 px check (before
    :data:`~myoface.analysis.motionreader.READER_IOD_PX`) 39 % of the readings failed the
    check against 10 %, and the regions were 0.006-0.082 off (the chin 0.082, the lower lip
    0.064, the brows 0.052, the corners 0.067); as now, 14 %, and 0.003-0.016 (the corners
    0.039)."""
    from myoface.analysis.fidelity import (
        JUDGED_REGIONS,
        POINTS,
        input_displacements,
        read_video_points,
    )
    from myoface.analysis.video import open_video
    from myoface.face.personal import face_from_photo

    path = shared_path("video", "single_face.mp4")
    if not path.exists():
        pytest.skip("../shared/data/video/single_face.mp4 is not here")
    frames = open_video(path).read_all()
    small = _encoded(tmp_path / "360.mp4", frames)
    large = _encoded(tmp_path / "1080.mp4", frames, (1920, 1080))
    face, _ = face_from_photo(frames[0])
    side = {"neutral_3d": face.vertices[list(POINTS)].astype(np.float64)}
    got, failing = {}, {}
    for name, video in (("small", small), ("large", large)):
        ref, pts, unsure, _ = read_video_points(video, list(range(len(frames))), 0)
        got[name] = input_displacements(ref, pts, side, JUDGED_REGIONS, "3d", unsure)
        failing[name] = float(unsure.mean())
    assert failing["large"] <= failing["small"] + 0.1, failing
    for region in JUDGED_REGIONS:
        a, b = got["small"][region], got["large"][region]
        ok = np.isfinite(a).all(-1) & np.isfinite(b).all(-1)
        diff = float(np.sqrt(((a[ok] - b[ok]) ** 2).sum(-1).mean()))
        assert diff <= (0.07 if region == "mouth_corners" else 0.02), (region, diff)


def test_frames_the_judge_cannot_read_are_left_out_and_said():
    """A frame most of whose readings fail the reader's forward-backward check is not judged
    (:func:`~myoface.analysis.fidelity.unjudged`: more than half), the result counts it, and
    the report says so: "not measurable" when the judge read fewer than half of the measured
    frames (the scores over those it read given beside it), else how many it read."""
    from myoface.analysis.fidelity import FidelityResult, Scores, unjudged
    from myoface.commands.analyze import fidelity_lines

    unsure = np.zeros((4, 10), bool)
    unsure[1, :5] = True  # half: still judged
    unsure[2, :6] = True  # more than half: not
    unsure[3] = True
    np.testing.assert_array_equal(unjudged(unsure), [False, False, True, True])

    s = Scores(0.8, 0.9, 0.95, 0.05, 0.045)
    regions = {"mouth_corners": s}

    def result(n, lost):
        return FidelityResult(s, regions, 0, n, 2, reader="DIS from frame 0", frames_unjudged=lost)

    ok = result(70, 0)
    assert ok.valid and ok.coverage == 1.0 and ok.as_dict()["valid"] is True
    line = fidelity_lines(ok)[0]
    assert line.startswith("fidelity: 0.80 of the input's") and "could not" not in line
    some = result(60, 10)
    assert some.valid and "60 of the 70 measured frames" in fidelity_lines(some)[0]
    few = result(30, 70)
    assert not few.valid and few.as_dict()["judge_coverage"] == 0.3
    line = fidelity_lines(few)[0]
    assert line.startswith("fidelity: not measurable on this video")
    assert "could not read 70 of the 100 measured frames" in line and "0.80" in line
