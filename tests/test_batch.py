"""``myoface batch`` on tiny synthetic videos rendered by the model (no MediaPipe: the contours
start from the model's projected sections), on a 2-worker Dask LocalCluster and locally."""

import csv
import json
import time

import numpy as np
import pytest

from myoface.cli import main

pytest.importorskip("distributed")
pd = pytest.importorskip("pandas")
pytest.importorskip("pyarrow")

SIZE = 128  # px; the snakes still find every contour of the rendered face


@pytest.fixture(scope="module")
def clips(tmp_path_factory):
    """smile.mp4 (rest, smile, rest), brows.mp4 (rest, brows raised twice), broken.mp4
    (random bytes) and init.json (the sections projected by the camera)."""
    from myoface.analysis.batch import cached_model
    from myoface.analysis.initfiles import save_init
    from myoface.analysis.sections import project_sections
    from myoface.render import Camera, Renderer, VideoWriter, to_srgb8
    from myoface.render.dressing import default_skin_texture

    d = tmp_path_factory.mktemp("clips")
    fm = cached_model()  # the same model the in-process engine uses
    cam = Camera.front(fm.face.vertices, width=SIZE, height=SIZE, fov_deg=None)
    r = Renderer(fm.face, cam, texture=to_srgb8(default_skin_texture(fm.face, 256, makeup=True)))
    rest = fm.rest_state()

    def render(c: dict):
        return r.render(fm.skin_vertices(fm.relax(c, rest).state if c else rest))

    zyg, brow = 0.8, 0.8
    f0 = render({})
    f_smile = render({"zygomaticus_major_l": zyg, "zygomaticus_major_r": zyg})
    f_brows = render({f"frontalis_{p}_{s}": brow for p in ("inner", "major") for s in "lr"})
    for name, frames in (("smile", (f0, f_smile, f0)), ("brows", (f0, f_brows, f_brows))):
        with VideoWriter(d / f"{name}.mp4", fps=10) as vw:
            for f in frames:
                vw.write(f)
    (d / "broken.mp4").write_bytes(np.random.default_rng(0).bytes(4096))
    save_init(d / "init.json", project_sections(fm, cam))
    return d


def _table(path) -> np.ndarray:
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    from myoface.analysis.sections import PAPER_MUSCLES

    return np.array([[float(r[m]) for m in PAPER_MUSCLES] for r in rows])


