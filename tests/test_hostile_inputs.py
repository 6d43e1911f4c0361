"""Hostile input at the boundary (issue 31, part C): each case reproduced as a user meets it,
and what the command line must do instead. README: errors are one line on stderr (no
traceback unless --debug), exit status 2 for a usage error (an unknown option, a number
outside its limits), 1 for any other; what is accepted but doubted is one warning line.

1. meshes with coordinates far beyond a head in mm (a vertex at 1e308 crashed scipy's k-d
   tree: a segfault, exit 139);
2. images in other colour spaces (a CMYK JPEG was read as RGBA: "no face found", wrong
   colours);
3. --au / --muscle values outside [0, 1] (exit 1, not 2);
4. silently wrong: a variable-frame-rate video timed by its average rate, a truncated MP4
   analysed in part without a word, a photo of two faces, a huge photo's memory, resynth's
   missing columns / no measured row / absurd head pose / over-long video, synth --intensity
   alone, analyze --estimator fiducials with the landmark tracker;
5. messages that leaked internals (numpy's "need at least one array to stack", imageio's
   "Could not find a backend", PyAV's "[Errno 1094995529]", Python's
   "use sys.set_int_max_str_digits()", a full disk's error without its path).
"""

from __future__ import annotations

import csv
import errno
import json
import re
import subprocess
import sys
import zipfile
from fractions import Fraction

import numpy as np
import pytest

from myoface.cli import main
from myoface.errors import MyofaceWarning
from tests.conftest import needs_mediapipe, shared_path

BIG = "1" * 5000  # a number of 5000 digits (Python's int() refuses more than 4300)


