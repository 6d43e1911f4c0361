"""The OpenFace-2.2-compatible CSV (``myoface.analysis.openface``)."""

import csv

import numpy as np
import pytest

from myoface.analysis.camera import HeadPose, PinholeCamera
from myoface.analysis.gaze import EyeGaze, Gaze
from myoface.analysis.openface import (
    MYOFACE_COLUMNS,
    OPENFACE_AUS,
    OPENFACE_COLUMNS,
    OPENFACE_GAZE_COLUMNS,
    UNMEASURED_AUS,
    au_basis,
    au_intensities,
    openface_gaze,
    openface_pose,
    write_openface_csv,
)
from myoface.analysis.trackers.landmark_fit import FitMeasurement
from myoface.control.facs import au_contractions


@pytest.fixture(scope="module")
def ids():
    from myoface.muscles.io import load_default_muscles

    return list(load_default_muscles().ids)


#: the AUs myoface measures in the OpenFace list
MEASURED = [n for n in OPENFACE_AUS if n not in UNMEASURED_AUS]


#: the pose columns
POSE = [f"pose_{a}" for a in ("Tx", "Ty", "Tz", "Rx", "Ry", "Rz")]


def test_columns_and_their_order():
    """OpenFace 2.2's sequence header (RecorderCSV.cpp: frame,face_id,timestamp,confidence,
    success, then the gaze vectors and angles, then the pose, then the AU intensities sorted by
    name), without the columns myoface does not measure (the eye landmarks between the gaze and
    the pose, ...)."""
    aus = "01 02 04 05 06 07 09 10 12 14 15 17 20 23 25 26 45".split()
    expected = ["frame", "face_id", "timestamp", "confidence", "success"]
    expected += ["gaze_0_x", "gaze_0_y", "gaze_0_z", "gaze_1_x", "gaze_1_y", "gaze_1_z"]
    expected += ["gaze_angle_x", "gaze_angle_y", *POSE]
    expected += [f"AU{a}_r" for a in aus]
    assert list(OPENFACE_COLUMNS) == expected
    assert list(OPENFACE_GAZE_COLUMNS) == expected[5:13]
    assert sorted(OPENFACE_COLUMNS[19:]) == list(OPENFACE_COLUMNS[19:])


def test_the_basis_has_full_rank(ids):
    """Every measured AU (per side) asks the default face's muscles for a different pattern:
    the fit's answer is unique."""
    b = au_basis(ids)
    assert b.aus == tuple(MEASURED)
    assert np.linalg.matrix_rank(b.weights) == b.weights.shape[1]


@pytest.mark.parametrize("au", MEASURED)
@pytest.mark.parametrize("intensity", [0.3, 1.0])
def test_a_single_au_gives_its_intensity_back(ids, au, intensity):
    c = au_contractions({au: intensity}, ids)
    out = au_intensities(c, ids)
    col = OPENFACE_AUS.index(au)
    assert out[col] == pytest.approx(5 * intensity, abs=1e-3)
    others = [j for j, n in enumerate(OPENFACE_AUS) if n != au and n not in UNMEASURED_AUS]
    np.testing.assert_allclose(out[others], 0.0, atol=1e-3)
    assert np.isnan(out[[OPENFACE_AUS.index(n) for n in UNMEASURED_AUS]]).all()


def test_au7_is_reported_as_the_aus_of_its_muscles(ids):
    """AU7's muscles are AU6's orbital sphincter (0.5) and AU45's palpebral part (0.3): its
    contractions read as AU6 at 0.5 / 0.9 and AU45 at 0.3 of its intensity, AU07 empty."""
    out = au_intensities(au_contractions({7: 0.9}, ids), ids)
    assert np.isnan(out[OPENFACE_AUS.index(7)])
    assert out[OPENFACE_AUS.index(6)] == pytest.approx(5 * 0.9 * 0.5 / 0.9, abs=1e-3)
    assert out[OPENFACE_AUS.index(45)] == pytest.approx(5 * 0.9 * 0.3, abs=1e-3)


def test_one_side_of_a_bilateral_au_is_half_its_intensity(ids):
    out = au_intensities(au_contractions({"L12": 0.8}, ids), ids)
    assert out[OPENFACE_AUS.index(12)] == pytest.approx(0.5 * 5 * 0.8, abs=1e-3)


