"""``myoface resynth`` writes one frame per CSV row, each the model's render for that row."""

import numpy as np
import pytest

from myoface.cli import main

SIZE = 128
#: H.264 (libx264, crf 18, yuv420p) changes a 128x128 face render by about 2 grey levels on
#: average (the RGB -> YUV 4:2:0 -> RGB round trip and the quantisation): the tolerance of a
#: frame against the direct render
CODEC_MAD_LEVELS = 3.5
# (3.0 until the default face rested with its lips closed: the lips' edge, now drawn at rest,
# left a frame of the resynthesis 3.007 levels from its direct render, 2026-12-02; each frame
# is still nearer its own render than any other frame is, which the test checks too)


@pytest.fixture(scope="module")
def model():
    from myoface.model import build_face_model

    return build_face_model()


def _table(model):
    """Six rows whose neighbours look clearly different: a smile and the jaw going up and down."""
    ids = list(model.ids)
    table = np.zeros((6, len(ids)))
    zyg = [ids.index("zygomaticus_major_l"), ids.index("zygomaticus_major_r")]
    for k, (smile, jaw) in enumerate([(0, 0), (1, 0), (0.2, 0.8), (1, 0.3), (0, 1), (0.6, 0)]):
        table[k, zyg] = smile
        table[k, ids.index("jaw")] = jaw
    return table


def _write_csv(path, model, table, fps=10.0):
    from myoface.analysis.contractions_csv import write_contractions_csv
    from myoface.analysis.trackers.base import FrameMeasurement

    frames = [FrameMeasurement(k, k / fps, "ok", row, np.zeros(2)) for k, row in enumerate(table)]
    write_contractions_csv(path, list(model.ids), frames, model.muscles.jaw.max_angle_rad)


def _direct_renders(model, table):
    from myoface.render import Renderer
    from myoface.synth import Synthesizer, make_camera

    cam = make_camera(model.face.vertices, "front", SIZE, SIZE)
    syn = Synthesizer(model, Renderer(model.face, cam))
    return np.array([syn.image(c) for c in table]).astype(np.int16)


def test_resynth_frames_match_direct_renders(model, tmp_path, capsys):
    import imageio.v3 as iio

    table = _table(model)
    csv = tmp_path / "contractions.csv"
    _write_csv(csv, model, table)
    out = tmp_path / "resynth.mp4"
    assert main(["resynth", str(csv), "-o", str(out), "--size", str(SIZE), "--quiet"]) == 0
    assert "6 frames at 10.0 fps" in capsys.readouterr().out
    video = iio.imread(out, plugin="pyav").astype(np.int16)
    assert video.shape == (len(table), SIZE, SIZE, 3)  # one frame per CSV row
    direct = _direct_renders(model, table)
    assert np.abs(video - direct).mean(axis=(1, 2, 3)).max() < CODEC_MAD_LEVELS
    # the direct renders through the same encoder: each video frame is its own row's render
    # (to well under a grey level), and clearly not a neighbouring row's
    from myoface.render import VideoWriter

    with VideoWriter(tmp_path / "direct.mp4", fps=10.0) as vw:
        for img in direct:
            vw.write(img.astype(np.uint8))
    coded = iio.imread(tmp_path / "direct.mp4", plugin="pyav").astype(np.int16)
    mad = np.abs(video[:, None] - coded[None]).mean(axis=(2, 3, 4))  # (video k, render j)
    others = mad + np.diag(np.full(len(table), np.inf))
    assert mad.diagonal().max() < 0.25, mad
    assert others.min() > 1.0, mad  # the rows are different enough for this test to fail


def test_write_video_is_the_frames(model, tmp_path):
    """Synthesizer.write_video (background encoding) writes exactly what the serial loop would."""
    import imageio.v3 as iio

    from myoface.render import Renderer, VideoWriter
    from myoface.synth import Synthesizer, make_camera

    table = _table(model)[:4]
    times = np.arange(len(table)) / 10.0
    cam = make_camera(model.face.vertices, "front", 64, 64)
    a = Synthesizer(model, Renderer(model.face, cam))
    a.write_video(table, times, tmp_path / "a.mp4", 10.0, show_progress=False)
    assert len(a.stats.encode_ms) == len(a.stats.relax_ms) == len(table)
    b = Synthesizer(model, Renderer(model.face, cam))
    with VideoWriter(tmp_path / "b.mp4", 10.0) as vw:
        for img in b.frames(table, times):
            vw.write(img)
    va, vb = (iio.imread(tmp_path / f"{n}.mp4", plugin="pyav") for n in "ab")
    assert va.shape == (len(table), 64, 64, 3)
    np.testing.assert_array_equal(va, vb)