def run_cli(capsys, argv):
    """(exit status, stdout, stderr lines) of ``myoface argv`` run in this process."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err.strip().splitlines()


def one_line(capsys, argv, code, *match, forbid=()):
    """Run ``argv``: exit status ``code``, exactly one stderr line holding every ``match``,
    none of ``forbid``, and no traceback; the line is returned."""
    got, _, err = run_cli(capsys, argv)
    assert got == code, err
    assert len(err) == 1, err
    line = err[0]
    assert "Traceback" not in line, line
    for m in match:
        assert m in line, (m, line)
    for f in forbid:
        assert f not in line, (f, line)
    return line


def run_subprocess(argv, tmp_path):
    """(exit status, stdout, stderr lines) of ``python -m myoface argv`` in ``tmp_path``."""
    proc = subprocess.run(
        [sys.executable, "-m", "myoface", *map(str, argv)],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    return proc.returncode, proc.stdout, proc.stderr.strip().splitlines()


@pytest.fixture(scope="module")
def tiny_video(tmp_path_factory):
    """A 64x64 grey video of 3 frames (no face in it)."""
    from myoface.render import VideoWriter

    path = tmp_path_factory.mktemp("tiny") / "grey.mp4"
    with VideoWriter(path, fps=10) as vw:
        for _ in range(3):
            vw.write(np.full((64, 64, 3), 128, np.uint8))
    return path


@pytest.fixture(scope="module")
def sample_frames():
    """The frames (72, 360, 640, 3) of the sample video (neutral -> smile -> neutral)."""
    from myoface.analysis.video import open_video

    return open_video(shared_path("video", "single_face.mp4")).read_all()


@pytest.fixture(scope="module")
def face_photo(sample_frames, tmp_path_factory):
    """A frontal photo of a face (the sample video's frame 0), 640x360 RGB JPEG."""
    from PIL import Image

    path = tmp_path_factory.mktemp("photo") / "face.jpg"
    Image.fromarray(sample_frames[0]).save(path, quality=95)
    return path


# ------------------------------------------------------------------ 1. coordinates far off

HUGE_OBJ = "v 0 0 0\nv 1e308 0 0\nv 0 1e308 0\nf 1 2 3\n"  # finite, but the mean overflows


@pytest.mark.parametrize(
    ("obj", "vertex"),
    [
        (HUGE_OBJ, "vertex 2's x coordinate is 1e+308 mm"),  # was a segfault (exit 139)
        ("v 1e308 1e308 1e308\nv 1e308 0 0\nv 0 1e308 0\nf 1 2 3\n", "vertex 1"),  # traceback
    ],
)
def test_scan_with_a_vertex_at_1e308_is_refused_in_one_line(tmp_path, obj, vertex):
    """The crash is the process's (scipy's k-d tree): run as a user runs it."""
    (tmp_path / "t.obj").write_text(obj)
    landmarks = shared_path("scan", "james.ljson")
    code, _, err = run_subprocess(
        ["face", "from-scan", "t.obj", "--landmarks", landmarks, "-o", "s.myoface"], tmp_path
    )
    assert code == 1, err
    assert len(err) == 1 and "Traceback" not in err[0], err
    assert err[0].startswith("myoface face from-scan: error: t.obj: " + vertex), err
    assert "within 1000000 mm (1 km)" in err[0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.obj"]


def _geoface(folder, coordinate="1e308"):
    folder.mkdir()
    (folder / "faceline.dat").write_text(f"3\n0 0 0\n{coordinate} 0 0\n0 1 0\n")
    (folder / "index.dat").write_text("1\n1000 1 2 3\n")
    return folder


def _face_file(path, obj: str):
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("face.json", json.dumps({"format": "myoface face", "version": 1}))
        z.writestr("mesh.obj", obj)
    return path


PLY = (
    "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
    "property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
    "0 0 0\n0 3e38 0\n1 0 0\n3 0 1 2\n"
)


@pytest.mark.parametrize(
    ("make", "argv", "match"),
    [
        (lambda d: d / "t.obj", ["info", "--face", "{f}"], "t.obj: vertex 2"),
        (lambda d: d / "t.obj", ["synth", "--face", "{f}", "-o", "{d}/x.png"], "vertex 2"),
        (lambda d: d / "t.obj", ["face", "maps", "{f}", "-o", "{d}/m.npz"], "vertex 2"),
        (lambda d: d / "t.obj", ["face", "from-scan", "{f}", "-o", "{d}/s.myoface"], "vertex 2"),
        (lambda d: d / "t.ply", ["info", "--face", "{f}"], "t.ply: vertex 2's y"),
        (lambda d: _geoface(d / "geo"), ["info", "--face", "{f}"], "faceline.dat: vertex 2"),
        (
            lambda d: _face_file(d / "p.myoface", HUGE_OBJ),
            ["info", "--face", "{f}"],
            "mesh.obj: vertex 2",
        ),
        # within the bound only once scaled: 2 units x 1e6 mm per unit is 2 km
        (
            lambda d: d / "small.obj",
            ["face", "maps", "{f}", "--scale-mm", "1e6", "-o", "{d}/m.npz"],
            "(at 1e+06 mm per unit): vertex 2's x coordinate is 2e+06 mm",
        ),
    ],
)
def test_every_mesh_reader_refuses_coordinates_beyond_a_kilometre(
    tmp_path, capsys, make, argv, match
):
    (tmp_path / "t.obj").write_text(HUGE_OBJ)
    (tmp_path / "small.obj").write_text("v 0 0 0\nv 2 0 0\nv 0 2 0\nf 1 2 3\n")
    (tmp_path / "t.ply").write_text(PLY)
    f = make(tmp_path)
    before = sorted(tmp_path.iterdir())
    argv = [a.format(f=f, d=tmp_path) for a in argv]
    one_line(capsys, argv, 1, match, "1000000 mm (1 km)")
    assert sorted(tmp_path.iterdir()) == before


def test_a_mesh_within_the_bound_is_still_read(tmp_path):
    """A scan in scanner coordinates (a head 2 m from the origin) is not refused."""
    from myoface.face import load_mesh
    from myoface.face.mesh import MAX_COORDINATE_MM

    p = tmp_path / "far.obj"
    p.write_text(f"v 2000 0 0\nv 2100 0 0\nv 2000 100 0\nv {MAX_COORDINATE_MM} 0 0\nf 1 2 3\n")
    assert load_mesh(p).vertices[3, 0] == MAX_COORDINATE_MM


# ------------------------------------------------------------------------ 2. colour spaces


def _save_as(rgb: np.ndarray, path, mode: str):
    """``rgb`` saved in Pillow's ``mode`` (CMYK, P, L, LA, I;16 (16-bit grey), RGB16)."""
    from PIL import Image

    im = Image.fromarray(rgb)
    if mode == "I;16":
        grey = np.asarray(im.convert("L")).astype(np.uint16) * 257
        Image.fromarray(grey).save(path)  # (Pillow writes a 16-bit grey PNG)
    elif mode == "RGB16":
        _write_png16(path, rgb.astype(np.uint16) * 257)
    elif mode == "P":
        im.convert("P", palette=Image.Palette.ADAPTIVE).save(path)
    else:
        im.convert(mode).save(path, **({"quality": 95} if str(path).endswith(".jpg") else {}))
    return path


def _write_png16(path, rgb16: np.ndarray) -> None:
    """A 16-bit RGB PNG (Pillow cannot write one), by hand."""
    import struct
    import zlib

    h, w = rgb16.shape[:2]
    raw = b"".join(b"\x00" + rgb16[r].astype(">u2").tobytes() for r in range(h))

    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    ihdr = struct.pack(">IIBBBBB", w, h, 16, 2, 0, 0, 0)
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(raw))
    path.write_bytes(png + chunk(b"IEND", b""))


@pytest.mark.parametrize(
    ("mode", "suffix", "tol"),
    [
        ("CMYK", ".jpg", 3.0),  # read as RGBA before: the colours were wrong
        ("CMYK", ".tif", 1.0),
        ("P", ".png", 0.0),
        ("RGBA", ".png", 0.0),
        ("RGB16", ".png", 0.0),
    ],
)
def test_every_colour_space_is_read_as_its_rgb(tmp_path, mode, suffix, tol):
    from PIL import Image

    from myoface.face.image import read_image

    rng = np.random.default_rng(0)
    colours = (rng.random((16, 3)) * 255).astype(np.uint8)  # (a palette holds them all)
    rgb = colours[rng.integers(0, 16, (24, 32))]
    rgb = np.repeat(np.repeat(rgb, 4, 0), 4, 1)  # blocks: what a JPEG keeps
    path = _save_as(rgb, tmp_path / f"x{suffix}", mode)
    got = read_image(path)
    assert got.shape == rgb.shape and got.dtype == np.uint8
    assert np.abs(got.astype(int) - rgb).mean() <= tol
    if mode == "CMYK":  # what was read before: C, M, Y taken for R, G, B (the colours inverted)
        raw = np.asarray(Image.open(path))[:, :, :3]
        assert np.abs(raw.astype(int) - rgb).mean() > 40


@pytest.mark.parametrize("mode", ["L", "LA", "I;16", "1"])
def test_grey_images_are_read_as_grey_rgb(tmp_path, mode):
    from myoface.face.image import read_image

    grey = np.tile(np.array([0, 64, 128, 255], np.uint8), (8, 2))
    if mode == "1":
        grey = np.where(grey > 100, 255, 0).astype(np.uint8)
    rgb = np.repeat(grey[:, :, None], 3, axis=2)
    got = read_image(_save_as(rgb, tmp_path / "g.png", mode))
    np.testing.assert_array_equal(got, rgb)


@needs_mediapipe
def test_cmyk_photo_gives_the_face_of_the_rgb_photo(tmp_path, capsys, sample_frames):
    """#11: a CMYK JPEG of a face said "no face found"."""
    from myoface.face.facefile import read_face

    for mode in ("RGB", "CMYK"):
        photo = _save_as(sample_frames[0], tmp_path / f"{mode}.jpg", mode)
        code, out, err = run_cli(capsys, ["face", "from-photo", photo, "-o", tmp_path / mode])
        assert code == 1 and "must be a .myoface file" in err[0]  # (-o's suffix first)
        code, out, err = run_cli(
            capsys, ["face", "from-photo", photo, "-o", tmp_path / f"{mode}.myoface"]
        )
        assert code == 0 and err == [], err
    rgb, cmyk = (read_face(tmp_path / f"{m}.myoface")[0] for m in ("RGB", "CMYK"))
    assert np.abs(rgb.texture.astype(int) - cmyk.texture).mean() < 3
    assert np.abs(rgb.vertices - cmyk.vertices).max() < 2.0  # mm: the same face found


def test_cmyk_texture_renders_the_colours_of_the_rgb_one(tmp_path, capsys):
    """#11: ``synth --texture cmyk.jpg`` rendered wrong colours without a word."""
    import imageio.v3 as iio

    rng = np.random.default_rng(1)
    tex = np.repeat(np.repeat((rng.random((16, 16, 3)) * 255).astype(np.uint8), 8, 0), 8, 1)
    renders = {}
    for mode in ("RGB", "CMYK", "P"):
        path = _save_as(tex, tmp_path / f"{mode}.{'png' if mode == 'P' else 'jpg'}", mode)
        out = tmp_path / f"{mode}-render.png"
        argv = ["synth", "--texture", path, "--width", 48, "--height", 48, "--ssaa", 1]
        code, _, err = run_cli(capsys, [*argv, "-o", out])
        assert code == 0 and err == [], err
        renders[mode] = iio.imread(out).astype(int)
    # (two JPEG compressions of the same texture: CMYK's and RGB's; a palette's colours)
    assert np.abs(renders["CMYK"] - renders["RGB"]).mean() < 3
    assert np.abs(renders["P"] - renders["RGB"]).mean() < 6


def test_images_that_are_not_rgb_or_grey_are_refused_in_one_line(tmp_path, capsys):
    from PIL import Image

    Image.fromarray(np.linspace(0, 1, 64, dtype=np.float32).reshape(8, 8)).save(tmp_path / "f.tif")
    Image.fromarray(np.arange(64, dtype=np.int32).reshape(8, 8) * 1000).save(tmp_path / "i.tif")
    for name, kind in (("f.tif", "floating-point"), ("i.tif", "integer")):
        argv = ["synth", "--texture", tmp_path / name, "-o", tmp_path / "x.png"]
        one_line(capsys, argv, 1, f"{name}: a 32-bit {kind} image", "8 or 16 bits")
    assert not (tmp_path / "x.png").exists()


def test_an_image_of_too_many_pixels_is_refused_before_it_is_decoded(tmp_path, capsys):
    """A header that claims 20000 x 20000 pixels: refused from the header (it would be 1.2
    GB decoded), the bound said."""
    import struct
    import zlib

    def chunk(kind, data):
        body = kind + data
        return struct.pack(">I", len(data)) + body + struct.pack(">I", zlib.crc32(body))

    ihdr = struct.pack(">IIBBBBB", 20000, 20000, 8, 2, 0, 0, 0)
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IEND", b"")
    (tmp_path / "huge.png").write_bytes(png)
    argv = ["synth", "--texture", tmp_path / "huge.png", "-o", tmp_path / "x.png"]
    one_line(capsys, argv, 1, "huge.png: 400 million pixels", "at most 100 million pixels")
    ihdr = struct.pack(">IIBBBBB", 12000, 9000, 8, 2, 0, 0, 0)  # (below Pillow's own limit)
    png = b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IEND", b"")
    (tmp_path / "huge.png").write_bytes(png)
    one_line(capsys, argv, 1, "huge.png: 12000x9000 pixels (108 million)", "at most 100 million")


# --------------------------------------------------------------------- 3. numbers and limits


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (["--au", "12=1.5"], "argument --au: intensity of AU12 must be in [0, 1]; got '1.5'"),
        (["--au", "12=nan"], "argument --au: intensity of AU12 must be in [0, 1]; got 'nan'"),
        (["--au", "L12=-0.1"], "argument --au"),
        (["--muscle", "X=3"], "argument --muscle: intensity of muscle X must be in [0, 1]"),
        (["--muscle", "zygomaticus_major_l=inf"], "argument --muscle"),
        (["--au", "12=0.5", "--au", "12=0.6"], "--au 12 is given twice"),
    ],
)
def test_au_and_muscle_values_outside_their_limits_are_usage_errors(tmp_path, capsys, extra, match):
    """#12: exit status 1 where README promises 2 (a number outside its limits)."""
    one_line(capsys, ["synth", *extra, "-o", tmp_path / "x.png"], 2, match, "see myoface synth")
    assert not list(tmp_path.iterdir())


