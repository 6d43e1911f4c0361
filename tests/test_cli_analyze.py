"""``myoface analyze`` and ``myoface resynth`` on a short synthetic video (the model smiling)."""

import csv

import numpy as np
import pytest

from myoface.cli import main


@pytest.fixture(scope="module")
def smile_video(tmp_path_factory):
    from myoface.analysis.pipeline import project_sections, save_init
    from myoface.model import build_face_model
    from myoface.render import Camera, Renderer, VideoWriter, to_srgb8
    from myoface.render.dressing import default_skin_texture

    d = tmp_path_factory.mktemp("smile")
    fm = build_face_model()
    cam = Camera.front(fm.face.vertices, width=192, height=192, fov_deg=None)
    r = Renderer(fm.face, cam, texture=to_srgb8(default_skin_texture(fm.face, 256, makeup=True)))
    state = fm.rest_state()
    with VideoWriter(d / "smile.mp4", fps=10) as vw:
        for c in (0.0, 0.3, 0.6, 0.9, 0.6, 0.3, 0.0):
            state = fm.relax({"zygomaticus_major_l": c, "zygomaticus_major_r": c}, state).state
            vw.write(r.render(fm.skin_vertices(state)))
    save_init(d / "init.json", project_sections(fm, cam))
    return d


def test_analyze_then_resynth(smile_video, tmp_path, capsys):
    out = tmp_path / "ana"
    assert (
        main(
            [
                "analyze",
                str(smile_video / "smile.mp4"),
                "--init",
                str(smile_video / "init.json"),
                "-o",
                str(out),
                "--quiet",
            ]
        )
        == 0
    )
    for name in ("contractions.csv", "analysis.json", "contractions.png", "overlay.mp4"):
        assert (out / name).stat().st_size > 0, name
    with open(out / "contractions.csv", newline="") as fh:
        rows = list(csv.DictReader(fh))
    z = np.array([float(r["zygomaticus_major_l"]) for r in rows])
    assert len(rows) == 7 and z[3] > z[0] + 0.3 and z[3] > z[6] + 0.3  # rises and returns
    import json

    side = json.loads((out / "analysis.json").read_text())
    assert side["estimator"] == "curves" and side["sigma_px"] > 0
    # the paper's fiducial scheme, on request
    out2 = tmp_path / "ana_fid"
    argv = ["analyze", str(smile_video / "smile.mp4"), "--init", str(smile_video / "init.json")]
    assert main([*argv, "-o", str(out2), "--estimator", "fiducials", "--quiet"]) == 0
    assert json.loads((out2 / "analysis.json").read_text())["estimator"] == "fiducials"
    with open(out2 / "contractions.csv", newline="") as fh:
        z2 = np.array([float(r["zygomaticus_major_l"]) for r in csv.DictReader(fh)])
    assert z2[3] > z2[0] + 0.3
    video = tmp_path / "re.mp4"
    assert (
        main(
            [
                "resynth",
                str(out / "contractions.csv"),
                "-o",
                str(video),
                "--size",
                "96",
                "--side-by-side",
                str(smile_video / "smile.mp4"),
                "--quiet",
            ]
        )
        == 0
    )
    import imageio.v3 as iio

    frames = iio.imread(video, plugin="pyav")
    assert frames.shape[0] == 7 and frames.shape[2] == 192  # input | resynthesis


def test_analyze_check_init(smile_video, tmp_path):
    png = tmp_path / "check.png"
    assert (
        main(
            [
                "analyze",
                str(smile_video / "smile.mp4"),
                "--init",
                str(smile_video / "init.json"),
                "--check-init",
                str(png),
            ]
        )
        == 0
    )
    assert png.stat().st_size > 0


@pytest.mark.parametrize("case", ["missing", "empty", "bad_init", "outside"])
def test_analyze_bad_input(smile_video, tmp_path, capsys, case):
    video, init = smile_video / "smile.mp4", smile_video / "init.json"
    if case == "missing":
        video, match = tmp_path / "none.mp4", "no such video"
    elif case == "empty":
        video = tmp_path / "empty.mp4"
        video.write_bytes(b"")
        match = "empty"
    elif case == "bad_init":
        init = tmp_path / "i.json"
        init.write_text('{"contours": {"lips": [[1, 2, 3]]}}')
        match = "at least 2"
    else:
        init = tmp_path / "i.json"
        init.write_text('{"contours": {"lips": [[1, 2], [5000, 3]]}}')
        match = "outside the frame"
    out = tmp_path / "out"
    assert main(["analyze", str(video), "--init", str(init), "-o", str(out)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[0], err
    assert not out.exists() or not any(out.iterdir())


def test_resynth_bad_csv(tmp_path, capsys):
    p = tmp_path / "c.csv"
    p.write_text("time_s,jaw\n0,nan\n")
    assert main(["resynth", str(p), "-o", str(tmp_path / "v.mp4")]) == 1
    assert "must be a number" in capsys.readouterr().err
    assert not (tmp_path / "v.mp4").exists()
