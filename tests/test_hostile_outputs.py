"""Never lose a user's results (issue 31): a run's outputs are one transaction, one writer per
folder, no output on an input, and a stop signal in any stage of ``analyze`` keeps what was
complete, says so in one line and exits with 128 + its number.

The runs are ``myoface`` processes on 8 frames cut from the sample video (``single_face.mp4``),
into a copy of an earlier run's folder with the user's own files in it. Where a run must be
stopped in a given stage, it is started through a small driver (:data:`DRIVER`) that wraps
the stage's function: when the stage is reached, a timer thread of the process sends it the
signal after a delay, and the stage may pause meanwhile, so that the signal lands in that
stage however fast or loaded the machine is. Each case checks the exit status, the one line
on stderr (no traceback) and, by hashes, what the folder held before.

The runs of the cases (:data:`SCENARIOS`) are started two at a time as the module begins
(:func:`runs`; only those of the tests selected), and each test checks its own: the file
takes about half the time it would one run after another.
"""

from __future__ import annotations

import concurrent.futures
import contextlib
import hashlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from myoface._io import STAGING_MARK, live_folder
from myoface.analysis.outputs import ANALYSIS_FILES, FOLDER_FILES, REPORT_FILES
from myoface.cli import main
from tests.conftest import needs_mediapipe

N_FRAMES = 8
ANALYZE = ["analyze", "--tracker", "landmarks", "--quiet"]
#: the runs of the module that may go at once (the machine has 2 cores)
PARALLEL_RUNS = 2


def _sample() -> Path:
    from myoface.analysis.sample import cache_dir

    p = cache_dir() / "single_face.mp4"
    if not p.is_file():
        pytest.skip(f"the sample video is not cached: {p} (myoface demo fetches it)")
    return p


def _encode(path: Path, frames, fmt: str | None = None) -> Path:
    import av

    h, w = frames[0].shape[:2]
    with av.open(str(path), "w", format=fmt) as out:
        st = out.add_stream("libx264", rate=30)
        st.width, st.height, st.pix_fmt = w, h, "yuv420p"
        for f in frames:
            for pk in st.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(f), "rgb24")):
                out.mux(pk)
        for pk in st.encode(None):
            out.mux(pk)
    return path


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    """Short inputs cut from the sample video: clip.mp4 (8 frames, 640 x 360), one.mp4 (its
    first frame), frames/ (the 8 frames as PNG), odd/ (the same, the fifth cropped to 500 x
    300), resolution.ts (a stream whose frames halve in size after the fifth)."""
    import av
    import imageio.v3 as iio

    d = tmp_path_factory.mktemp("inputs")
    with av.open(str(_sample())) as c:
        decoded = (f.to_ndarray(format="rgb24") for f in c.decode(video=0))
        frames = [next(decoded) for _ in range(N_FRAMES)]
    _encode(d / "clip.mp4", frames)
    _encode(d / "one.mp4", frames[:1])
    for name in ("frames", "odd"):
        (d / name).mkdir()
        for k, f in enumerate(frames):
            if name == "odd" and k == 4:
                f = f[:300, :500]
            iio.imwrite(d / name / f"f{k:03d}.png", f)
    a = _encode(d / "a.ts", frames[:5], "mpegts").read_bytes()
    b = _encode(d / "b.ts", [f[::2, ::2] for f in frames[5:]], "mpegts").read_bytes()
    (d / "resolution.ts").write_bytes(a + b)
    return d


def _cli(argv, *, cwd, stage=None, timeout=240):
    """Run ``myoface argv`` in a process (with ``stage``: through :data:`DRIVER`):
    ``(exit status, stdout, stderr lines, the driver's record or None)``."""
    argv = [str(a) for a in argv]
    record = None
    if stage is None:
        cmd = [sys.executable, "-m", "myoface", *argv]
    else:
        record = Path(cwd) / f".stage-{os.getpid()}-{time.monotonic_ns()}.json"
        cmd = [sys.executable, "-c", DRIVER, json.dumps({**stage, "record": str(record)}), *argv]
    env = {**os.environ, "MPLBACKEND": "Agg"}
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    rec = None
    if record is not None and record.exists():
        rec = json.loads(record.read_text())
        record.unlink()
    return proc.returncode, proc.stdout, lines, rec