# ---------------------------------------------------------------- 4. silent but wrong: video


def _write_vfr(path, frames, times_s):
    """An H.264 MP4 whose frame k is shown at ``times_s[k]`` (a millisecond clock)."""
    import av

    with av.open(str(path), "w") as out:
        st = out.add_stream("libx264", rate=30)
        st.height, st.width = frames.shape[1:3]
        st.pix_fmt = "yuv420p"
        st.time_base = Fraction(1, 1000)
        for f, t in zip(frames, times_s, strict=True):
            vf = av.VideoFrame.from_ndarray(np.ascontiguousarray(f), format="rgb24")
            vf.pts, vf.time_base = int(round(t * 1000)), Fraction(1, 1000)
            for p in st.encode(vf):
                out.mux(p)
        for p in st.encode(None):
            out.mux(p)


#: 36 frames at 30 fps, then 10 at 10 fps (a phone camera slowing down in the dark): frame 35
#: is at 1.17 s, where the average rate (46 frames in 2.1 s) put it at 1.6 s
VFR_TIMES = np.concatenate([np.arange(36) / 30, 35 / 30 + np.arange(1, 11) / 10])


def test_variable_frame_rate_frames_are_timed_by_their_timestamps(tmp_path):
    from myoface.analysis.pipeline import Tracking
    from myoface.analysis.trackers.base import FrameMeasurement
    from myoface.analysis.video import open_video

    frames = np.zeros((len(VFR_TIMES), 32, 32, 3), np.uint8)
    frames[:] = (np.arange(len(VFR_TIMES)) * 5)[:, None, None, None]
    _write_vfr(tmp_path / "vfr.mp4", frames, VFR_TIMES)
    video = open_video(tmp_path / "vfr.mp4")
    assert abs(35 / video.fps - 1.6) < 0.05  # the average rate: frame 35 at 1.6 s
    times = np.array([t for t, _ in video.timed()])
    np.testing.assert_allclose(times, VFR_TIMES, atol=1e-3)

    class Stamps:  # a tracker that measures nothing but the time it is given
        OBSERVES_AHEAD = False
        ids = ("jaw",)

        def calibrate(self, frames, first_index):
            next(frames)
            return 0

        def measure(self, frame, index, time_s):
            return FrameMeasurement(index, time_s, "ok", np.zeros(1))

    got = [m for _, m in Tracking(video, Stamps())]
    assert [m.index for m in got] == list(range(len(VFR_TIMES)))
    np.testing.assert_allclose([m.time_s for m in got], VFR_TIMES, atol=1e-3)


