"""Bad input on the command line (README, "Command line"): one line on stderr, exit
status 2 (usage) or 1 (a MyofaceError), no traceback, no partial output, no hang."""

from __future__ import annotations

import signal
import socket
import subprocess
import sys
import time

import numpy as np
import pytest

from myoface.cli import main
from myoface.errors import MyofaceFormatError, MyofaceValueError, MyofaceWarning


def run_cli(capsys, argv):
    """(exit status, stdout, stderr lines) of ``myoface argv`` run in this process."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err.strip().splitlines()


def one_line_error(capsys, argv, match, code=1):
    got, _, err = run_cli(capsys, argv)
    assert got == code, err
    assert len(err) == 1 and match in err[0], err
    assert "Traceback" not in err[0]
    return err[0]


@pytest.fixture(scope="module")
def tiny_video(tmp_path_factory):
    """A 64x64 grey video of 3 frames (no face: nothing can be measured on it)."""
    from myoface.render import VideoWriter

    d = tmp_path_factory.mktemp("tiny")
    with VideoWriter(d / "grey.mp4", fps=10) as vw:
        for _ in range(3):
            vw.write(np.full((64, 64, 3), 128, np.uint8))
    return d / "grey.mp4"


# --------------------------------------------------------------------- an existing folder as -o


@pytest.mark.parametrize(
    ("argv", "name"),
    [
        (["synth", "--au", "12=0.5", "-o"], "out.png"),
        (["synth", "--au", "12=0.5", "--duration", "0.2", "-o"], "out.mp4"),
        (["resynth", "c.csv", "-o"], "out.mp4"),
        (["face", "from-photo", "photo.png", "-o"], "out.myoface"),
        (["face", "maps", "head.obj", "-o"], "out.npz"),
        (["bench", "--only", "render", "--json"], "out.json"),
    ],
)
def test_existing_folder_as_output_is_refused_up_front(tmp_path, capsys, monkeypatch, argv, name):
    monkeypatch.chdir(tmp_path)
    (tmp_path / name).mkdir()
    t0 = time.perf_counter()
    one_line_error(capsys, [*argv, name], f"{name} is an existing folder; expected a file name")
    assert time.perf_counter() - t0 < 5  # before any work
    assert sorted(p.name for p in tmp_path.iterdir()) == [name]
    assert not any((tmp_path / name).iterdir())


# --------------------------------------------------------------------------- non-UTF-8 text


def test_latin1_timeline(tmp_path, capsys):
    tl = tmp_path / "talk.toml"
    tl.write_bytes(
        'title = "café"\n[[event]]\nkind = "au"\nname = "12"\nstart = 0\nduration = 1\n'.encode(
            "latin-1"
        )
    )
    err = one_line_error(
        capsys, ["synth", "--timeline", tl, "-o", tmp_path / "x.png"], "not UTF-8 text"
    )
    assert str(tl) in err and "timeline" in err
    assert [p.name for p in tmp_path.iterdir()] == ["talk.toml"]


def test_binary_contractions_csv(tmp_path, capsys):
    csv = tmp_path / "c.csv"
    csv.write_bytes(b"time_s,jaw\n0,0.1\n\x00\xff\xfe\x01binary")
    err = one_line_error(capsys, ["resynth", csv, "-o", tmp_path / "v.mp4"], str(csv))
    assert "not UTF-8" in err or "binary" in err
    assert not (tmp_path / "v.mp4").exists()


def test_csv_with_nul_bytes_only(tmp_path):
    from myoface.analysis.contractions_csv import read_contractions_csv

    p = tmp_path / "c.csv"
    p.write_bytes(b"time_s,jaw\n0,0\x00.1\n")
    with pytest.raises(MyofaceFormatError, match="binary file"):
        read_contractions_csv(p, ["jaw"])


def test_latin1_init_json(tmp_path, capsys, tiny_video):
    init = tmp_path / "init.json"
    init.write_bytes('{"note": "café", "contours": {"lips": [[1, 2], [3, 4]]}}'.encode("latin-1"))
    out = tmp_path / "out"
    err = one_line_error(
        capsys, ["analyze", tiny_video, "--init", init, "-o", out], "not UTF-8 text"
    )
    assert str(init) in err
    assert not out.exists()


# ------------------------------------------------------------------------- numbers and limits


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["synth", "--au", "12=.5", "--fps", "nan", "-o", "x.mp4"], "argument --fps"),
        (["synth", "--au", "12=.5", "--fps", "inf", "-o", "x.mp4"], "argument --fps"),
        (["synth", "--au", "12=.5", "--fps", "0", "-o", "x.mp4"], "argument --fps"),
        (["synth", "--au", "12=.5", "--fps", "1000", "-o", "x.mp4"], "(0, 240]"),
        (["synth", "--au", "12=.5", "--duration", "1e9", "-o", "x.mp4"], "argument --duration"),
        (["synth", "--au", "12=.5", "--duration", "-1", "-o", "x.mp4"], "argument --duration"),
        (["synth", "--au", "12=.5", "--width", "0", "-o", "x.png"], "[16, 4096]"),
        (["synth", "--au", "12=.5", "--height", "100000", "-o", "x.png"], "argument --height"),
        (["synth", "--au", "12=.5", "--ssaa", "9", "-o", "x.png"], "argument --ssaa"),
        (["synth", "--au", "12=.5", "--intensity", "nan", "-o", "x.png"], "--intensity"),
        (["synth", "--au", "12=.5", "--view", "top", "-o", "x.png"], "argument --view"),
        (["face", "maps", "m.obj", "-o", "m.npz", "--size", "100000x100000"], "[16, 8192]"),
        (["face", "maps", "m.obj", "-o", "m.npz", "--size", "8192x8192"], "at most"),
        (["face", "maps", "m.obj", "-o", "m.npz", "--size", "512"], "expected WxH"),
        (["face", "maps", "m.obj", "-o", "m.npz", "--scale-mm", "nan"], "--scale-mm"),
        (["face", "from-scan", "s.obj", "-o", "f.myoface", "--scale-mm", "0"], "--scale-mm"),
        (["face", "from-photo", "p.png", "-o", "f.myoface", "--depth-blend", "2"], "[0, 1]"),
        (["face", "from-photo", "p.png", "-o", "f.myoface", "--frame", "-1"], "--frame"),
        (["view", "--port", "-1"], "[0, 65535]"),
        (["view", "--port", "70000"], "[0, 65535]"),
        (["analyze", "v.mp4", "-o", "a", "--refine", "-1"], "[0, 10]"),
        (["analyze", "v.mp4", "-o", "a", "--refine", "1000000"], "[0, 10]"),
        (["analyze", "v.mp4", "-o", "a", "--sigma", "nan"], "argument --sigma"),
        (["analyze", "v.mp4", "-o", "a", "--max-frames", "0"], "argument --max-frames"),
        # batch's analysis options are analyze's, with the same limits
        (
            ["batch", "v.mp4", "-o", "b", "--max-frames", "0"],
            "--max-frames: expected an integer >= 1; got '0'",
        ),
        (
            ["batch", "v.mp4", "-o", "b", "--max-frames", "-5"],
            "--max-frames: expected an integer >= 1; got '-5'",
        ),
        (
            ["batch", "v.mp4", "-o", "b", "--refine", "11"],
            "argument --refine: expected an integer in [0, 10]",
        ),
        (
            ["batch", "v.mp4", "-o", "b", "--calibration-frame", "-1"],
            "argument --calibration-frame",
        ),
        (["batch", "v.mp4", "-o", "b", "--sigma", "0"], "argument --sigma"),
        (["batch", "v.mp4", "-o", "b", "--estimator", "best"], "argument --estimator"),
        (["resynth", "c.csv", "-o", "v.mp4", "--size", "0"], "argument --size"),
        (["demo", "-o", "d", "--fps", "0"], "argument --fps"),
        (["demo", "-o", "d", "--size", "0"], "argument --size"),
    ],
)
def test_numbers_outside_their_limits_are_usage_errors(tmp_path, capsys, monkeypatch, argv, match):
    monkeypatch.chdir(tmp_path)
    err = one_line_error(capsys, argv, match, code=2)
    assert "see myoface" in err and "--help" in err
    assert not list(tmp_path.iterdir())  # nothing written, no folder made


def test_timeline_times_are_bounded(tmp_path, capsys):
    far = tmp_path / "far.toml"
    far.write_text('[[event]]\nkind = "au"\nname = "12"\nstart = 1e12\nduration = 1\n')
    one_line_error(
        capsys, ["synth", "--timeline", far, "-o", tmp_path / "x.mp4"], "start must be at most"
    )
    long = tmp_path / "long.json"
    long.write_text(
        '{"events": [{"kind": "au", "name": "12", "start": 7000, "duration": 10}]}'
    )  # a valid timeline, but longer than a video may be
    one_line_error(
        capsys, ["synth", "--timeline", long, "-o", tmp_path / "x.mp4"], "a video is at most"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["far.toml", "long.json"]


def test_camera_presets_check_the_size_first():
    import warnings

    from myoface.render import Camera

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no division-by-zero warning before the message
        with pytest.raises(MyofaceValueError, match="between 1 and 16384"):
            Camera.front(np.eye(3) * 100, width=0, height=64)


# --------------------------------------------------------------------------------- the viewer


@pytest.fixture
def no_model(monkeypatch):
    """``view`` without building the model or starting a server: a stand-in FaceViewer that
    records its arguments and returns from serve_forever at once."""
    pytest.importorskip("viser")
    import myoface.commands.view as view_cmd
    import myoface.viewer.app as app

    made = []

    class FakeViewer:
        def __init__(self, fm, host, port, texture=None):
            made.append((host, port))
            self.url = f"http://{host}:{port}"

        def serve_forever(self):
            pass

    monkeypatch.setattr(view_cmd, "load_model", lambda args: None)
    monkeypatch.setattr(app, "FaceViewer", FakeViewer)
    return made


def test_view_busy_port_is_an_error(capsys, no_model):
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        one_line_error(capsys, ["view", "--port", port], f"port {port} on 127.0.0.1 is in use")
    assert no_model == []


@pytest.mark.parametrize(
    ("host", "match"),
    [
        ("no-such-host.invalid", "does not resolve"),
        ("192.0.2.1", "not an address of this machine"),  # TEST-NET-1: nobody's
    ],
)
def test_view_host_it_cannot_serve_on_is_an_error(capsys, no_model, host, match):
    t0 = time.perf_counter()
    one_line_error(capsys, ["view", "--host", host, "--port", "0"], match)
    assert time.perf_counter() - t0 < 30 and no_model == []


def test_view_warns_on_stderr_for_a_host_others_can_reach(capsys, no_model):
    code, out, err = run_cli(capsys, ["view", "--host", "0.0.0.0", "--port", "0"])
    assert code == 0 and no_model == [("0.0.0.0", 0)]
    assert len(err) == 1 and "warning" in err[0] and "127.0.0.1" in err[0], err
    assert "all who can reach 0.0.0.0" in out
    code, out, err = run_cli(capsys, ["view", "--port", "0"])
    assert code == 0 and err == [] and "this machine only" in out


def test_check_address():
    pytest.importorskip("viser")
    from myoface.viewer.app import check_address

    assert check_address("127.0.0.1", 0) == "127.0.0.1"
    assert check_address("localhost", 0) in ("127.0.0.1", "::1")
    for port in (-1, 65536, 1.5, "80", True):
        with pytest.raises(MyofaceValueError, match="port must be"):
            check_address("127.0.0.1", port)
    with pytest.raises(MyofaceValueError, match="host must be"):
        check_address("", 0)


# --------------------------------------------------------------- every output checked up front


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (["--preview", "{tmp}/no/p.png"], "--preview: output folder does not exist"),
        (["--preview", "{tmp}/p.jpg"], "--preview must be a .png file"),
        (["--preview", "{tmp}/dir.png"], "--preview: {tmp}/dir.png is an existing folder"),
        (["--maps-out", "{tmp}/no/m.npz"], "--maps-out: output folder does not exist"),
        (["--maps-out", "{tmp}/m.txt"], "--maps-out must be a .npz file or a folder"),
        (["--maps-out", "{tmp}/f.txt/m"], "--maps-out: cannot create"),
    ],
)
def test_face_outputs_are_checked_before_the_work(tmp_path, capsys, extra, match):
    (tmp_path / "dir.png").mkdir()
    (tmp_path / "f.txt").write_text("a file")
    before = sorted(tmp_path.iterdir())
    extra = [e.format(tmp=tmp_path) for e in extra]
    cmd = "from-scan" if "--maps-out" in extra else "from-photo"
    one_line_error(
        capsys,
        ["face", cmd, tmp_path / "missing", "-o", tmp_path / "f.myoface", *extra],
        match.format(tmp=tmp_path),
    )
    assert sorted(tmp_path.iterdir()) == before


def test_face_from_photo_failing_preview_leaves_nothing(tmp_path, capsys, monkeypatch):
    """The preview fails after the face was made: neither the preview nor the face file stays."""
    import myoface.commands.face as face_cmd
    import myoface.face.personal as personal
    from myoface.face import load_default_face

    photo = tmp_path / "me.png"
    photo.write_bytes(b"not read: _read_photo is replaced")
    info = {"face_width_px": 100.0, "head_yaw_deg": 0.0, "fit_rms_to_generic_mm": 1.0}
    monkeypatch.setattr(face_cmd, "_read_photo", lambda path, frame: None)
    monkeypatch.setattr(personal, "face_from_photo", lambda *a, **k: (load_default_face(), info))

    def bad_preview(face, path):
        path.write_bytes(b"half a png")
        raise MyofaceValueError("the preview broke")

    monkeypatch.setattr(face_cmd, "_write_preview", bad_preview)
    out, preview = tmp_path / "me.myoface", tmp_path / "me-preview.png"
    one_line_error(
        capsys, ["face", "from-photo", photo, "-o", out, "--preview", preview], "preview broke"
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["me.png"]


def test_output_set_removes_only_what_it_created(tmp_path):
    from myoface._io import OutputSet

    old = tmp_path / "old.txt"
    old.write_text("keep")
    with pytest.raises(RuntimeError), OutputSet() as outs:
        outs.add(old).write_text("replaced")
        outs.add(tmp_path / "new.txt").write_text("new")
        d = outs.add(tmp_path / "a" / "b")
        d.mkdir(parents=True)
        (d / "x").write_text("x")
        raise RuntimeError
    assert sorted(p.name for p in tmp_path.iterdir()) == ["old.txt"]


def test_analyze_failing_leaves_no_new_folders(tmp_path, capsys, tiny_video):
    """``-o a/b/c`` that fails after the folders were made removes a (which it made), not
    what existed before."""
    init = tmp_path / "init.json"
    init.write_text('{"contours": {"lips": [[20, 30], [30, 32], [40, 30]]}}')
    (tmp_path / "keep").mkdir()
    out = tmp_path / "keep" / "a" / "b" / "c"
    argv = ["analyze", tiny_video, "--init", init, "-o", out, "--quiet"]
    code, _, err = run_cli(capsys, argv)
    assert code == 1 and len(err) == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["init.json", "keep"]
    assert not any((tmp_path / "keep").iterdir())


def test_output_dir_context(tmp_path):
    from myoface._io import check_output_dir, output_dir

    with pytest.raises(KeyboardInterrupt), output_dir(tmp_path / "x" / "y") as out:
        (out / "f").write_text("f")
        raise KeyboardInterrupt
    assert not (tmp_path / "x").exists()
    with pytest.raises(ValueError), output_dir(tmp_path) as out:
        raise ValueError
    assert tmp_path.is_dir()
    (tmp_path / "file").write_text("")
    with pytest.raises(MyofaceValueError, match="-o: .* exists and is not a folder"):
        check_output_dir(tmp_path / "file", "-o")
    with pytest.raises(MyofaceValueError, match="is not a folder"):
        check_output_dir(tmp_path / "file" / "sub", "-o")


# --------------------------------------------------------------------------- SIGTERM / SIGHUP


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP])
def test_signal_during_synth_removes_the_partial_video(tmp_path, signum):
    out = tmp_path / "long.mp4"
    cmd = [sys.executable, "-m", "myoface", "synth", "--expression", "happiness"]
    cmd += ["--duration", "600", "--fps", "10", "--width", "32", "--height", "32"]
    cmd += ["--ssaa", "1", "--quiet", "-o", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while not list(tmp_path.glob(".long.*.part.mp4")):  # it is writing
            assert proc.poll() is None, proc.communicate()
            assert time.monotonic() < deadline, "synth did not start writing"
            time.sleep(0.2)
        time.sleep(1.0)
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 128 + signum, err
    lines = err.strip().splitlines()
    assert lines == [f"myoface synth: interrupted ({signal.Signals(signum).name})"], lines
    assert list(tmp_path.iterdir()) == []


def test_sigterm_handler_is_restored_after_main(tmp_path, capsys):
    before = signal.getsignal(signal.SIGTERM)
    main(["synth", "--au", "3=0.5", "-o", str(tmp_path / "x.png")])  # an error: unknown AU
    capsys.readouterr()
    assert signal.getsignal(signal.SIGTERM) is before


# ------------------------------------------------------------- no longer silently accepted


def test_muscles_without_face(tmp_path, capsys):
    one_line_error(
        capsys,
        ["synth", "--au", "12=0.5", "--muscles", tmp_path / "m.toml", "-o", tmp_path / "x.png"],
        "--muscles m.toml needs --face".replace("m.toml", str(tmp_path / "m.toml")),
    )


@pytest.mark.parametrize(
    ("extra", "match", "code"),
    [
        # usage errors (exit status 2): the option's syntax, a number outside its limits
        (["--au", "12=0.5", "--au", "12=0.7"], "--au 12 is given twice", 2),
        (["--au", "12"], "argument --au: expected NAME=VALUE", 2),
        (["--muscle", "zygomaticus_major_l=nan"], "must be in [0, 1]", 2),
        (["--au", "99=0.5"], "unknown action unit AU99", 1),
        (["--au", "12=0.5", "--texture", "{tmp}/none.png"], "--texture: no such texture", 1),
    ],
)
def test_synth_requests_checked_before_the_model(tmp_path, capsys, monkeypatch, extra, match, code):
    import myoface.commands.synth as synth_cmd

    def no_model(args):
        raise AssertionError("the model should not be built")

    monkeypatch.setattr(synth_cmd, "load_model", no_model)
    extra = [e.format(tmp=tmp_path) for e in extra]
    one_line_error(capsys, ["synth", *extra, "-o", tmp_path / "x.png"], match, code=code)


def test_resynth_warns_about_columns_of_no_muscle(tmp_path, capsys):
    import imageio.v3 as iio

    csv = tmp_path / "c.csv"
    csv.write_text("time_s,zygomaticus_major_l,smile,frown\n0,0.1,0.5,0\n0.1,0.2,0.5,0\n")
    out = tmp_path / "v.mp4"
    code, stdout, err = run_cli(capsys, ["resynth", csv, "-o", out, "--size", "32", "--quiet"])
    assert code == 0, err
    assert len(err) == 1 and "warning" in err[0], err
    assert "2 column(s) name no muscle" in err[0] and "'smile', 'frown'" in err[0]
    assert iio.imread(out, plugin="pyav").shape[0] == 2


def test_read_contractions_csv_warns_for_unknown_columns(tmp_path):
    from myoface.analysis.contractions_csv import read_contractions_csv

    p = tmp_path / "c.csv"
    p.write_text("frame,time_s,quality,jaw,jaw_angle_rad,head_scale\n0,0,ok,0.5,0.1,1\n")
    with _no_warnings():
        read_contractions_csv(p, ["jaw", "risorius_l"])  # the analysis' own columns: quiet
    p.write_text("time_s,jaw,orbicularis\n0,0.5,0.2\n")
    with pytest.warns(MyofaceWarning, match="'orbicularis'.*1 of its 2 muscles"):
        _, table, _ = read_contractions_csv(p, ["jaw", "risorius_l"])
    assert table.tolist() == [[0.5, 0.0]]
    p.write_text("time_s,jaw,jaw\n0,0.5,0.2\n")
    with pytest.raises(MyofaceFormatError, match="appears twice"):
        read_contractions_csv(p, ["jaw"])
    p.write_text("time_s,jaw\n0,0.5,0.2\n")
    with pytest.raises(MyofaceFormatError, match="row 2 has 3 cells"):
        read_contractions_csv(p, ["jaw"])


def test_16bit_grey_texture_is_not_white(tmp_path):
    import imageio.v3 as iio

    from myoface.render.renderer import load_texture

    grey16 = np.full((8, 8), 32896, np.uint16)  # 128/255 of full scale
    p = tmp_path / "grey16.png"
    iio.imwrite(p, grey16)
    t16 = load_texture(p)
    t8 = load_texture(np.full((8, 8, 3), 128, np.uint8))
    assert t16.shape == (8, 8, 3)
    np.testing.assert_allclose(t16, t8, atol=1e-4)
    grey_alpha = np.stack([np.full((8, 8), 128, np.uint8), np.full((8, 8), 255, np.uint8)], -1)
    np.testing.assert_allclose(load_texture(grey_alpha), t8, atol=1e-6)


def test_mesh_far_from_millimetres_warns(tmp_path, capsys):
    from myoface.face import load_default_face
    from myoface.face.io import save_mesh
    from myoface.face.mesh import FaceMesh

    f = load_default_face()
    big = tmp_path / "big.obj"
    # in micrometres (150 m across in mm): read, with a warning (1e6 would be refused: beyond
    # the readers' bound, myoface.face.mesh.MAX_COORDINATE_MM)
    save_mesh(FaceMesh(f.vertices * 1e3, f.triangles, f.uv, None, name="big"), big)
    code, out, err = run_cli(capsys, ["info", "--face", big])
    assert code == 0
    assert len(err) == 1 and "warning" in err[0] and "millimetres" in err[0], err


def test_odd_video_size_is_said(tmp_path, capsys):
    import imageio.v3 as iio

    out = tmp_path / "x.mp4"
    argv = ["synth", "--au", "12=0.5", "--duration", "0.1", "--fps", "10", "--ssaa", "1"]
    code, _, err = run_cli(capsys, [*argv, "--width", 33, "--height", 32, "--quiet", "-o", out])
    assert code == 0
    # padded, not cropped: every rendered column is in the file, the last one twice
    assert len(err) == 1 and "34x32 pixels, not 33x32 (the last column repeated)" in err[0], err
    assert iio.imread(out, plugin="pyav").shape[1:3] == (32, 34)


def test_bench_json_path_checked_before_the_run(tmp_path, capsys):
    t0 = time.perf_counter()
    one_line_error(capsys, ["bench", "--json", tmp_path / "no" / "b.json"], "--json: output folder")
    assert time.perf_counter() - t0 < 5


def test_usage_errors_are_one_line(capsys):
    one_line_error(capsys, ["synth", "-o", "x.png", "--bad"], "unrecognized arguments", code=2)
    one_line_error(capsys, ["synth"], "required: -o/--output", code=2)
    one_line_error(capsys, ["no-such-command"], "invalid choice", code=2)
    assert main(["--version"]) == 0


def test_os_errors_are_one_line(tmp_path, capsys, monkeypatch):
    """An error of the machine (disk full, ...) is one line too, without a traceback."""
    import myoface.commands.info as info_cmd

    def disk_full(args):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(info_cmd, "load_model", disk_full)
    one_line_error(capsys, ["info"], "No space left on device")


class _no_warnings:
    def __enter__(self):
        import warnings

        self._cm = warnings.catch_warnings()
        self._cm.__enter__()
        warnings.simplefilter("error")

    def __exit__(self, *exc):
        return self._cm.__exit__(*exc)


def test_errors_name_the_subcommand(tmp_path, capsys):
    (tmp_path / "m.npz").mkdir()
    err = one_line_error(capsys, ["face", "maps", "x.obj", "-o", tmp_path / "m.npz"], "folder")
    assert err.startswith("myoface face maps: error: -o: ")


def test_16bit_grey_photo_is_read_as_8bit_rgb(tmp_path):
    import imageio.v3 as iio

    from myoface.commands.face import _read_photo

    p = tmp_path / "grey16.png"
    iio.imwrite(p, np.full((8, 8), 32896, np.uint16))
    img = _read_photo(p, 0)
    assert img.dtype == np.uint8 and img.shape == (8, 8, 3) and (img == 128).all()