#: the driver of a run stopped in a stage: argv[1] is a JSON dict -- ``fsize`` (the largest
#: file it may write, bytes: then writes fail with EFBIG as a full disk fails them with
#: ENOSPC), ``target``
#: ("module:attr.attr", the stage's function), ``nth`` (its call that is the stage's),
#: ``match`` (only calls whose first argument's text or ``path`` contains it), ``after``
#: (the stage is reached when that call returns), ``signal`` (its name), ``delay`` (s after
#: the stage is reached), ``pause`` (s the stage waits then), ``record`` (a JSON file for the
#: times the stage was reached and ``main`` returned); the rest is myoface's command line
DRIVER = r"""
import importlib, inspect, json, os, signal, sys, threading, time
cfg = json.loads(sys.argv[1])
argv = sys.argv[2:]
if cfg.get("fsize"):
    import resource
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (cfg["fsize"], cfg["fsize"]))

record = {"pid": os.getpid()}

def note(**items):
    record.update(items)
    with open(cfg["record"], "w") as fh:
        json.dump(record, fh)

def reached():
    note(reached=time.time())
    if cfg.get("signal"):
        sig = getattr(signal, cfg["signal"])
        t = threading.Timer(cfg.get("delay", 0.0), os.kill, (os.getpid(), sig))
        t.daemon = True
        t.start()
    end = time.monotonic() + cfg.get("pause", 0.0)
    while time.monotonic() < end:  # (a signal that is not held off is raised in here)
        time.sleep(0.01)

mod, _, attr = cfg.get("target", "myoface.cli:main").partition(":")
owner = importlib.import_module(mod)
*path, name = attr.split(".")
for p in path:
    owner = getattr(owner, p)
orig = getattr(owner, name, None) or __builtins__.print
calls = [0]

def counts(args):
    text = str(getattr(args[0], "path", args[0])) if args else ""
    if cfg.get("match") and cfg["match"] not in text:
        return False
    calls[0] += 1
    return calls[0] == cfg.get("nth", 1)

if inspect.isgeneratorfunction(orig):
    def wrapper(*a, **k):
        if counts(a):
            reached()
        yield from orig(*a, **k)
else:
    def wrapper(*a, **k):
        hit = counts(a)
        if hit and not cfg.get("after"):
            reached()
        out = orig(*a, **k)
        if hit and cfg.get("after"):
            reached()
        return out
if "target" in cfg:
    setattr(owner, name, wrapper)

from myoface.cli import main
code = main(argv)
if "reached" in record:
    note(returned=time.time())  # (the interpreter's exit after it is not the command's)
sys.exit(code)
"""

#: where each stage of ``myoface analyze`` is entered (the driver's ``target``)
STAGES = {
    "calibration": {"target": "myoface.analysis.trackers.landmark_fit:FitTracker.calibrate"},
    # the fourth frame's measurement: three frames are complete
    "frames": {"target": "myoface.analysis.trackers.landmark_fit:FitTracker.measure", "nth": 4},
    "plots": {"target": "myoface.analysis.outputs:plot_contractions"},
    "report": {"target": "myoface.analysis.fidelity:fidelity_of_analysis"},
    # the report's resynthesis (the model driven by the CSV, rendered for MediaPipe)
    "resynthesis": {"target": "myoface.analysis.fidelity:resynthesis_frames"},
    # once the outputs are in place, as the command says so
    "end": {"target": "myoface.commands.analyze:print", "match": "analysed", "after": True},
}


def snapshot(folder: Path) -> dict:
    """{relative path: SHA-256} of every file under ``folder`` (hidden ones too)."""
    out = {}
    for p in sorted(folder.rglob("*")):
        if p.is_file():
            out[str(p.relative_to(folder))] = hashlib.sha256(p.read_bytes()).hexdigest()
    return out