@needs_mediapipe
@pytest.mark.slow  # (about 10 s: the model built, MediaPipe's calibration, 46 frames)
def test_variable_frame_rate_video_is_analysed_at_its_own_times(tmp_path, capsys, sample_frames):
    """The analysis' time_s column: frame 35 at 1.17 s, not the average rate's 1.6 s."""
    video = tmp_path / "vfr.mp4"
    _write_vfr(video, sample_frames[: len(VFR_TIMES)], VFR_TIMES)
    code, _, err = run_cli(capsys, ["analyze", video, "-o", tmp_path / "out", "--quiet"])
    assert code == 0 and err == [], err
    with open(tmp_path / "out" / "contractions.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == len(VFR_TIMES)
    np.testing.assert_allclose([float(r["time_s"]) for r in rows], VFR_TIMES, atol=1e-3)
    assert rows[35]["time_s"] == "1.1667"


@needs_mediapipe
@pytest.mark.slow
def test_the_calibration_window_is_two_seconds_of_the_videos_own_times(tmp_path, sample_frames):
    """A video slow at first (20 frames at 10 fps, then 40 at 30 fps): the calibration's
    "first 2 s" are its frames up to the first at or after 2 s (23 of them), not 2 s at the
    average rate (about 40 frames, 2.6 s)."""
    import json

    times = np.concatenate([np.arange(20) / 10, 1.9 + np.arange(1, 41) / 30])
    video = tmp_path / "slow_start.mp4"
    _write_vfr(video, np.resize(sample_frames, (len(times), *sample_frames.shape[1:])), times)
    assert main(["analyze", str(video), "-o", str(tmp_path / "out"), "--quiet"]) == 0
    doc = json.loads((tmp_path / "out" / "analysis.json").read_text())
    want = int(np.flatnonzero(times >= 2.0 - 1e-9)[0]) + 1
    assert len(doc["calibration"]["scores_mm"]) == want, len(doc["calibration"]["scores_mm"])


def _truncated_copy(src, path, keep: float):
    """``src`` remuxed with its index first ("faststart": the container declares every
    frame), then cut to the first ``keep`` of its bytes: a download or a copy interrupted."""
    import av

    full = path.with_name("full.mp4")
    with (
        av.open(str(src)) as inp,
        av.open(str(full), "w", options={"movflags": "faststart"}) as out,
    ):
        s_in = inp.streams.video[0]
        s_out = out.add_stream_from_template(s_in)
        for packet in inp.demux(s_in):
            if packet.dts is not None:
                packet.stream = s_out
                out.mux(packet)
    data = full.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])
    full.unlink()
    return path


