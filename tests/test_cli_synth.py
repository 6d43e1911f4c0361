"""``myoface synth`` and ``myoface demo`` from the command line."""

import csv

import numpy as np
import pytest

from myoface.cli import main
from tests.conftest import REPO, needs_mediapipe, shared_path


def one_line_error(capsys, argv, match, code=1):
    assert main(argv) == code
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[0], err


#: H.264 (libx264, crf 18, yuv420p) changes a small face render by 2-3 grey levels on average
#: (the RGB -> YUV 4:2:0 -> RGB round trip and the quantisation): the tolerance of a video
#: frame against the direct render
CODEC_MAD_LEVELS = 3.0


@pytest.fixture(scope="module")
def model():
    from myoface.model import build_face_model

    return build_face_model()


def _neutral(model, size, ssaa=2):
    """The rest face rendered as ``myoface synth`` renders it (front camera, default texture)."""
    from myoface.render import Renderer
    from myoface.synth import make_camera

    cam = make_camera(model.face.vertices, "front", size, size)
    return Renderer(model.face, cam, ssaa=ssaa).render(model.skin_vertices(model.rest_state()))


def _box(model, size, *groups, pad=1.0):
    """(row slice, column slice) around the landmark ``groups`` on the neutral face, ``pad`` px
    wider, in a front view of ``size`` px."""
    from myoface.synth import make_camera

    lm = model.face.landmarks
    idx = np.concatenate([np.atleast_1d(lm[g]) for g in groups])
    p = make_camera(model.face.vertices, "front", size, size).project(model.face.vertices[idx])
    (x0, y0), (x1, y1) = np.floor(p[:, :2].min(0) - pad), np.ceil(p[:, :2].max(0) + pad)
    return slice(int(y0), int(y1) + 1), slice(int(x0), int(x1) + 1)


def _codec_mad(img, tmp_path) -> float:
    """What H.264 (the writer's settings) alone changes ``img`` by, on average: the tolerance of
    a video frame against its direct render is this plus a level (rounding of the rest state's
    shading). Small faces have more edge per pixel, so it grows as the size shrinks."""
    import imageio.v3 as iio

    from myoface.render import VideoWriter

    path = tmp_path / f"codec_{img.shape[0]}.mp4"
    with VideoWriter(path, fps=10) as vw:
        for _ in range(3):
            vw.write(img.astype(np.uint8))
    coded = iio.imread(path, plugin="pyav").astype(int)
    return float(np.abs(coded - img.astype(int)).mean(axis=(1, 2, 3)).max())


def _background_rows(height):
    """The renderer's background: a vertical gradient between two linear colours, in sRGB."""
    from myoface.render import to_srgb8
    from myoface.render.renderer import BACKGROUND_BOTTOM, BACKGROUND_TOP

    t = np.linspace(0, 1, height)[:, None]
    return to_srgb8(np.array(BACKGROUND_TOP) * (1 - t) + np.array(BACKGROUND_BOTTOM) * t)