def test_mixed_aus_through_the_mixing_rule(ids):
    """AUs that share muscles (1, 2 and 5 on the frontalis; 25 and 26 on the jaw) mix by the
    probabilistic OR: the fit through that rule recovers each of them."""
    aus = {1: 0.6, 2: 0.4, 5: 0.5, 12: 0.9, 25: 0.7, 26: 0.5, 4: 0.3, 9: 0.6}
    out = au_intensities(au_contractions(aus, ids), ids)
    for n in MEASURED:
        assert out[OPENFACE_AUS.index(n)] == pytest.approx(5 * aus.get(n, 0.0), abs=2e-3), n


def test_rows_and_nan(ids):
    rng = np.random.default_rng(0)
    table = np.vstack([au_contractions({6: 0.5}, ids), np.full(len(ids), np.nan)])
    out = au_intensities(table, ids)
    assert out.shape == (2, len(OPENFACE_AUS))
    assert out[0, OPENFACE_AUS.index(6)] == pytest.approx(2.5, abs=1e-3)
    assert np.isnan(out[1]).all()
    out = au_intensities(rng.uniform(0, 1, (3, len(ids))), ids)  # any vector: on the scale
    ok = np.isfinite(out)
    assert ((out[ok] >= 0) & (out[ok] <= 5)).all()


def _openface_rotation(rx, ry, rz):
    """OpenFace's Euler2RotationMatrix: R = Rx Ry Rz, right-handed matrices."""
    cx, sx, cy, sy, cz, sz = np.cos(rx), np.sin(rx), np.cos(ry), np.sin(ry), np.cos(rz), np.sin(rz)
    mx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    my = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    mz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return mx @ my @ mz


@pytest.mark.parametrize(
    "angles, shift",
    [((0, 0, 0), (0, 0, -500)), ((25, -10, 5), (12, -3, -480)), ((-30, 15, -12), (-20, 8, -600))],
)
def test_pose_in_openfaces_camera_frame(default_face, angles, shift):
    """A face point placed by the OpenFace pose (its head axes: x right, y down, z away from
    the camera; OpenCV's pinhole projection) lands on the pixel where myoface's pose puts it."""
    pose = HeadPose.from_euler(*angles, shift)
    tx, ty, tz, rx, ry, rz = openface_pose(pose)
    assert tz > 0  # in front of the camera, z away from it
    cam = PinholeCamera.for_image(640, 480)
    v = default_face.vertices
    ours = cam.project(pose.apply(v))
    p = (v * [1, -1, -1]) @ _openface_rotation(rx, ry, rz).T + [tx, ty, tz]
    theirs = np.column_stack(
        [cam.focal_px * p[:, 0] / p[:, 2] + cam.cx, cam.focal_px * p[:, 1] / p[:, 2] + cam.cy]
    )
    np.testing.assert_allclose(theirs, ours, atol=1e-6)


def test_pose_signs():
    """OpenFace's pitch is Rx (nodding down is positive: y points down), yaw Ry (a face turned
    to the image's right is negative: z points away), roll Rz."""
    assert openface_pose(HeadPose.from_euler(0, 10, 0))[3] == pytest.approx(np.radians(10))
    assert openface_pose(HeadPose.from_euler(20, 0, 0))[4] == pytest.approx(-np.radians(20))
    assert openface_pose(HeadPose.from_euler(0, 0, 5))[5] == pytest.approx(-np.radians(5))
    assert openface_pose(HeadPose.from_euler(0, 0, 0, (10, 20, -400)))[:3] == pytest.approx(
        (10, -20, 400)
    )


def _read(path):
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    return rows[0], rows[1:]