def test_a_cut_short_video_warns_naming_both_counts(tmp_path):
    from myoface.analysis.video import open_video
    from myoface.render import VideoWriter

    rng = np.random.default_rng(0)  # noise: the frames' data, not the index, fill the file
    with VideoWriter(tmp_path / "grey.mp4", fps=10) as vw:
        for _ in range(30):
            vw.write(rng.integers(0, 255, (64, 64, 3), dtype=np.uint8))
    cut = _truncated_copy(tmp_path / "grey.mp4", tmp_path / "cut.mp4", 0.5)
    video = open_video(cut)
    assert video.n_frames == 30
    with pytest.warns(MyofaceWarning, match=r"only (\d+) of the 30 frames its container") as rec:
        n = len(list(video))
    assert 0 < n < 30 and f"only {n} of the 30" in str(rec[0].message)
    with _nothing():  # the whole file: nothing to say; stopped early (--max-frames): neither
        assert len(list(open_video(tmp_path / "grey.mp4"))) == 30
        it = iter(open_video(cut))
        next(it)
        it.close()


class _nothing:
    """No warning may be raised in the block."""

    def __enter__(self):
        import warnings

        self._cm = warnings.catch_warnings()
        self._cm.__enter__()
        warnings.simplefilter("error")

    def __exit__(self, *exc):
        return self._cm.__exit__(*exc)


@pytest.mark.shared_data
def test_the_sample_videos_are_not_said_to_be_cut_short():
    """no_face.mp4 declares 98 frames, of which its edit list shows 95 (to the stream's end):
    not a truncation."""
    from myoface.analysis.video import open_video

    with _nothing():
        for name, n in (("no_face.mp4", 95), ("single_face.mp4", 72), ("noface_face.mov", 169)):
            assert len(list(open_video(shared_path("video", name)))) == n


@needs_mediapipe
def test_a_truncated_mp4_is_analysed_with_a_warning(tmp_path, capsys):
    """The analysis went on with exit status 0 and no word about the frames lost."""
    cut = _truncated_copy(shared_path("video", "single_face.mp4"), tmp_path / "cut.mp4", 0.4)
    code, out, err = run_cli(capsys, ["analyze", cut, "-o", tmp_path / "out", "--quiet"])
    assert code == 0 and len(err) == 1, err
    m = re.fullmatch(
        r"myoface analyze: warning: \S+cut\.mp4: only (\d+) of the 72 frames its container "
        r"declares could be decoded: the file is cut short or damaged; the frames after them "
        r"are missing",
        err[0],
    )
    assert m, err
    n = int(m.group(1))
    assert 0 < n < 72 and f"analysed {n} frames" in out


# ---------------------------------------------------------------- 4. silent but wrong: photos