@pytest.mark.slow
def test_batch_dask_then_resume_then_local(clips, tmp_path, capsys):
    from myoface.analysis.batch import DONE_FILE, SUMMARY_COLUMNS
    from myoface.analysis.outputs import FOLDER_FILES
    from myoface.analysis.sections import PAPER_MUSCLES

    out = tmp_path / "out"
    argv = ["batch", str(clips / "*.mp4"), "--init", str(clips / "init.json"), "-o", str(out)]
    # one video is broken: recorded, the others analysed, exit status 1
    assert main([*argv, "--engine", "dask", "--workers", "2", "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "broken.mp4" in err[0] and "not a readable video" in err[0]
    for name in ("smile", "brows"):
        for f in (*FOLDER_FILES, DONE_FILE):
            assert (out / name / f).stat().st_size > 0, (name, f)
    assert not (out / "broken").exists()

    s = pd.read_parquet(out / "summary.parquet")
    assert list(s.columns) == [*SUMMARY_COLUMNS, *(f"mean_{m}" for m in PAPER_MUSCLES)]
    assert list(s["folder"]) == ["broken", "brows", "smile"]  # the pattern's matches, sorted
    s = s.set_index("folder")
    assert list(s["status"]) == ["failed", "ok", "ok"]
    assert "not a readable video" in s.loc["broken", "error"]
    assert s.loc["broken", "frames"] == 0 and np.isnan(s.loc["broken", "mean_jaw"])
    ok = s.loc[["brows", "smile"]]
    assert (ok["frames"] == 3).all() and (ok["measured_fraction"] == 1.0).all()
    assert (ok["error"] == "").all() and (ok["fps"] > 0).all() and (ok["wall_time_s"] > 0).all()
    # the means say which video smiled and which raised the brows
    zyg = "mean_zygomaticus_major_l"
    assert ok.loc["smile", zyg] > 0.25 and ok.loc["brows", zyg] < 0.05
    fro = "mean_frontalis_inner_l"
    assert ok.loc["brows", fro] > ok.loc["smile", fro] + 0.1
    c = pd.read_csv(out / "summary.csv").set_index("folder")
    assert list(c["status"]) == list(s["status"])
    np.testing.assert_allclose(c.loc[ok.index, zyg], ok[zyg], rtol=1e-5)

    # a second run skips the finished videos (their files untouched) and retries the broken one
    stamp = {n: (out / n / DONE_FILE).stat().st_mtime_ns for n in ("smile", "brows")}
    time.sleep(0.01)
    assert main([*argv, "--quiet"]) == 1
    s2 = pd.read_parquet(out / "summary.parquet").set_index("folder")
    assert list(s2["status"]) == ["failed", "skipped", "skipped"]
    np.testing.assert_array_equal(s2.loc[ok.index, zyg], ok[zyg])  # the first run's numbers
    assert {n: (out / n / DONE_FILE).stat().st_mtime_ns for n in stamp} == stamp

    # the local engine (here in this process, with the fixture's model) measures the same
    # contractions as the dask engine. Not to the last digit: Dask's workers run BLAS on one
    # thread (its nanny sets OMP_NUM_THREADS=1) and this process on every core, so sums are
    # added in another order; most values agree to the CSV's rounding, but a snake can settle
    # in a neighbouring position from a last-bit difference (a contraction 0.02 apart seen on
    # one frame of one run). So: the typical difference at rounding level, and none beyond the
    # analysis' accuracy target (0.05).
    loc = tmp_path / "local"
    good = [str(clips / "smile.mp4"), str(clips / "brows.mp4")]
    init = str(clips / "init.json")
    assert main(["batch", *good, "--init", init, "-o", str(loc), "--workers", "1"]) == 0
    for name in ("smile", "brows"):
        a, b = _table(out / name / "contractions.csv"), _table(loc / name / "contractions.csv")
        diff = np.abs(a - b)
        assert np.median(diff) <= 1e-4 and diff.max() < 0.05, (name, diff.max())
    side = json.loads((loc / "smile" / "analysis.json").read_text())
    assert side["video"] == str((clips / "smile.mp4").resolve()) and side["tracker"] == "snakes"


def test_batch_local_pool_records_each_failure(tmp_path, capsys):
    """The process pool (spawned workers) returns every video's row; a broken file fails
    before the worker builds a model."""
    rng = np.random.default_rng(0)
    for name in ("x", "y", "z"):
        (tmp_path / f"{name}.mp4").write_bytes(rng.bytes(2048))
    out = tmp_path / "out"
    assert (
        main(["batch", str(tmp_path / "*.mp4"), "-o", str(out), "--workers", "2", "--quiet"]) == 1
    )
    s = pd.read_parquet(out / "summary.parquet")
    assert list(s["folder"]) == ["x", "y", "z"] and (s["status"] == "failed").all()
    assert s["error"].str.contains("not a readable video").all()
    assert len(capsys.readouterr().err.strip().splitlines()) == 3


def test_an_error_a_stop_signal_caused_is_an_interruption_not_a_failed_video(tmp_path, monkeypatch):
    """A stop signal that lands inside a library comes out as that library's error (numba's
    cache, a C callback); analyze_job raises it as the interruption it is, so the batch stops
    and does not record the video as failed (a video of a batch stopped by Ctrl-C was in its
    summary as failed in CI); an ordinary error is still a failed row."""
    import signal

    from myoface._signals import Interrupted
    from myoface.analysis import batch

    job = batch._Job(str(tmp_path / "v.mp4"), str(tmp_path / "out"), "v", {})

    def cut_by_a_signal(path):
        try:
            raise Interrupted(signal.SIGTERM)
        except Interrupted as exc:
            raise RuntimeError("no compiled object yet") from exc

    monkeypatch.setattr(batch, "open_video", cut_by_a_signal)
    with pytest.raises(Interrupted) as got:
        batch.analyze_job(job)
    assert got.value.signum == signal.SIGTERM

    def broken(path):
        raise RuntimeError("a broken file")

    monkeypatch.setattr(batch, "open_video", broken)
    row = batch.analyze_job(job)
    assert row["status"] == "failed" and "a broken file" in row["error"]


def test_expand_videos(tmp_path):
    from myoface.analysis.batch import expand_videos

    for name in ("b.mp4", "a.mp4", "take[1].mp4", "out/a/overlay.mp4"):
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_bytes(b"x")
    got = expand_videos(
        [tmp_path / "take[1].mp4", str(tmp_path / "**" / "*.mp4"), tmp_path / "a.mp4"],
        exclude=tmp_path / "out",
    )
    # a file name with glob characters is a file; matches sorted, each once; OUT left out
    assert [p.name for p in got] == ["take[1].mp4", "a.mp4", "b.mp4"]


def test_result_folders_keep_names_with_their_videos(tmp_path):
    from myoface.analysis.batch import DONE_FILE, result_folders

    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    va, vb = tmp_path / "a" / "clip.mp4", tmp_path / "b" / "clip.mp4"
    for v in (va, vb):
        v.write_bytes(b"x")
    out = tmp_path / "out"
    assert result_folders([va, vb], out) == ["clip", "clip-2"]
    # "clip" holds b's finished result: a does not take it over when listed first
    (out / "clip").mkdir(parents=True)
    (out / "clip" / DONE_FILE).write_text(json.dumps({"video": str(vb)}))
    assert result_folders([va, vb], out) == ["clip-2", "clip"]


def test_summary_is_read_by_pandas(tmp_path):
    from myoface.analysis.batch import write_summary

    rows = [
        {
            "path": "/v/a.mp4",
            "folder": "a",
            "status": "ok",
            "error": "",
            "frames": 10,
            "measured_fraction": 0.9,
            "fps": 4.0,
            "wall_time_s": 2.5,
            "means": {"jaw": 0.25},
        },
        {
            "path": "/v/b.mp4",
            "folder": "b",
            "status": "failed",
            "error": "b.mp4: not a readable video",
            "frames": 0,
            "measured_fraction": float("nan"),
            "fps": float("nan"),
            "wall_time_s": 0.1,
            "means": {},
        },
    ]
    pq, cs = write_summary(rows, tmp_path)
    for s in (pd.read_parquet(pq), pd.read_csv(cs)):
        assert list(s["status"]) == ["ok", "failed"] and list(s["frames"]) == [10, 0]
        assert s["mean_jaw"].iloc[0] == 0.25 and np.isnan(s["mean_jaw"].iloc[1])
        assert np.isnan(s["fps"].iloc[1])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["summary.csv", "summary.parquet"]


@pytest.mark.parametrize("case", ["no_match", "missing", "out_is_file", "refused", "bad_address"])
def test_batch_bad_input_is_one_line(tmp_path, capsys, case):
    video = tmp_path / "v.mp4"
    video.write_bytes(b"not a video")
    out = tmp_path / "out"
    extra: list[str] = []
    if case == "no_match":
        video, match = tmp_path / "*.mov", "no file matches"
    elif case == "missing":
        video, match = tmp_path / "none.mp4", "no such video"
    elif case == "out_is_file":
        out.write_text("")
        match = "exists and is not a folder"
    elif case == "refused":  # nothing listens there: an error after --timeout, not a hang
        extra, match = ["--scheduler", "tcp://127.0.0.1:1", "--timeout", "1"], "no Dask scheduler"
    else:
        extra, match = ["--scheduler", "nonsense"], "not a scheduler address"
    t0 = time.perf_counter()
    assert main(["batch", str(video), "-o", str(out), "--quiet", *extra]) == 1
    assert time.perf_counter() - t0 < 20
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[0], err
    if case != "out_is_file":
        assert not out.exists()  # nothing written


def test_batch_without_the_extra_says_how_to_install(tmp_path, capsys, monkeypatch):
    import sys

    video = tmp_path / "v.mp4"
    video.write_bytes(b"x")
    monkeypatch.setitem(sys.modules, "distributed", None)  # import distributed -> ImportError
    assert main(["batch", str(video), "-o", str(tmp_path / "o"), "--engine", "dask"]) == 1
    err = capsys.readouterr().err
    assert 'pip install "myoface[batch]"' in err


def test_batch_gives_each_video_the_analysis_options_of_analyze(clips, tmp_path, capsys):
    """--calibration-frame, --max-frames, --refine, --sigma and --estimator reach each
    video's analysis as they reach myoface analyze's (the same analysis.json settings, the
    same contractions); done.json keeps them, so a run with another --refine analyses again."""
    import imageio.v3 as iio

    from myoface.render import VideoWriter

    rest, smile = iio.imread(clips / "smile.mp4", plugin="pyav")[:2]
    late = tmp_path / "late.mp4"  # smile, rest (the calibration frame), smile, smile
    with VideoWriter(late, fps=10) as vw:
        for f in (smile, rest, smile, smile):
            vw.write(f)
    opts = ["--init", str(clips / "init.json"), "--calibration-frame", "1", "--max-frames", "2"]
    opts += ["--refine", "2", "--sigma", "1.5", "--estimator", "fiducials", "--quiet"]
    out, ana = tmp_path / "out", tmp_path / "ana"
    assert main(["batch", str(late), "-o", str(out), "--workers", "1", *opts]) == 0
    assert main(["analyze", str(late), "-o", str(ana), *opts]) == 0
    capsys.readouterr()
    side = json.loads((out / "late" / "analysis.json").read_text())
    assert side["calibration_frame"] == 1 and side["refine"] == 2
    assert side["sigma_px"] == 1.5 and side["estimator"] == "fiducials"
    ref = json.loads((ana / "analysis.json").read_text())
    # every setting and per-frame record as analyze's; the contours are the file's (batch sends
    # them to its workers: "contours given"), which analyze names
    assert side.pop("init") == "contours given" and ref.pop("init") == str(clips / "init.json")
    assert side == ref
    rows = _table(out / "late" / "contractions.csv")
    np.testing.assert_array_equal(rows, _table(ana / "contractions.csv"))
    # frames 1 (rest: calibrated on) and 2 (the smile), then --max-frames stops it
    with open(out / "late" / "contractions.csv", newline="") as fh:
        assert [r["frame"] for r in csv.DictReader(fh)] == ["1", "2"]
    from myoface.analysis.sections import PAPER_MUSCLES

    zyg = PAPER_MUSCLES.index("zygomaticus_major_l")
    assert rows[1, zyg] > rows[0, zyg] + 0.2, rows[:, zyg]
    done = json.loads((out / "late" / "done.json").read_text())["settings"]
    assert (done["calibration_frame"], done["max_frames"], done["refine"]) == (1, 2, 2)
    assert (done["sigma"], done["estimator"], done["flow"]) == (1.5, "fiducials", False)

    assert main(["batch", str(late), "-o", str(out), "--workers", "1", *opts]) == 0
    assert "0 analysed, 1 already done" in capsys.readouterr().out
    opts[opts.index("--refine") + 1] = "1"
    assert main(["batch", str(late), "-o", str(out), "--workers", "1", *opts]) == 0
    assert "1 analysed, 0 already done" in capsys.readouterr().out
    assert json.loads((out / "late" / "analysis.json").read_text())["refine"] == 1


def test_a_result_from_before_the_analysis_options_is_still_complete(tmp_path):
    """A done.json written before batch had --calibration-frame, --refine, --sigma and
    --flow is complete for a run without them (its analysis had their defaults), and not for
    one with another value."""
    import os

    from myoface.analysis.batch import DONE_FILE, SUMMARY_COLUMNS, run_batch

    video = tmp_path / "v.mp4"
    video.write_bytes(b"not a video: it is never read when its result is complete")
    st = os.stat(video)
    row = {c: 0 for c in SUMMARY_COLUMNS} | {"status": "ok", "error": "", "frames": 3}
    old = {
        "tracker": "snakes",
        "estimator": None,
        "max_frames": None,
        "init_sha256": None,
        "face": None,
        "muscles": None,
    }
    out = tmp_path / "out"
    (out / "v").mkdir(parents=True)
    doc = {"video": str(video.resolve()), "size": st.st_size, "mtime_ns": st.st_mtime_ns}
    (out / "v" / DONE_FILE).write_text(json.dumps({**doc, "settings": old, "row": row}))
    (rows,) = run_batch([video], out, workers=1)
    assert rows["status"] == "skipped" and rows["frames"] == 3
    (rows,) = run_batch([video], out, workers=1, refine=2)
    assert rows["status"] == "failed" and "not a readable video" in rows["error"]


def test_batch_flow_fails_as_analyze_does(tmp_path, capsys, monkeypatch):
    """--flow is the landmark tracker's: with the snakes it is refused before any video is
    analysed; without MediaPipe each video fails with analyze's own one-line error."""
    import sys

    from myoface.render import VideoWriter

    video = tmp_path / "grey.mp4"
    with VideoWriter(video, fps=10) as vw:
        for _ in range(2):
            vw.write(np.full((64, 64, 3), 128, np.uint8))
    out = tmp_path / "out"
    snakes = ["--tracker", "snakes", "--flow", "--quiet"]
    assert main(["batch", str(video), "-o", str(out), *snakes]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [
        "myoface batch: error: --flow refines the landmark tracker's points; use it with "
        "--tracker landmarks"
    ]
    assert not out.exists()

    monkeypatch.setitem(sys.modules, "mediapipe", None)  # import mediapipe -> ImportError
    flow = ["--tracker", "landmarks", "--flow", "--quiet"]
    assert main(["analyze", str(video), "-o", str(tmp_path / "ana"), *flow]) == 1
    (analyze_err,) = capsys.readouterr().err.strip().splitlines()
    assert 'pip install "myoface[mediapipe]"' in analyze_err
    assert main(["batch", str(video), "-o", str(out), "--workers", "1", *flow]) == 1
    (batch_err,) = capsys.readouterr().err.strip().splitlines()
    why = analyze_err.removeprefix("myoface analyze: error: ")
    assert batch_err.startswith(f"myoface batch: failed: {video.resolve()}")
    assert batch_err.endswith(why)