def _one_line(lines, start: str) -> str:
    assert len(lines) == 1, lines
    assert lines[0].startswith(start), lines
    assert "Traceback" not in lines[0]
    return lines[0]


def _leftovers(folder: Path) -> list[str]:
    """Temporary folders of runs beside ``folder``, and locks or staging folders in it."""
    beside = [p.name for p in folder.parent.iterdir() if p.name.startswith(f".{folder.name}.")]
    inside = [p.name for p in folder.iterdir() if p.name.startswith(".myoface")]
    return beside + inside


@pytest.fixture(scope="module")
def earlier_run(inputs, tmp_path_factory):
    """A finished analysis of clip.mp4 (``earlier/out``), the folder the hostile runs go into."""
    d = tmp_path_factory.mktemp("earlier")
    code, _, err, _ = _cli([*ANALYZE, inputs / "clip.mp4", "-o", d / "out"], cwd=d)
    assert code == 0 and not err, err
    return d / "out"


def _copy_earlier(earlier_run: Path, d: Path) -> tuple[Path, dict]:
    """A copy of the earlier analysis in ``d/out`` with the user's own files in it (a note, a
    folder) and an older report's fidelity.json; and its hashes."""
    out = d / "out"
    shutil.copytree(earlier_run, out)
    (out / "notes.txt").write_text("my notes on this take\n")
    (out / "mine").mkdir()
    (out / "mine" / "cut.txt").write_text("frames 3-5\n")
    (out / "fidelity.json").write_text('{"an": "older report"}\n')
    return out, snapshot(out)


@pytest.fixture
def earlier(earlier_run, tmp_path):
    return _copy_earlier(earlier_run, tmp_path)


def _analysis_files(out: Path) -> set:
    return {p.name for p in out.iterdir()} - {"notes.txt", "mine"}


def _check_user_files(out: Path) -> None:
    assert (out / "notes.txt").read_text() == "my notes on this take\n"
    assert (out / "mine" / "cut.txt").read_text() == "frames 3-5\n"


def _rows(path: Path) -> int:
    return len(path.read_text().splitlines()) - 1


def _video_frames(path: Path) -> int:
    import av

    with av.open(str(path)) as c:
        return sum(1 for _ in c.decode(video=0))


def _stage(name, signame, delay=0.3, pause=5.0, **more) -> dict:
    return {**STAGES[name], "signal": signame, "delay": delay, "pause": pause, **more}


REPORT = ["--report", "--format", "openface"]
_SNAKES = ["analyze", "--tracker", "snakes", "--quiet", "--format", "openface"]
#: the runs of the cases: name -> (arguments after ``myoface``, the driver's settings or
#: None); ``{clip}`` and the like are the inputs' names, the output is ``out``
SCENARIOS = {
    # #2: a run failing part-way
    "part-way:odd-image": ([*ANALYZE, "{odd}", "-o", "out"], None),
    "part-way:resolution-change": ([*ANALYZE, "{resolution.ts}", "-o", "out"], None),
    "part-way:disk-full": ([*ANALYZE, "{clip.mp4}", "-o", "out"], {"fsize": 20_000}),
    # #3: a failing report
    "report:one-frame": ([*ANALYZE, "{one.mp4}", "--report", "-o", "out"], None),
    # #5: a stop signal in each stage
    "stage:calibration": (
        [*ANALYZE, "{clip.mp4}", *REPORT, "-o", "out"],
        _stage("calibration", "SIGINT"),
    ),
    "stage:frames": ([*ANALYZE, "{clip.mp4}", *REPORT, "-o", "out"], _stage("frames", "SIGHUP")),
    "stage:plots": ([*ANALYZE, "{clip.mp4}", *REPORT, "-o", "out"], _stage("plots", "SIGTERM")),
    # (no pause: the signal lands in the report's own work)
    "stage:report": (
        [*ANALYZE, "{clip.mp4}", *REPORT, "-o", "out"],
        _stage("report", "SIGTERM", pause=0.0),
    ),
    "stage:resynthesis": (
        [*ANALYZE, "{clip.mp4}", *REPORT, "-o", "out"],
        _stage("resynthesis", "SIGINT"),
    ),
    "stage:end": ([*ANALYZE, "{clip.mp4}", *REPORT, "-o", "out"], _stage("end", "SIGINT")),
    # resynth: the signal comes as its third frame is encoded
    "resynth": (
        ["resynth", "out/contractions.csv", "--side-by-side", "{clip.mp4}"]
        + ["-o", "out/resynth.mp4", "--quiet"],
        {
            "target": "myoface.render.io:VideoWriter.write",
            "nth": 3,
            "signal": "SIGHUP",
            "delay": 0.3,
            "pause": 5.0,
        },
    ),
    # the signal comes as the fourth frame's overlay picture is written (after its row)
    "snakes": (
        [*_SNAKES, "{clip.mp4}", "-o", "out"],
        {
            "target": "myoface.render.io:VideoWriter.write",
            "match": "overlay",
            "nth": 4,
            "signal": "SIGTERM",
            "delay": 0.05,
            "pause": 0.5,
        },
    ),
    # killed outright at a seeded random time in a stage
    **{
        f"killed:{stage}": (
            [*ANALYZE, "{clip.mp4}", "--report", "-o", "out"],
            _stage(
                stage,
                "SIGKILL",
                pause=0.0,
                delay=float(np.random.default_rng(seed).uniform(0, 0.5)),
            ),
        )
        for seed, stage in enumerate(("frames", "report"))
    },
}