def test_write_openface_csv_from_the_3d_fit(tmp_path, ids):
    from myoface.analysis.contractions_csv import write_contractions_csv

    smile = au_contractions({12: 0.8, 6: 0.4}, ids)
    pose = HeadPose.from_euler(10, -5, 2, (1, 2, -500))
    frames = [
        FitMeasurement(0, 0.0, "ok", np.zeros(len(ids)), pose, 0.3),
        FitMeasurement(1, 0.04, "no_face", np.full(len(ids), np.nan), None, float("nan")),
        FitMeasurement(2, 0.08, "ok", smile, pose, 0.4),
    ]
    src = tmp_path / "contractions.csv"
    write_contractions_csv(src, ids, frames, 0.3)
    out = write_openface_csv(src, tmp_path / "openface.csv")
    head, rows = _read(out)
    assert head == [*OPENFACE_COLUMNS, *MYOFACE_COLUMNS]  # (the expressions after OpenFace's)
    assert [r[0] for r in rows] == ["1", "2", "3"]  # OpenFace counts frames from 1
    assert [r[4] for r in rows] == ["1", "0", "1"]  # success
    assert [float(r[3]) for r in rows] == [1.0, 0.0, 1.0]
    assert [float(r[2]) for r in rows] == [0.0, 0.04, 0.08]
    # a frame that could not be measured: zeros, as OpenFace writes them
    n = len(OPENFACE_COLUMNS)
    assert rows[1][1] == "0" and all(float(x) == 0.0 for x in rows[1][3:n])
    assert rows[1][n:] == [""] * len(MYOFACE_COLUMNS)  # (myoface's: not measured)
    row = dict(zip(head, rows[2], strict=True))
    assert float(row["AU12_r"]) == pytest.approx(4.0, abs=0.01)
    assert float(row["AU06_r"]) == pytest.approx(2.0, abs=0.01)
    assert float(row["AU01_r"]) == pytest.approx(0.0, abs=0.01)
    assert row["AU07_r"] == "" and float(row["AU45_r"]) == pytest.approx(0.0, abs=0.01)
    want = openface_pose(pose)
    got = [float(row[c]) for c in POSE]
    np.testing.assert_allclose(got[:3], want[:3], atol=0.06)  # mm, 1 decimal
    np.testing.assert_allclose(got[3:], want[3:], atol=6e-4)  # rad, 3 decimals


def test_write_openface_csv_without_a_3d_pose(tmp_path, ids):
    """The snakes' CSV: the paper's 12 muscles + jaw and a 2-D head frame. The pose cells are
    empty, and AUs whose principal muscles were not estimated (AU4: the corrugators) too."""
    from myoface.analysis.sections import PAPER_MUSCLES

    cols = list(PAPER_MUSCLES)
    c = au_contractions({12: 0.6}, ids)
    vals = [f"{c[ids.index(m)]:.5f}" for m in cols]
    text = ",".join(["frame", "time_s", "quality", *cols, "head_dx_px"]) + "\n"
    text += ",".join(["0", "0.0", "ok", *vals, "0.5"]) + "\n"
    src = tmp_path / "contractions.csv"
    src.write_text(text)
    head, rows = _read(write_openface_csv(src, tmp_path / "openface.csv"))
    row = dict(zip(head, rows[0], strict=True))
    assert all(row[c] == "" for c in POSE)
    assert all(row[c] == "" for c in OPENFACE_GAZE_COLUMNS)  # no gaze without a 3-D fit
    assert row["AU04_r"] == "" and row["AU06_r"] == "" and row["AU45_r"] == ""
    assert float(row["AU12_r"]) == pytest.approx(3.0, abs=0.01)
    assert float(row["AU01_r"]) == pytest.approx(0.0, abs=0.01)


def _deg(yaw_l, pitch_l, yaw_r, pitch_r):
    return np.array([yaw_l, pitch_l, yaw_r, pitch_r], dtype=float)