@pytest.fixture(scope="module")
def two_faces(sample_frames, tmp_path_factory):
    """A photo of two faces: the sample's face (153 px wide) on the left, a smaller copy
    (115 px) on the right. MediaPipe asked for one face gave the smaller."""
    from PIL import Image

    crop = sample_frames[0][:, 160:480]
    small = np.asarray(Image.fromarray(crop).resize((240, 270)))
    right = np.full_like(crop, 128)
    right[45:315, 40:280] = small
    path = tmp_path_factory.mktemp("two") / "two.png"
    Image.fromarray(np.concatenate([crop, right], axis=1)).save(path)
    return path


@needs_mediapipe
def test_a_photo_of_two_faces_says_which_it_used(tmp_path, capsys, two_faces):
    out = tmp_path / "f.myoface"
    code, stdout, err = run_cli(capsys, ["face", "from-photo", two_faces, "-o", out])
    assert code == 0 and len(err) == 1, err
    assert err[0].startswith("myoface face from-photo: warning: 2 faces in the photo; made of ")
    assert "made of face 0, the largest (numbered from 0, left to right; --face-index N" in err[0]
    assert "(face 0 of 2, left to right)" in stdout
    wide = float(re.search(r"face found (\d+) px wide", stdout).group(1))
    code, stdout, err = run_cli(
        capsys, ["face", "from-photo", two_faces, "--face-index", 1, "-o", out]
    )
    assert code == 0 and err == [], err
    assert "(face 1 of 2, left to right)" in stdout
    assert float(re.search(r"face found (\d+) px wide", stdout).group(1)) < 0.9 * wide
    out.unlink()
    one_line(
        capsys,
        ["face", "from-photo", two_faces, "--face-index", 2, "-o", out],
        1,
        "the photo has 2 faces (0 to 1, left to right); no face 2",
    )
    one_line(
        capsys,
        ["face", "from-photo", two_faces, "--face-index", 10, "-o", out],
        2,
        "argument --face-index: expected an integer in [0, 9]",
    )
    assert not out.exists()