@pytest.fixture(scope="module")
def runs(request, inputs, earlier_run, tmp_path_factory):
    """{scenario: future of (exit status, stdout, stderr lines, record, out, hashes before)}
    for the :data:`SCENARIOS` of the tests selected, run :data:`PARALLEL_RUNS` at a time
    (each into its own copy of the earlier folder)."""
    wanted = [
        item.callspec.params["scenario"]
        for item in request.session.items
        if item.module is request.module
        and hasattr(item, "callspec")
        and "scenario" in item.callspec.params
    ]

    def run(name):
        argv, stage = SCENARIOS[name]
        d = tmp_path_factory.mktemp(name.replace(":", "-"))
        if name == "resynth":  # (an earlier resynthesis, which it is to replace)
            shutil.copy(inputs / "clip.mp4", earlier_copy := d / "resynth.mp4")
        out, before = _copy_earlier(earlier_run, d)
        if name == "resynth":
            earlier_copy.rename(out / "resynth.mp4")
            before = snapshot(out)
        argv = [
            str(inputs / a[1:-1]) if a.startswith("{") else a for a in argv
        ]  # (the inputs' paths)
        code, stdout, err, rec = _cli(argv, cwd=d, stage=stage)
        return code, stdout, err, rec, out, before

    pool = concurrent.futures.ThreadPoolExecutor(PARALLEL_RUNS, thread_name_prefix="run")
    futures = {name: pool.submit(run, name) for name in dict.fromkeys(wanted)}
    yield futures
    pool.shutdown(cancel_futures=True)


def _scenarios(prefix: str, *, slow=()) -> list:
    return [
        pytest.param(name, marks=[pytest.mark.slow] if name in slow else [], id=name.split(":")[-1])
        for name in SCENARIOS
        if name.startswith(prefix)
    ]


# ------------------------------------------------------- #2, #3: a failing run changes nothing


@needs_mediapipe
@pytest.mark.parametrize("scenario", _scenarios("part-way:"))
def test_a_run_failing_part_way_leaves_the_earlier_results(runs, scenario):
    """Issue 31 #2: a run into the folder of an earlier one that fails part-way (an image
    folder with an odd-sized image, a stream whose resolution changes, a full disk) leaves
    the earlier contractions.csv and everything else byte-identical, and nothing beside."""
    code, _, err, _, out, before = runs[scenario].result()
    assert code == 1, err
    line = _one_line(err, "myoface analyze: error: ")
    assert STAGING_MARK not in line  # it names the folder, not the temporary one
    assert snapshot(out) == before
    assert _leftovers(out) == []


