"""``myoface encode`` / ``myoface decode`` end to end on a few frames of the sample video, and
the bad streams through the command line (one line, exit status 1; a truncated stream keeps
its frames)."""

from __future__ import annotations

import subprocess
import sys

import numpy as np
import pytest

from myoface.cli import main
from tests.conftest import needs_mediapipe, shared_path

pytestmark = [needs_mediapipe, pytest.mark.slow]

N = 6


def _frames(path) -> list[np.ndarray]:
    from myoface.analysis.video import open_video

    return list(open_video(path))


@pytest.fixture(scope="module")
def encoded(tmp_path_factory):
    video = shared_path("video", "single_face.mp4")
    out = tmp_path_factory.mktemp("codec") / "clip.myo"
    argv = ["encode", str(video), "-o", str(out), "--max-frames", str(N),
            "--calibration-frame", "0", "--quiet"]  # fmt: skip
    assert main(argv) == 0
    return video, out


def test_encode_then_decode_the_sample(encoded, tmp_path, capsys):
    from myoface.codec.encode import psnr_y
    from myoface.codec.stream import BytesSource, StreamReader

    video, clip = encoded
    data = clip.read_bytes()
    reader = StreamReader(BytesSource(data))
    params = list(reader)
    assert len(params) == N and all(p.measured for p in params)
    assert reader.header.calibration_index == 0
    assert (reader.header.width, reader.header.height) == (640, 360)
    body_bits = 8 * (len(data) - len(reader.header.to_bytes()) - 12) / N
    assert body_bits < 400  # (a few frames: the first packets teach the models)
    out = tmp_path / "out.mp4"
    assert main(["decode", str(clip), "-o", str(out), "--quiet"]) == 0
    assert f"({N} frames" in capsys.readouterr().out
    got, ref = _frames(out), _frames(video)[:N]
    assert len(got) == N and got[0].shape == (360, 640, 3)
    # the calibration frame is the picture the header carries (its codec's PSNR-Y target is
    # 36 dB at the default quality; the H.264 of out.mp4 on top)
    assert psnr_y(got[0], ref[0]) > 30
    # the frames after it follow the video better than the picture alone does (measured
    # 2026-12-02: 0.8 to 1.8 dB better on frames 1-5, where the video moves away from it)
    picture = reader.header.picture()
    gain = [psnr_y(g, r) - psnr_y(picture, r) for g, r in zip(got[1:], ref[1:], strict=True)]
    assert min(gain) > -0.2 and np.mean(gain) > 0.5


def test_decode_from_a_pipe(encoded, tmp_path):
    _, clip = encoded
    out = tmp_path / "piped.mp4"
    with open(clip, "rb") as fh:
        r = subprocess.run(
            [sys.executable, "-m", "myoface", "decode", "-", "-o", str(out), "--quiet"],
            stdin=fh, capture_output=True, text=True, timeout=300,
        )  # fmt: skip
    assert r.returncode == 0, r.stderr
    assert len(_frames(out)) == N


def test_a_truncated_stream_keeps_its_frames_and_says_so(encoded, tmp_path, capsys):
    _, clip = encoded
    data = clip.read_bytes()
    cut = tmp_path / "cut.myo"
    cut.write_bytes(data[:-20])
    out = tmp_path / "cut.mp4"
    assert main(["decode", str(cut), "-o", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "truncated stream" in err and "frames decoded are in" in err
    n = len(_frames(out))
    assert 1 <= n < N and f"the {n} frames decoded" in err


@pytest.mark.parametrize("what", ["corrupted", "version"])
def test_a_bad_stream_ends_in_one_line_and_no_video(encoded, tmp_path, capsys, what):
    _, clip = encoded
    data = bytearray(clip.read_bytes())
    if what == "corrupted":
        data[-30] ^= 0x10  # (in the body)
    else:
        data[4] = 9
    bad = tmp_path / "bad.myo"
    bad.write_bytes(bytes(data))
    out = tmp_path / "bad.mp4"
    assert main(["decode", str(bad), "-o", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err.strip()
    assert "\n" not in err
    assert ("corrupted stream" if what == "corrupted" else "format version 9") in err
    assert not out.exists()


def test_an_interrupted_encode_keeps_a_complete_stream(tmp_path):
    """SIGINT once packets are being written: exit status 130, and the stream under the
    user's name is complete (its end marker written) with the frames encoded before."""
    import os
    import signal
    import time

    from myoface.codec.stream import FileSource, StreamReader

    video = shared_path("video", "single_face.mp4")
    out = tmp_path / "int.myo"
    p = subprocess.Popen(
        [sys.executable, "-m", "myoface", "encode", str(video), "-o", str(out), "--quiet"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    t0 = time.monotonic()
    part = None
    while time.monotonic() - t0 < 240 and p.poll() is None:
        parts = list(tmp_path.glob(".int.*.part.myo"))
        if parts and parts[0].stat().st_size > 2000:  # (the header and some packets)
            part = parts[0]
            break
        time.sleep(0.02)
    assert part is not None, "the encode wrote no packets"
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 128 + signal.SIGINT, err
    assert "interrupted (SIGINT)" in err and "is complete with the frames encoded" in err
    assert not list(tmp_path.glob(".int.*"))  # (no temporary file left)
    src = FileSource(out)
    try:
        frames = list(StreamReader(src))  # (a truncated stream would raise)
    finally:
        src.close()
    assert 1 <= len(frames) < 72
    assert os.path.getsize(out) > 2000