@needs_mediapipe
@pytest.mark.slow
def test_a_huge_photo_is_read_scaled_down_in_modest_memory(tmp_path, sample_frames):
    """A 12000 x 6750 photo took 4.4 GB (the whole photo in float64, then a 12000-pixel
    texture); read at most 4096 px a side (the JPEG decoded at a reduced scale), the command
    stays under 1 GB, MediaPipe's own 0.2 GB included."""
    from PIL import Image

    photo = tmp_path / "huge.jpg"
    Image.fromarray(sample_frames[0]).resize((12000, 6750), Image.Resampling.BILINEAR).save(
        photo, quality=80
    )
    # the command in a process of its own, which says its peak memory (its VmHWM: the
    # process's own, not its parent's before the exec, as getrusage's would be)
    code = (
        "import sys\nfrom myoface.cli import main\nrc = main(sys.argv[1:])\n"
        "with open('/proc/self/status') as fh:\n"
        "    hwm = [ln.split()[1] for ln in fh if ln.startswith('VmHWM')]\n"
        "open('hwm.txt', 'w').write(hwm[0] if hwm else '')\nsys.exit(rc)\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code, "face", "from-photo", photo, "-o", "f.myoface"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    assert "photo      12000x6750 px, read at 4096x2304 (at most 4096 px a side)" in proc.stdout
    hwm = (tmp_path / "hwm.txt").read_text()
    if hwm:  # (Linux)
        assert int(hwm) / 1024 < 1000, f"{int(hwm) / 1024:.0f} MB"
    from myoface.face.facefile import read_face

    assert read_face(tmp_path / "f.myoface")[0].texture.shape == (2304, 4096, 3)


# ---------------------------------------------------------------- 4. silent but wrong: resynth


def _csv(path, header, rows):
    path.write_text("\n".join(",".join(map(str, r)) for r in [header, *rows]) + "\n")
    return path


def test_resynth_warns_of_the_muscles_without_a_column(tmp_path, capsys):
    """A missing muscle column was filled with rest without a word."""
    import imageio.v3 as iio

    c = _csv(tmp_path / "c.csv", ["time_s", "zygomaticus_major_l"], [[0, 0.1], [0.1, 0.2]])
    out = tmp_path / "v.mp4"
    code, _, err = run_cli(capsys, ["resynth", c, "-o", out, "--size", 32, "--quiet"])
    assert code == 0 and len(err) == 1, err
    assert err[0].startswith("myoface resynth: warning: c.csv: 38 of its 41 muscles have no ")
    assert "'frontalis_inner_l'" in err[0] and "(38 in all)" in err[0]
    assert "zygomaticus_major_l" not in err[0]
    assert iio.imread(out, plugin="pyav").shape[0] == 2


def test_resynth_refuses_a_csv_without_a_measured_row(tmp_path, capsys):
    """It rendered a video of the face at rest."""
    c = _csv(
        tmp_path / "c.csv", ["time_s", "quality", "jaw"], [[0, "no_face", ""], [0.1, "lost", ""]]
    )
    one_line(
        capsys,
        ["resynth", c, "-o", tmp_path / "v.mp4", "--quiet"],
        1,
        "c.csv: no row was measured",
        "nothing to resynthesize",
    )
    assert not (tmp_path / "v.mp4").exists()


def test_resynth_refuses_an_absurd_head_pose(tmp_path, capsys):
    from myoface.analysis.camera import POSE_COLUMNS

    header = ["time_s", "quality", "jaw", *POSE_COLUMNS]
    rows = [[0, "ok", 0.1, 0, 0, 0, 0, 0, 500], [0.1, "ok", 0.2, 1e9, 0, 0, 0, 0, 500]]
    c = _csv(tmp_path / "c.csv", header, rows)
    argv = ["resynth", c, "--pose", "-o", tmp_path / "v.mp4", "--quiet"]
    one_line(capsys, argv, 1, "row 3: head_yaw_deg is 1e+09", "within +-180")
    rows[1][3], rows[1][-1] = 0, 1e12
    _csv(c, header, rows)
    one_line(capsys, argv, 1, "row 3: head_tz_mm is 1e+12", "within +-10000")


def test_resynth_refuses_a_video_longer_than_an_hour(tmp_path, capsys):
    """73 rows 60 s apart made a 73-minute video, past resynth's own one hour."""
    c = _csv(tmp_path / "c.csv", ["time_s", "jaw"], [[60 * k, 0.1] for k in range(73)])
    one_line(
        capsys,
        ["resynth", c, "-o", tmp_path / "v.mp4", "--quiet"],
        1,
        "its 73 rows, 60 s apart, make a video of 73 minutes; a video is at most 1 hour",
    )


# ------------------------------------------------------- 4. silent but wrong: options ignored


def test_synth_intensity_without_an_expression_is_a_usage_error(tmp_path, capsys):
    """--intensity scales --expression / --viseme; alone it was ignored."""
    for extra in ([], ["--au", "12=0.5"]):
        argv = ["synth", "--intensity", "0.5", *extra, "-o", tmp_path / "x.png"]
        one_line(capsys, argv, 2, "--intensity is the emphasis of --expression or --viseme")
    assert not list(tmp_path.iterdir())


@pytest.mark.parametrize(
    ("extra", "match"),
    [
        (
            ["--estimator", "fiducials"],
            "--estimator fiducials is not an estimator of --tracker landmarks (the default)",
        ),
        (["--tracker", "landmarks", "--estimator", "curves"], "estimator of --tracker landmarks"),
        (["--tracker", "snakes", "--estimator", "paper"], "--estimator fiducials"),
    ],
)
def test_an_estimator_of_the_other_tracker_is_a_usage_error(
    tmp_path, capsys, tiny_video, extra, match
):
    """``--estimator fiducials`` with the landmark tracker silently meant ``paper``."""
    out = tmp_path / "out"
    one_line(capsys, ["analyze", tiny_video, *extra, "-o", out], 2, match, "see myoface analyze")
    assert not out.exists()


# ---------------------------------------------------------------- 5. messages that leaked


def _text_file(path, text="this is text, not an image"):
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("make", "argv", "match", "leak"),
    [
        (  # an image folder holding a text file named .png
            lambda d: _text_file(d / "frames" / "a.png") and d / "frames",
            ["analyze", "{f}", "-o", "{d}/out"],
            "a.png: not an image file",
            "need at least one array to stack",
        ),
        (
            lambda d: _text_file(d / "t.png"),
            ["synth", "--texture", "{f}", "-o", "{d}/x.png"],
            "t.png: not an image file",
            "need at least one array to stack",
        ),
        (
            lambda d: _text_file(d / "p.jpg"),
            ["face", "from-photo", "{f}", "-o", "{d}/x.myoface"],
            "p.jpg: not an image file",
            "need at least one array to stack",
        ),
        (  # an empty .png
            lambda d: _text_file(d / "e.png", ""),
            ["synth", "--texture", "{f}", "-o", "{d}/x.png"],
            "e.png: not an image file",
            "Could not find a backend",
        ),
        (
            lambda d: _text_file(d / "frames" / "e.png", "") and d / "frames",
            ["analyze", "{f}", "-o", "{d}/out"],
            "e.png: not an image file",
            "iomode",
        ),
        (
            lambda d: (d / "empty").mkdir() or d / "empty",
            ["analyze", "{f}", "-o", "{d}/out"],
            "a folder with no images",
            "stack",
        ),
        (  # a corrupt mp4: PyAV's AVERROR_INVALIDDATA
            lambda d: _text_file(d / "bad.mp4", "not a video " * 100),
            ["analyze", "{f}", "-o", "{d}/out"],
            "bad.mp4: not a readable video: invalid data",
            "Errno",
        ),
        (
            lambda d: _text_file(d / "bad.mp4", "not a video " * 100),
            ["face", "from-photo", "{f}", "-o", "{d}/x.myoface"],
            "bad.mp4: not a readable video",
            "1094995529",
        ),
        (  # a 5000-digit integer in a TOML timeline, a JSON timeline, a landmark file
            lambda d: _text_file(
                d / "t.toml", f'[[event]]\nkind = "au"\nname = "12"\nstart = {BIG}\n'
            ),
            ["synth", "--timeline", "{f}", "-o", "{d}/x.png"],
            "a number of 5000 digits (at most 4300)",
            "set_int_max_str_digits",
        ),
        (
            lambda d: _text_file(d / "t.json", f'{{"events": [{{"start": {BIG}}}]}}'),
            ["synth", "--timeline", "{f}", "-o", "{d}/x.png"],
            "a number of 5000 digits",
            "set_int_max_str_digits",
        ),
        (
            lambda d: _text_file(d / "l.ljson", f'{{"points": [[{BIG}, 0, 0]]}}'),
            ["face", "from-scan", "{f}", "--landmarks", "{f}", "-o", "{d}/x.myoface"],
            "l.ljson",
            "set_int_max_str_digits",
        ),
        (
            lambda d: (
                _face_file(d / "p.myoface", HUGE_OBJ)
                and _face_json(d / "p.myoface", f'{{"format": "myoface face", "version": {BIG}}}')
            ),
            ["info", "--face", "{f}"],
            "p.myoface: damaged face file: a number of 5000 digits",
            "set_int_max_str_digits",
        ),
        (  # ... and in a CSV's cell, and an option's value
            lambda d: _text_file(d / "c.csv", f"time_s,jaw\n0,0.1\n0.1,{BIG}\n"),
            ["resynth", "{f}", "-o", "{d}/v.mp4"],
            "row 3: jaw must be a number in [0, 1]; got '1111111111",
            BIG[:100],
        ),
    ],
)
def test_messages_say_what_is_wrong_with_the_file_not_the_library(
    tmp_path, capsys, make, argv, match, leak
):
    f = make(tmp_path)
    argv = [a.format(f=f, d=tmp_path) for a in argv]
    line = one_line(capsys, argv, 1, match, forbid=(leak, "Traceback"))
    assert len(line) < 400, line