@needs_mediapipe
@pytest.mark.parametrize("scenario", ["report:one-frame"])
def test_a_failing_report_leaves_the_earlier_results(runs, scenario):
    """Issue 31 #3: a 1-frame video with --report into the earlier folder fails (the report
    needs two measured frames): all the earlier files stay as they were (they were all
    replaced by the failed run's)."""
    code, _, err, _, out, before = runs[scenario].result()
    assert code == 1
    line = _one_line(err, "myoface analyze: error: ")
    assert "out/contractions.csv: fewer than 2 measured" in line  # where the user looks
    assert snapshot(out) == before
    assert _leftovers(out) == []


# ------------------------------------------------------- #4, #10: no output on an input


def _main(capsys, argv):
    code = main([str(a) for a in argv])
    _, err = capsys.readouterr()
    return code, [ln for ln in err.splitlines() if ln.strip()]


@pytest.mark.parametrize("where", ["the-folder", "inside-it"])
def test_outputs_never_go_inside_the_input(inputs, tmp_path, capsys, where):
    """Issue 31 #4: ``analyze FOLDER_OF_FRAMES -o FOLDER_OF_FRAMES`` (or a folder inside
    it), twice, is refused before any work, exit status 2 and one line; the input is
    untouched (earlier, the first run wrote contractions.png among the frames and the second
    read it as a frame)."""
    frames = shutil.copytree(inputs / "frames", tmp_path / "frames")
    before = snapshot(frames)
    out = frames if where == "the-folder" else frames / "results"
    t0 = time.perf_counter()
    for _ in range(2):
        code, err = _main(capsys, [*ANALYZE, frames, "-o", out])
        assert code == 2
        line = _one_line(err, "myoface analyze: error: -o ")
        assert "the input folder" in line
    assert time.perf_counter() - t0 < 10  # before the model is built
    assert snapshot(frames) == before and not (frames / "results").exists()


def test_no_command_writes_over_its_input(inputs, earlier_run, tmp_path, capsys, monkeypatch):
    """Issue 31 #10: ``resynth c.csv --side-by-side v.mp4 -o v.mp4`` (the same path, another
    spelling of it, the same file under another name) and ``analyze v.mp4 -o v.mp4`` are
    refused: exit status 2, one line, the input untouched; as is an analysis whose folder
    holds its input video under the name of one of its outputs."""
    video = shutil.copy(inputs / "clip.mp4", tmp_path / "v.mp4")
    os.link(video, tmp_path / "same.mp4")
    (tmp_path / "take").mkdir()
    shutil.copy(video, tmp_path / "take" / "overlay.mp4")
    csv = earlier_run / "contractions.csv"
    monkeypatch.chdir(tmp_path)
    before = snapshot(tmp_path)
    for argv, says in (
        (["resynth", csv, "--side-by-side", video, "-o", video], "never writes over its input"),
        (["resynth", csv, "--side-by-side", video, "-o", "same.mp4"], "never writes over"),
        (["resynth", csv, "--side-by-side", video, "-o", "x/../v.mp4"], "never writes over"),
        (["analyze", video, "-o", video], "a command never writes over its input"),
        (["analyze", "take/overlay.mp4", "-o", "take"], "its overlay.mp4 would be written over"),
    ):
        code, err = _main(capsys, argv)
        assert code == 2, argv
        assert says in _one_line(err, f"myoface {argv[0]}: error: -o "), argv
    assert snapshot(tmp_path) == before


# ------------------------------------------------------- #5: a stop signal in each stage