def test_resynth_side_by_side_too_short(model, tmp_path, capsys):
    from myoface.render import VideoWriter

    table = _table(model)
    csv = tmp_path / "c.csv"
    _write_csv(csv, model, table)
    short = tmp_path / "short.mp4"
    with VideoWriter(short, 10.0) as vw:
        for _ in range(3):
            vw.write(np.zeros((32, 32, 3), np.uint8))
    out = tmp_path / "sbs.mp4"
    argv = ["resynth", str(csv), "-o", str(out), "--size", "32", "--quiet"]
    assert main([*argv, "--side-by-side", str(short)]) == 1
    assert "shorter than the CSV" in capsys.readouterr().err
    assert not out.exists()


def test_held_contractions_need_no_physics(model):
    """A row that repeats its predecessor (a held or neutral stretch) keeps the relaxed state;
    a state that is not known to be an equilibrium is relaxed even for the same row."""
    from myoface.render import Renderer
    from myoface.synth import Synthesizer, make_camera

    syn = Synthesizer(
        model, Renderer(model.face, make_camera(model.face.vertices, "front", 48, 48))
    )
    rest = syn.state
    syn.image(np.zeros(model.n_muscles))
    assert syn.state is rest  # the rest state is the equilibrium of no contraction
    c = _table(model)[3]
    first = syn.image(c)
    relaxed = syn.state
    assert relaxed is not rest and np.array_equal(relaxed.contractions, c)
    np.testing.assert_array_equal(syn.image(c), first)
    assert syn.state is relaxed and syn.stats.unconverged == 0
    syn.state = model.step(relaxed, c, n_steps=3)  # moved by dynamics: not an equilibrium
    syn.image(c)
    assert syn.state is not relaxed
    skin = model.skin_vertices
    assert np.abs(skin(syn.state) - skin(relaxed)).max() < 0.05  # mm, the same equilibrium


def test_read_performance_holds_unmeasured_rows(model, tmp_path):
    """The library's reading of a contractions.csv for resynthesis: a row the analysis did not
    measure holds the last measured one (zeros before the first), at the CSV's frame rate."""
    from myoface.analysis.contractions_csv import write_contractions_csv
    from myoface.analysis.resynthesis import read_performance
    from myoface.analysis.trackers.base import FrameMeasurement

    table = _table(model)
    lost = np.full(len(model.ids), np.nan)
    quality = ["no_face", "ok", "ok", "no_face", "no_face", "ok"]
    frames = [
        FrameMeasurement(k, k / 12.5, q, row if q == "ok" else lost, np.zeros(2))
        for k, (q, row) in enumerate(zip(quality, table, strict=True))
    ]
    csv = tmp_path / "c.csv"
    write_contractions_csv(csv, list(model.ids), frames, model.muscles.jaw.max_angle_rad)
    perf = read_performance(csv, model)
    assert perf.n_frames == 6 and perf.quality == quality and perf.poses is None
    assert perf.fps == pytest.approx(12.5, rel=1e-3)
    np.testing.assert_allclose(perf.times, np.arange(6) / 12.5, atol=1e-4)
    held = np.array([np.zeros(len(model.ids)), table[1], table[2], table[2], table[2], table[5]])
    np.testing.assert_allclose(perf.contractions, held, atol=1e-4)  # the CSV's 4 decimals


def test_read_performance_refuses_rows_no_video_can_show(model, tmp_path):
    from myoface.analysis.resynthesis import read_performance
    from myoface.errors import MyofaceValueError

    csv = tmp_path / "c.csv"
    _write_csv(csv, model, _table(model), fps=1000.0)  # 1 ms apart: a video has <= 240 fps
    with pytest.raises(MyofaceValueError, match=r"c\.csv: its rows are 0\.001 s apart"):
        read_performance(csv, model)


def test_resynthesis_frames_are_the_resynth_videos_frames(model, tmp_path):
    """The frames the fidelity measures (resynthesis_frames) are those myoface resynth
    encodes, to H.264's loss, each its own row's (the rows differ by far more)."""
    import imageio.v3 as iio

    from myoface.analysis.resynthesis import resynthesis_frames

    table = _table(model)
    csv = tmp_path / "c.csv"
    _write_csv(csv, model, table)
    out = tmp_path / "r.mp4"
    assert main(["resynth", str(csv), "-o", str(out), "--size", "64", "--quiet"]) == 0
    video = iio.imread(out, plugin="pyav").astype(np.int16)
    frames = np.array(list(resynthesis_frames(model, table, 64))).astype(np.int16)
    assert frames.shape == video.shape == (len(table), 64, 64, 3)
    mad = np.abs(video[:, None] - frames[None]).mean(axis=(2, 3, 4))  # (video k, frame j)
    assert mad.diagonal().max() < CODEC_MAD_LEVELS, mad
    assert (mad + np.diag(np.full(len(table), np.inf))).min() > mad.diagonal().max(), mad