def _face_json(path, text):
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("face.json", text)
        z.writestr("mesh.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    return path


def test_a_number_of_5000_digits_as_an_option_is_said_by_its_length(tmp_path, capsys):
    argv = ["analyze", "v.mp4", "-o", tmp_path / "o", "--calibration-frame", BIG]
    line = one_line(capsys, argv, 2, "expected an integer >= 0; got '1111", "(5000 characters)")
    assert len(line) < 200


def test_a_full_disk_names_the_file_it_was_writing(tmp_path, capsys, monkeypatch):
    """ "[Errno 28] No space left on device", and which file, on which disk?"""
    import imageio.v3 as iio

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(iio, "imwrite", full)
    out = tmp_path / "x.png"
    one_line(
        capsys,
        ["synth", "--au", "12=0.5", "--width", 32, "--height", 32, "-o", out],
        1,
        f"myoface synth: error: No space left on device (writing {out})",
        forbid=("Errno",),
    )
    assert list(tmp_path.iterdir()) == []


def test_a_full_disk_while_a_face_file_is_written_names_it(tmp_path, capsys, monkeypatch):
    import myoface.commands.face as face_cmd
    import myoface.face.personal as personal
    from myoface.face import load_default_face

    info = {"face_width_px": 100.0, "head_yaw_deg": 0.0, "fit_rms_to_generic_mm": 1.0}
    monkeypatch.setattr(face_cmd, "_read_photo", lambda path, frame: None)
    monkeypatch.setattr(personal, "face_from_photo", lambda *a, **k: (load_default_face(), info))

    def full(self, *args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(zipfile.ZipFile, "writestr", full)
    photo = _text_file(tmp_path / "me.png", "not read")
    out = tmp_path / "me.myoface"
    one_line(
        capsys,
        ["face", "from-photo", photo, "-o", out],
        1,
        f"myoface face from-photo: error: {out}: No space left on device",
    )
    assert sorted(p.name for p in tmp_path.iterdir()) == ["me.png"]


def test_a_full_disk_while_the_csv_is_streamed_names_it(tmp_path):
    from myoface.analysis.contractions_csv import ContractionsCsvWriter
    from myoface.analysis.trackers.base import FrameMeasurement

    class Full:
        def write(self, text):
            raise OSError(errno.ENOSPC, "No space left on device")

        def flush(self):
            pass

        def close(self):
            pass

    w = ContractionsCsvWriter(tmp_path / "contractions.csv", ["jaw"], None)
    w.write(FrameMeasurement(0, 0.0, "ok", np.zeros(1)))
    w._fh.close()
    w._fh = Full()
    with pytest.raises(OSError) as e:
        w.write(FrameMeasurement(1, 0.1, "ok", np.zeros(1)))
    assert e.value.errno == errno.ENOSPC and e.value.filename == str(tmp_path / "contractions.csv")
