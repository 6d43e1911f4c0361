"""The CLI skeleton, ``myoface info`` and ``myoface bench`` (smoke runs so they cannot rot)."""

import json
import subprocess
import sys

import numpy as np
import pytest

from myoface.cli import main
from tests.conftest import REPO, needs_mediapipe


def test_no_command_is_a_usage_error(capsys):
    assert main([]) == 2


def test_info_prints_lattice_counts(capsys):
    assert main(["info", "--muscles-list"]) == 0
    out = capsys.readouterr().out
    assert "2556 elements, 13302 springs" in out
    assert "zygomaticus_major_l" in out and "jaw" in out


def test_info_bad_face_is_one_line_error(capsys, tmp_path):
    assert main(["info", "--face", str(tmp_path / "none.obj")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no such face model" in err[0]


def test_bench_list_has_the_contract_names(capsys):
    assert main(["bench", "--list"]) == 0
    out = capsys.readouterr().out
    for name in ("tissue.rk2_steps_per_s", "tissue.relax_ms", "tissue.ns_per_spring_1m"):
        assert name in out


def test_bench_unknown_prefix(capsys):
    assert main(["bench", "--only", "nothing."]) == 1


@pytest.mark.slow
def test_bench_json_record_schema(quick_run):
    rec = [r for r in quick_run[0] if r["name"] == "tissue.rk2_steps_per_s"]
    assert len(rec) == 1
    r = rec[0]
    assert set(r) == {
        "name",
        "value",
        "unit",
        "higher_is_better",
        "peer",
        "peer_value",
        "n",
        "machine",
        "software",
    }
    # the libraries' versions the numbers rest on, as installed here
    from importlib.metadata import version

    assert f"numpy {version('numpy')}" in r["software"]
    assert r["name"] == "tissue.rk2_steps_per_s" and r["unit"] == "1/s" and r["higher_is_better"]
    # a rate measured on at least one repeat: finite and positive
    assert 0 < r["value"] < float("inf") and isinstance(r["n"], int) and r["n"] >= 1


def test_benchmarks_md_generator(tmp_path):
    run = tmp_path / "run.json"
    run.write_text(
        json.dumps(
            [
                {
                    "name": "snakes.track_fps_9x40_256",
                    "value": 1000.0,
                    "unit": "1/s",
                    "higher_is_better": True,
                    "peer": "skimage",
                    "peer_value": 10.0,
                    "n": 5,
                    "machine": "test machine",
                    "software": "numpy 9.9.9, mediapipe -",
                },
                {
                    "name": "tissue.relax_ms",
                    "value": 20.0,
                    "unit": "ms",
                    "higher_is_better": False,
                    "peer": None,
                    "peer_value": None,
                    "n": 3,
                    "machine": "test machine",
                },
            ]
        )
    )
    md = tmp_path / "B.md"
    subprocess.run(
        [
            sys.executable,
            str(REPO / "benchmarks" / "make_benchmarks_md.py"),
            "--json",
            str(run),
            "--out",
            str(md),
        ],
        check=True,
        capture_output=True,
    )
    text = md.read_text()
    assert "test machine" in text
    assert "Software: numpy 9.9.9, mediapipe -." in text
    assert "| `snakes.track_fps_9x40_256` | 1,000 | 1/s | skimage | 10 | 100× |" in text
    assert ">= 500 (met)" in text and "<= 10 (**not met**)" in text


@pytest.mark.slow
def test_every_benchmark_runs_quick(quick_run):
    from myoface.bench import load_all

    records = quick_run[0]
    assert {r["name"] for r in records} == set(load_all())
    assert all(r["value"] == r["value"] for r in records)  # no NaN


def test_bench_list_has_the_gaze_benchmark(capsys):
    assert main(["bench", "--list"]) == 0
    assert "analysis.gaze_error_deg" in capsys.readouterr().out


@pytest.mark.slow
def test_gaze_benchmark_runs_quick(quick_run):
    """``analysis.gaze_error_deg`` on its quick clip (30 frames): a finite value in degrees and
    the detail's parts (each eye on the analysis and on the reader alone, the blinks)."""
    from myoface.facemesh import mediapipe_available

    if not mediapipe_available():
        pytest.skip('needs pip install "myoface[mediapipe]"')
    records, detail = quick_run
    (rec,) = [r for r in records if r["name"] == "analysis.gaze_error_deg"]
    assert rec["unit"] == "deg"
    assert np.isfinite(rec["value"]) and 0 < rec["value"] < 45 and rec["n"] == 30
    fit = detail["analysis.gaze_error_deg"]["photometric"]  # (the default analysis)
    assert set(fit["per_eye"]) == {"l", "r"} == set(fit["reader_on_true_geometry"])
    assert fit["value"] == pytest.approx(rec["value"], abs=1e-6)
    for eye in fit["per_eye"].values():
        assert eye["open_frames_read"] > 0.8 and eye["shut_frames_said_closed"] is not None


@pytest.mark.shared_data
@needs_mediapipe
def test_the_known_warp_bench_reads_the_models_motion_in_the_warps_axes(quick_run):
    """``analysis.known_warp_*``'s comparison (the whole analysis on the known-warp clips, the
    model read from its vertices) in the warp's axes: every frame measured, every region's
    gain and explained fraction finite, and the brows moving the model the way the warp
    moved them (a sign or axis error would make it negative). Read from the session's quick
    run of every benchmark (its head-still clips), not run again."""
    from myoface.bench.knownwarp import EXPRESSIONS, NEUTRAL_FRAMES

    res = quick_run[1]["analysis.known_warp_gain"]["head still"]
    assert res["frames"] == len(EXPRESSIONS) * (NEUTRAL_FRAMES + 3 + 6 + 3)
    for r, v in res["regions"].items():
        assert np.isfinite(v["gain"]) and np.isfinite(v["explained"]), r
        assert v["true_rms_iod"] > 0.002, r
    assert res["regions"]["brows"]["gain"] > 0.3 and res["regions"]["brows"]["explained"] > 0.3
    assert np.isfinite(res["leak"])