@needs_mediapipe
@pytest.mark.parametrize("scenario", _scenarios("stage:"))
def test_a_stop_signal_in_each_stage_keeps_what_was_complete(runs, scenario):
    """Issue 31 #5: SIGINT, SIGTERM or SIGHUP in any stage of ``analyze --report --format
    openface`` stops it within 2 s with exit status 128 + N and one line saying what was
    kept. Before the first frame, nothing: the earlier results stay byte-identical. In the
    frames, the frames so far (CSV, overlay and openface.csv alike); later, all the frames;
    analysis.json says where it was interrupted. Either way the user's files stay, and the
    earlier run's files this run did not make (its fidelity.json) are gone: the folder
    describes one run. (Earlier: SIGTERM in --report deleted the whole folder, SIGINT there
    was ignored, SIGINT at the end gave 130 and no message.)"""
    stage = scenario.split(":")[1]
    spec = SCENARIOS[scenario][1]
    code, _, err, rec, out, before = runs[scenario].result()
    signame = spec["signal"]
    assert code == 128 + getattr(signal, signame), err
    assert rec is not None, "the stage was not reached"
    line = _one_line(err, f"myoface analyze: interrupted ({signame})")
    # stopped, said so and kept what it keeps within 2 s of the signal
    assert rec["returned"] - (rec["reached"] + spec["delay"]) < 2.0
    assert _leftovers(out) == []
    if stage == "calibration":
        assert line == f"myoface analyze: interrupted ({signame})"
        assert snapshot(out) == before
        return
    _check_user_files(out)
    side = json.loads((out / "analysis.json").read_text())
    n = 3 if stage == "frames" else N_FRAMES
    assert len(side["frames"]) == _rows(out / "contractions.csv") == n
    assert _video_frames(out / "overlay.mp4") == n
    if stage == "end":  # it came once the outputs were in place: the full set
        assert "the analysis was complete" in line and "interrupted" not in side
        assert _analysis_files(out) == {*FOLDER_FILES, "openface.csv", *REPORT_FILES}
        return
    assert side["interrupted"] is True
    assert side["interrupted_in"] == {"resynthesis": "report"}.get(stage, stage)
    if stage == "frames":  # (not plotted: the plot takes seconds, the run is stopping)
        assert f"kept the {n} frames analysed ({n} measured) in out/contractions.csv" in line
    else:
        assert f"kept the analysis of all {n} frames ({n} measured) in out" in line
    assert "the fidelity report (--report) was not made" in line
    plots = {"contractions.png", "expressions.png"}
    unplotted = plots if stage in ("frames", "plots") else set()
    assert _analysis_files(out) == {*FOLDER_FILES, "openface.csv"} - unplotted
    assert _rows(out / "openface.csv") == n


@needs_mediapipe
@pytest.mark.parametrize("scenario", ["snakes"])
def test_an_interrupted_snakes_run_keeps_as_many_pictures_as_rows(runs, scenario):
    """Issue 31 (silent): a signal between a frame's CSV row and its overlay picture (here: as
    the fourth frame's overlay is written) waits for the frame to be complete: the CSV,
    overlay.mp4, potential.mp4 and openface.csv keep the same frames (the overlay was one
    frame off, and openface.csv missing)."""
    code, _, err, rec, out, _ = runs[scenario].result()
    assert code == 128 + signal.SIGTERM and rec is not None, err
    line = _one_line(err, "myoface analyze: interrupted (SIGTERM); kept the 4 frames")
    assert "the fidelity report" not in line
    assert _rows(out / "contractions.csv") == _rows(out / "openface.csv") == 4
    assert _video_frames(out / "overlay.mp4") == _video_frames(out / "potential.mp4") == 4
    _check_user_files(out)


@needs_mediapipe
@pytest.mark.parametrize("scenario", ["resynth"])
def test_an_interrupted_resynth_leaves_the_earlier_video(runs, scenario):
    """``myoface resynth`` stopped (SIGHUP) as it renders: exit status 129 within 2 s, one
    line, the earlier video at ``-o`` byte-identical and no temporary file left (a video is
    complete only when all its frames are)."""
    code, _, err, rec, out, before = runs[scenario].result()
    assert code == 128 + signal.SIGHUP and rec is not None, err
    assert _one_line(err, "myoface resynth: interrupted (SIGHUP)") == (
        "myoface resynth: interrupted (SIGHUP)"
    )
    assert rec["returned"] - (rec["reached"] + 0.3) < 2.0
    assert snapshot(out) == before