def test_gaze_into_the_camera_is_straight_ahead():
    """OpenFace's documented convention (wiki "Output Format", GazeEstimation.cpp): camera
    frame x right, y down, z away from the camera; a frontal face looking straight ahead gives
    (0, 0, -1) for both eyes and angles 0."""
    pose = HeadPose.from_euler(0, 0, 0, (0, 0, -500))
    g = openface_gaze(pose, _deg(0, 0, 0, 0))
    np.testing.assert_allclose(g[:3], [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(g[3:6], [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(g[6:], [0, 0], atol=1e-12)


@pytest.mark.parametrize("yaw, pitch", [(20.0, 0.0), (-15.0, 0.0), (0.0, 10.0), (12.0, -8.0)])
def test_a_known_gaze_gives_the_documented_vector(yaw, pitch):
    """A frontal face whose eyes turn towards the person's left (the image's right) by ``yaw``
    and up by ``pitch``: x = sin(yaw) cos(pitch) > 0 to the right, y = -sin(pitch) (y down),
    z = -cos(yaw) cos(pitch) (towards the camera); gaze_angle_x = atan2(x, -z) = yaw and
    gaze_angle_y = atan2(y, -z), negative looking up (the wiki: up-down goes from negative to
    positive)."""
    pose = HeadPose.from_euler(0, 0, 0, (0, 0, -500))
    g = openface_gaze(pose, _deg(yaw, pitch, yaw, pitch))
    y, p = np.radians(yaw), np.radians(pitch)
    want = [np.sin(y) * np.cos(p), -np.sin(p), -np.cos(y) * np.cos(p)]
    np.testing.assert_allclose(g[:3], want, atol=1e-12)
    np.testing.assert_allclose(g[3:6], want, atol=1e-12)
    assert g[6] == pytest.approx(y, abs=1e-12)
    assert g[7] == pytest.approx(np.arctan2(-np.sin(p), np.cos(y) * np.cos(p)), abs=1e-12)
    assert np.sign(g[7]) == -np.sign(pitch) or pitch == 0


def test_gaze_turns_with_the_head_and_eye_0_is_the_right_eye():
    """The vectors are in the camera frame: eyes straight ahead in a head turned 30 deg to the
    person's left point 30 deg to the image's right. Eye 0 (the leftmost in the image) is the
    person's right eye: with only the left eye read, gaze_0 is NaN and the angles are the left
    eye's."""
    pose = HeadPose.from_euler(30, 0, 0, (0, 0, -500))
    g = openface_gaze(pose, _deg(0, 0, 0, 0))
    np.testing.assert_allclose(g[:3], [0.5, 0, -np.sqrt(3) / 2], atol=1e-12)
    assert g[6] == pytest.approx(np.radians(30), abs=1e-12)
    only_left = openface_gaze(HeadPose.from_euler(0, 0, 0), _deg(10, 0, np.nan, np.nan))
    assert np.isnan(only_left[:3]).all()
    np.testing.assert_allclose(only_left[3:6], [np.sin(np.radians(10)), 0, -np.cos(np.radians(10))])
    assert only_left[6] == pytest.approx(np.radians(10))
    none = openface_gaze(HeadPose.from_euler(0, 0, 0), np.full(4, np.nan))
    assert np.isnan(none).all()


def test_write_openface_csv_gaze_cells(tmp_path, ids):
    """The gaze of the 3-D fit's rows in the CSV: 6 decimals for the vectors, 3 for the angles;
    an eye whose lids are closed has empty cells, a frame not measured zeros."""
    from myoface.analysis.contractions_csv import write_contractions_csv

    pose = HeadPose.from_euler(0, 0, 0, (0, 0, -500))
    both = Gaze(EyeGaze(20.0, 0.0, "ok"), EyeGaze(20.0, 0.0, "ok"))
    wink = Gaze(EyeGaze(0.0, 10.0, "ok"), EyeGaze(state="closed"))
    zero = np.zeros(len(ids))
    frames = [
        FitMeasurement(0, 0.0, "ok", zero, pose, 0.3, gaze=both),
        FitMeasurement(1, 0.04, "ok", zero, pose, 0.3, gaze=wink),
        FitMeasurement(2, 0.08, "no_face", np.full(len(ids), np.nan), None, float("nan")),
    ]
    src = tmp_path / "contractions.csv"
    write_contractions_csv(src, ids, frames, 0.3)
    head, rows = _read(write_openface_csv(src, tmp_path / "openface.csv"))
    r0, r1, r2 = (dict(zip(head, r, strict=True)) for r in rows)
    s, c = np.sin(np.radians(20)), np.cos(np.radians(20))
    assert [r0[f"gaze_0_{a}"] for a in "xyz"] == [f"{s:.6f}", "0.000000", f"{-c:.6f}"]
    assert r0["gaze_angle_x"] == f"{np.radians(20):.3f}" and r0["gaze_angle_y"] == "0.000"
    assert all(r1[f"gaze_0_{a}"] == "" for a in "xyz")  # the right eye: closed
    assert float(r1["gaze_1_y"]) == pytest.approx(-np.sin(np.radians(10)), abs=1e-6)
    assert float(r1["gaze_angle_y"]) == pytest.approx(-np.radians(10), abs=6e-4)
    assert all(float(r2[col]) == 0.0 for col in OPENFACE_GAZE_COLUMNS)