def _check_face_visible(img, corner=6, tol=1):
    """The background at the four corners (to ``tol`` levels: 1 for the rounding of a PNG,
    the codec's 3 in a video's flat corners), the skin in the centre (red over green over blue,
    and brighter than any of the background)."""
    h, w, _ = img.shape
    bg = _background_rows(h).astype(int)
    for rows in (slice(0, corner), slice(h - corner, h)):
        for cols in (slice(0, corner), slice(w - corner, w)):
            diff = np.abs(img[rows, cols].astype(int) - bg[rows, None, :])
            assert diff.max() <= tol, (rows, cols, diff.max())
    c = img[h // 2 - 2 : h // 2 + 3, w // 2 - 2 : w // 2 + 3].reshape(-1, 3).astype(int)
    assert (c[:, 0] > c[:, 1]).all() and (c[:, 1] > c[:, 2]).all(), c
    assert c[:, 0].min() > 2 * bg.max(), c


def test_synth_png_from_aus(model, tmp_path, capsys):
    import imageio.v3 as iio

    out = tmp_path / "smile.png"
    argv = ["synth", "--au", "12=0.7", "--au", "6=0.4", "-o", str(out)]
    assert main([*argv, "--width", "96", "--height", "96", "--ssaa", "1"]) == 0
    img = iio.imread(out)
    assert img.shape == (96, 96, 3)
    _check_face_visible(img)
    # The smile (AU12, the lip corner puller: zygomaticus major, inserting at the mouth
    # corners) moves the mouth corners by pixels: across the lips' edges and shading, a good
    # part (a quarter) of a 9 x 9 px patch around each corner changes by more than 10 levels.
    # The forehead, far from the muscles AU12 drives and reached only at its lower edge by
    # AU6's orbital orbicularis oculi (its skin moves under 0.2 mm there, a tenth of a pixel
    # at 96 px for a 150 mm face, which changes the shading's smooth gradients by a level or
    # two), stays as it was: at most 3 levels (PNG is lossless), where the corners change by
    # tens.
    diff = np.abs(img.astype(int) - _neutral(model, 96, ssaa=1).astype(int)).max(axis=2)
    for side in "lr":
        rows, cols = _box(model, 96, f"mouth_corner_{side}", pad=4)
        assert (diff[rows, cols] > 10).mean() > 0.25, side
    rows, cols = _box(model, 96, "forehead", pad=2)
    assert diff[rows, cols].max() <= 3, diff[rows, cols].max()


def test_synth_without_control_renders_the_neutral_face(model, tmp_path, capsys):
    """No expression, AU, muscle, viseme or timeline: the face at rest, as
    the renderer draws the rest state (PNG is lossless: at most a level of rounding)."""
    import imageio.v3 as iio

    out = tmp_path / "neutral.png"
    assert main(["synth", "-o", str(out), "--width", "96", "--height", "96", "--ssaa", "1"]) == 0
    capsys.readouterr()
    img = iio.imread(out)
    _check_face_visible(img)
    assert np.abs(img.astype(int) - _neutral(model, 96, ssaa=1).astype(int)).max() <= 1


def test_synth_video_expression_and_timeline(model, tmp_path, capsys):
    import imageio.v3 as iio

    out = tmp_path / "s.mp4"
    argv = ["synth", "--expression", "surprise", "--intensity", "0.8", "--duration", "0.4"]
    argv += ["--fps", "10", "-o", str(out), "--width", "64", "--height", "64", "--quiet"]
    assert main(argv) == 0
    frames = iio.imread(out, plugin="pyav").astype(int)
    # the event (0.4 s) with 0.25 s of rest before and after, at 10 fps, both ends included
    assert frames.shape == (int(round((0.4 + 0.5) * 10)) + 1, 64, 64, 3)
    neutral = _neutral(model, 64).astype(int)
    mad = np.abs(frames - neutral).mean(axis=(1, 2, 3))
    # at rest before and after the event: the neutral face, within the codec's tolerance
    tol = _codec_mad(neutral, tmp_path) + 1
    assert mad[0] < tol and mad[-1] < tol, (mad, tol)
    # at the apex (t = 0.5 s, in the hold) the brows rise and the jaw drops: around them the
    # frame differs from the neutral face by more than twice what the codec changes there
    apex = len(frames) // 2
    for groups in (("eyebrow_l", "eyebrow_r"), ("lip_lower_outer", "chin")):
        rows, cols = _box(model, 64, *groups)
        d = np.abs(frames[:, rows, cols] - neutral[rows, cols]).mean(axis=(1, 2, 3))
        assert d[apex] > 2 * max(d[0], d[-1]), (groups, d)
    out2 = tmp_path / "talk.mp4"
    talk = REPO / "examples" / "talk.toml"
    argv = ["synth", "--timeline", str(talk), "--fps", "5", "-o", str(out2)]
    assert main([*argv, "--width", "48", "--height", "48", "--quiet"]) == 0
    from myoface.control import load_timeline

    frames = iio.imread(out2, plugin="pyav").astype(int)
    assert frames.shape == (int(round(load_timeline(talk).duration * 5)) + 1, 48, 48, 3)
    neutral = _neutral(model, 48).astype(int)
    # nothing happens before the first event (0.2 s): the neutral face
    tol = _codec_mad(neutral, tmp_path) + 1
    assert np.abs(frames[0] - neutral).mean() < tol, tol
    # then the mouth speaks: around the lips, some frame differs from the neutral face by more
    # than twice what the codec changes there in the first
    rows, cols = _box(model, 48, "lip_upper_outer", "lip_lower_outer")
    d = np.abs(frames[:, rows, cols] - neutral[rows, cols]).mean(axis=(1, 2, 3))
    assert d.max() > 2 * d[0], d


@pytest.mark.parametrize(
    ("extra", "match", "code"),
    [
        (["--au", "3=0.5"], "unknown action unit AU3", 1),
        # a number outside its limits is a usage error (README: exit status 2)
        (["--au", "12=3"], "must be in [0, 1]; got '3'", 2),
        (["--expression", "joy"], "unknown expression 'joy'", 1),
        (["--muscle", "zygomaticus=2"], "must be in [0, 1]", 2),
        (["--au", "12=0.5", "--texture", "/nonexistent/skin.png"], "no such texture image", 1),
    ],
)
def test_synth_bad_input(tmp_path, capsys, extra, match, code):
    out = tmp_path / "x.png"
    one_line_error(
        capsys, ["synth", *extra, "-o", str(out), "--width", "32", "--height", "32"], match, code
    )
    assert not out.exists() and not list(tmp_path.iterdir())


def test_synth_unwritable_output(tmp_path, capsys):
    one_line_error(
        capsys,
        ["synth", "--au", "12=0.5", "-o", str(tmp_path / "no" / "x.png")],
        "output folder does not exist",
    )


DEMO_ARGV = ["demo", "--size", "64", "--no-video", "--quiet", "--offline"]


def _check_demo_images(model, out):
    """expressions.png: the contact sheet, 3 x 2 panels of 3.2 x 3.5 inches at 110 dpi, a face
    in each; muscles.png: the three-quarter view, unchanged (lossless PNG) except along the 29
    muscle vectors, which are drawn all along."""
    import imageio.v3 as iio

    from myoface.render import Renderer
    from myoface.synth import make_camera, muscle_segments

    sheet = iio.imread(out / "expressions.png")[..., :3].astype(int)
    assert sheet.shape == (round(3.5 * 2 * 110), round(3.2 * 3 * 110), 3), sheet.shape
    skin = (sheet[..., 0] > sheet[..., 1]) & (sheet[..., 1] > sheet[..., 2])
    skin &= sheet[..., 0] > 150
    for band in np.array_split(skin, 2, axis=0):
        for cell in np.array_split(band, 3, axis=1):
            assert cell.mean() > 0.1, cell.mean()  # a face covers a good part of its panel
    img = iio.imread(out / "muscles.png").astype(int)
    assert img.shape == (64, 64, 3)
    cam = make_camera(model.face.vertices, "three_quarter", 64, 64)
    plain = Renderer(model.face, cam).render().astype(int)
    changed = np.argwhere(np.abs(img - plain).max(axis=2) > 0)[:, ::-1] + 0.5  # pixel centres
    ins, org = muscle_segments(model)
    a, b = cam.project(ins)[:, :2], cam.project(org)[:, :2]
    t = np.linspace(0, 1, 50)[:, None, None]
    samples = a[None] + t * (b - a)[None]  # (50, 29, 2) points along each muscle
    d = np.linalg.norm(changed[:, None, None] - samples[None], axis=3)  # (pixels, 50, 29)
    # Drawn along each muscle: every point of it within 1 px of a changed pixel (the line
    # is splatted onto the 2 x 2 pixels around each of its points).
    assert (d.min(axis=0) < 1.0).all()
    # Nothing else changes: every changed pixel within 4 px of a muscle (the splat, 0.7 px;
    # the attachment's dot, 2.4 px long and 3 px thick, up to 1.2 + 1 + 1 = 3.2 px along and
    # 2 px across from the attachment: 3.8 px).
    assert d.min(axis=(1, 2)).max() < 4.0


@needs_mediapipe
def test_demo_real_video(model, tmp_path, monkeypatch, capsys):
    """The demo's real-video branch, on the sample video from ../shared/data (put in a fresh
    cache folder, so that --offline finds it; MediaPipe tracks it)."""
    import json
    import shutil

    import imageio.v3 as iio

    from myoface.model import load_face_model

    cache = tmp_path / "cache"
    cache.mkdir()
    sample = cache / "single_face.mp4"
    shutil.copy(shared_path("video", "single_face.mp4"), sample)
    monkeypatch.setenv("MYOFACE_CACHE", str(cache))
    out = tmp_path / "demo"
    assert main([*DEMO_ARGV, "-o", str(out)]) == 0
    text = capsys.readouterr().out
    assert f"analysing the sample face video {sample}" in text and "synthetic" not in text
    assert f"output folder: {out.resolve()}" in text
    _check_demo_images(model, out)
    ana = out / "analysis"
    # the lines of myoface analyze --report, resynth and face from-photo, in their order
    said = [
        "fidelity: ",
        "fidelity, MediaPipe's face mesh on both (earlier reports' measure",
        # (the sample's broad smile holds muscles at the model's limit: said, with the share)
        "note: ",
        f"analysed 72 frames (72 measured, against frame 0 as the neutral); output folder: "
        f"{ana.resolve()}",
        f"wrote {ana / 'resynth.mp4'} (72 frames at 30.0 fps)",
        "face found ",
        f"wrote {ana / 'person.png'}",
        f"wrote {ana / 'person.myoface'}",
        "lips       inner lips at rest ",  # (issue 34: the person's rest gap)
        f"wrote {ana / 'resynth_person.mp4'} (72 frames at 30.0 fps)",
    ]
    lines = text.splitlines()
    k = lines.index(
        f"analysing the sample face video {sample} (the 3-D fit to its pixels and "
        "MediaPipe's face mesh)"
    )
    assert [a[: len(b)] for a, b in zip(lines[k + 1 :], said, strict=False)] == said, lines
    # the note names the smile's muscles held at the limit, as analysis.json has them
    limit = json.loads((ana / "analysis.json").read_text())["at_limit"]
    assert limit.get("zygomaticus_major_l", 0) >= 0.1 and "zygomaticus_major_l" in lines[k + 3]
    video = iio.imread(sample, plugin="pyav")
    assert video.shape == (72, 360, 640, 3)
    with open(ana / "contractions.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(video) and all(r["quality"] == "ok" for r in rows)
    # the video is neutral -> smile -> neutral: teeth shown from frame 24 to 66
    for s in "lr":
        z = np.array([float(r[f"zygomaticus_major_{s}"]) for r in rows])
        assert np.median(z[24:67]) > 0.5 > 2 * np.median(z[:12]), z
    # input | resynthesis, 360 rows, the input (640 x 360) unscaled on the left
    for name in ("resynth.mp4", "resynth_person.mp4"):
        sbs = iio.imread(ana / name, plugin="pyav")
        assert sbs.shape == (72, 360, 640 + 360, 3), name
        every = slice(None, None, 6)  # every 6th frame is enough to see it is the input
        left = np.abs(sbs[every, :, :640].astype(np.int16) - video[every]).mean(axis=(1, 2, 3))
        assert left.max() < CODEC_MAD_LEVELS, (name, left.max())
        _check_face_visible(sbs[0, :, 640:], corner=20, tol=CODEC_MAD_LEVELS)
    # the resynthesis' first frame is the default face driven by the CSV's first row
    from myoface.analysis.contractions_csv import read_contractions_csv
    from myoface.render import Renderer
    from myoface.synth import Synthesizer, make_camera

    _, table, _ = read_contractions_csv(ana / "contractions.csv", list(model.ids))
    cam = make_camera(model.face.vertices, "front", 360, 360)
    direct = Synthesizer(model, Renderer(model.face, cam)).image(table[0]).astype(int)
    sbs = iio.imread(ana / "resynth.mp4", plugin="pyav", index=0).astype(int)
    assert np.abs(sbs[:, 640:] - direct).mean() < CODEC_MAD_LEVELS
    # the person's own face: the default topology, reshaped (by millimetres) to the video's
    person = load_face_model(ana / "person.myoface")
    assert person.face.vertices.shape == model.face.vertices.shape
    assert np.abs(person.face.vertices - model.face.vertices).max() > 1.0
    preview = iio.imread(ana / "person.png")
    assert preview.ndim == 3 and preview[..., :3].std() > 10
    # --report: the fidelity of the person's resynthesis, every frame compared
    fid = json.loads((ana / "fidelity.json").read_text())
    assert fid["frames_compared"] == len(video) and "face_from_photo" in fid["face"]
    assert fid["input_reader"]["method"] == "dis" and fid["mediapipe_on_both"] is not None


@needs_mediapipe
def test_demo_reports_a_failing_step_as_its_own_error(tmp_path, monkeypatch, capsys):
    """A step of the demo's loop that fails (the cached sample video is not a video) is the
    demo's error: one line, "myoface demo: error: ...", exit status 1 returned (not a
    SystemExit), and the output folder it made removed."""
    cache = tmp_path / "cache"
    cache.mkdir()
    (cache / "single_face.mp4").write_bytes(b"not a video")
    monkeypatch.setenv("MYOFACE_CACHE", str(cache))
    out = tmp_path / "demo"
    assert main([*DEMO_ARGV, "-o", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("myoface demo: error: "), err
    assert "single_face.mp4" in err[0] and "not a readable video" in err[0], err
    assert not out.exists()


@pytest.mark.slow
def test_demo_synthetic_fallback(model, tmp_path, monkeypatch, capsys):
    """Offline with nothing cached (or without MediaPipe), the demo analyses a synthetic
    video of the model smiling with the jaw dropping, and resynthesizes it."""
    import imageio.v3 as iio

    monkeypatch.setenv("MYOFACE_CACHE", str(tmp_path / "empty-cache"))
    out = tmp_path / "demo"
    assert main([*DEMO_ARGV, "-o", str(out)]) == 0
    text = capsys.readouterr().out
    ana = out / "analysis"
    assert f"analysing the synthetic video {ana / 'synthetic_smile.mp4'}" in text
    _check_demo_images(model, out)
    assert not (ana / "person.myoface").exists()
    # the demo's smile: 6 neutral frames, a 12-frame rise to 0.8, 12 held, and back; the jaw
    # at 0.4 of it
    env = np.concatenate([np.zeros(6), np.linspace(0, 0.8, 12), np.full(12, 0.8)])
    env = np.concatenate([env, env[::-1]])
    video = iio.imread(ana / "synthetic_smile.mp4", plugin="pyav")
    assert video.shape == (len(env), 256, 256, 3)
    with open(ana / "contractions.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(env) and all(r["quality"] == "ok" for r in rows)
    # Recovered: each curve correlates with its truth (>= 0.95, as the closed loop requires)
    # and its RMSE is under 0.3 of a constant guess's (the truth's standard deviation).
    for m, truth in [
        ("zygomaticus_major_l", env),
        ("zygomaticus_major_r", env),
        ("jaw", 0.4 * env),
    ]:
        est = np.array([float(r[m]) for r in rows])
        rmse = np.sqrt(np.mean((est - truth) ** 2))
        assert np.corrcoef(est, truth)[0, 1] > 0.95 and rmse < 0.3 * truth.std(), (m, rmse)
    sbs = iio.imread(ana / "resynth.mp4", plugin="pyav")
    assert sbs.shape == (len(env), 360, 360 + 360, 3)  # the 256 px input scaled to 360 rows
    _check_face_visible(sbs[0, :, 360:], corner=20, tol=CODEC_MAD_LEVELS)


def test_the_first_run_on_a_new_install_says_it_compiles(monkeypatch, tmp_path):
    """``myoface demo``'s note on a new install (numba compiles the kernels then, several times
    the run's later length): said while the tissue solver's kernel is not in numba's cache,
    not once it is."""
    from myoface.commands._common import first_run_note
    from myoface.tissue.solver import _newton

    index = tmp_path / "solver._newton.nbi"
    monkeypatch.setattr(_newton._cache._cache_file, "_index_path", str(index))
    note = first_run_note()
    assert note is not None and "compiles myoface's kernels" in note
    index.write_bytes(b"")
    assert first_run_note() is None