# ------------------------------------------------------- #6: one writer per folder


@needs_mediapipe
def test_one_writer_per_folder_and_a_stale_lock_is_taken_over(inputs, earlier, tmp_path):
    """Issue 31 #6: while a run writes a folder, its lock file names it (pid, host, command,
    start), and a second run into the folder says so in one line and exits 2, changing
    nothing; the first one finishes. The first found the lock of a run that died (its pid
    gone) and took it over with a one-line warning."""
    out, _ = earlier
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    stale = {"pid": dead.pid, "host": socket.gethostname(), "command": "myoface analyze x"}
    (out / ".myoface.lock").write_text(json.dumps({**stale, "started": "2026-01-01T00:00:00"}))
    spec = {**STAGES["calibration"], "pause": 4.0}  # the first run holds the folder a while
    argv = [*ANALYZE, inputs / "clip.mp4", "-o", "out"]
    cmd = [sys.executable, "-c", DRIVER, json.dumps({**spec, "record": str(tmp_path / "r")})]
    env = {**os.environ, "MPLBACKEND": "Agg"}
    first = subprocess.Popen(
        [*cmd, *map(str, argv)],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 120
        while not (tmp_path / "r").exists():  # it is in the calibration, holding the lock
            assert first.poll() is None and time.monotonic() < deadline
            time.sleep(0.05)
        lock = json.loads((out / ".myoface.lock").read_text())
        assert lock["pid"] == first.pid and lock["host"] == socket.gethostname()
        assert "analyze" in lock["command"] and lock["started"]
        live = live_folder(out)  # where it writes meanwhile: beside the folder
        assert live is not None and live.parent == out.parent and STAGING_MARK in live.name
        t0 = time.perf_counter()
        code, _, err, _ = _cli(argv, cwd=tmp_path)
        assert code == 2
        line = _one_line(err, "myoface analyze: error: -o out: another run is writing")
        assert f"pid {first.pid}" in line and time.perf_counter() - t0 < 10
        _, first_err = first.communicate(timeout=180)
    finally:
        if first.poll() is None:
            first.kill()
        first.communicate()
    assert first.returncode == 0, first_err
    lines = [ln for ln in first_err.splitlines() if ln.strip()]
    warn = _one_line(lines, "myoface analyze: warning: out/.myoface.lock: took over the lock")
    assert f"pid {dead.pid}" in warn
    assert _leftovers(out) == []
    _check_user_files(out)
    assert _analysis_files(out) == set(FOLDER_FILES)  # the older fidelity.json is gone
    side = json.loads((out / "analysis.json").read_text())
    assert "interrupted" not in side and _rows(out / "contractions.csv") == N_FRAMES


# ------------------------------------------------------- killed outright: old or new, never a mix


OWNED = ("a.csv", "b.json", "c.png")
OLD = {"a.csv": "old a", "b.json": "old b", "c.png": "old c"}
NEW = {"a.csv": "new a", "b.json": "new b"}  # (c.png: not made by the new run)
USER = {"notes.txt": "mine", "sub/deep.txt": "mine too"}


def _commit_killed_at(target: Path, k: int) -> bool:
    """A forked child writes NEW as one transaction into ``target`` and is SIGKILLed at its
    ``k``-th file-system call (rename, replace, link, unlink, mkdir, rmdir, chmod, the
    exchange); True if it finished first."""
    import myoface._io as io

    pid = os.fork()
    if pid == 0:  # the child
        try:
            n = [0]

            def step(fn):
                def call(*a, **kw):
                    n[0] += 1
                    if n[0] == k:
                        os.kill(os.getpid(), signal.SIGKILL)
                    return fn(*a, **kw)

                return call

            for name in ("rename", "replace", "link", "unlink", "mkdir", "rmdir", "chmod"):
                setattr(os, name, step(getattr(os, name)))
            io.exchange_paths = step(io.exchange_paths)
            with io.output_transaction(target, OWNED) as tx:
                for name, text in NEW.items():
                    (tx.path / name).write_text(text)
        except BaseException:
            os._exit(1)
        os._exit(0)
    _, status = os.waitpid(pid, 0)
    if os.WIFSIGNALED(status):
        assert os.WTERMSIG(status) == signal.SIGKILL
        return False
    assert os.WEXITSTATUS(status) == 0, f"the transaction failed at step {k}"
    return True


def _state(target: Path) -> dict:
    return {
        str(p.relative_to(target)): p.read_text()
        for p in target.rglob("*")
        if p.is_file() and p.name != ".myoface.lock"
    }


def test_killed_at_any_step_of_the_commit_leaves_old_or_new_never_a_mix(tmp_path):
    """A run SIGKILLed at every one of its file-system steps in turn, from the first to the
    last: the folder holds the old results or the complete new ones, never a mix, never
    nothing; the user's files are always there (a folder of theirs may, for the instant
    before the exchange, sit in the killed run's temporary folder: the next run puts it
    back). The next run cleans up what the killed one left (its temporary folder beside the
    target, its lock, taken over with a warning)."""
    from myoface._io import output_transaction
    from myoface.errors import MyofaceWarning

    old_set = {**OLD, **USER}
    seen = set()
    k = 0
    while True:
        k += 1
        target = tmp_path / f"k{k}" / "out"
        (target / "sub").mkdir(parents=True)
        for name, text in old_set.items():
            (target / name).write_text(text)
        finished = _commit_killed_at(target, k)
        got = _state(target)
        outputs = {n: t for n, t in got.items() if n in OWNED}
        assert outputs in ({n: OLD[n] for n in OWNED}, NEW), (k, got)
        seen.add("new" if outputs == NEW else "old")
        missing = {n for n in USER if n not in got}
        assert missing <= {"sub/deep.txt"}, (k, got)  # (at most the folder, for an instant)
        # the next run: cleans up, puts the user's folder back, takes over the lock
        stale = (target / ".myoface.lock").exists()
        expect = (
            pytest.warns(MyofaceWarning, match="took over") if stale else contextlib.nullcontext()
        )
        with expect:
            with output_transaction(target, OWNED) as tx:
                (tx.path / "a.csv").write_text("next a")
        assert _state(target) == {"a.csv": "next a", **USER}, k
        assert sorted(p.name for p in target.parent.iterdir()) == ["out"], k
        if finished:
            break
    assert seen == {"old", "new"} and k > 10


class _Rollback(Exception):
    pass


@needs_mediapipe
@pytest.mark.parametrize("scenario", _scenarios("killed:", slow=("killed:report",)))
def test_killed_in_a_stage_leaves_old_or_new_never_a_mix(runs, scenario):
    """``analyze --report`` SIGKILLed at a seeded random time in a stage: the folder holds
    the earlier results byte for byte or a complete new set (not "interrupted"), never a
    mix, with the user's files; what the killed run left (its temporary folder beside the
    target, its lock) is cleaned by the next run into the folder as it starts."""
    from myoface._io import output_transaction
    from myoface.errors import MyofaceWarning

    code, _, _, rec, out, before = runs[scenario].result()
    assert rec is not None and code in (0, -signal.SIGKILL)
    _check_user_files(out)
    got = {k: v for k, v in snapshot(out).items() if k != ".myoface.lock"}
    if got != before:  # the new set, whole
        side = json.loads((out / "analysis.json").read_text())
        assert "interrupted" not in side and len(side["frames"]) == N_FRAMES
        assert _analysis_files(out) == {*FOLDER_FILES, *REPORT_FILES}
        assert _rows(out / "contractions.csv") == N_FRAMES
    if code == 0:
        assert got != before and _leftovers(out) == []
        return
    # the next run into the folder cleans up as it starts (here it then fails: no change)
    stale = (out / ".myoface.lock").exists()
    expect = pytest.warns(MyofaceWarning, match="took over") if stale else contextlib.nullcontext()
    with pytest.raises(_Rollback), expect, output_transaction(out, ANALYSIS_FILES):
        raise _Rollback
    assert _leftovers(out) == []
    assert snapshot(out) == got
