"""The analysis as an OpenFace-2.2-compatible CSV: gaze, head pose and action-unit intensities.

Many tools and scripts read the CSV that OpenFace 2.2's ``FeatureExtraction`` writes (its
successor, 3.0, dropped the head pose and all but 8 AUs). :func:`write_openface_csv` turns a
``contractions.csv`` of ``myoface analyze`` into that format (``myoface analyze ... --format
openface`` writes it as ``openface.csv`` beside ``contractions.csv``). Only the columns that
myoface measures are written, in OpenFace's order (no 2-D/3-D eye or face landmarks, no shape
parameters, no ``AUxx_c`` occurrence columns)::

    frame,face_id,timestamp,confidence,success,gaze_0_x,gaze_0_y,gaze_0_z,gaze_1_x,gaze_1_y,
    gaze_1_z,gaze_angle_x,gaze_angle_y,pose_Tx,pose_Ty,pose_Tz,pose_Rx,pose_Ry,pose_Rz,
    AU01_r,AU02_r,AU04_r,AU05_r,AU06_r,AU07_r,AU09_r,AU10_r,AU12_r,AU14_r,AU15_r,AU17_r,
    AU20_r,AU23_r,AU25_r,AU26_r,AU45_r

Sources for the format (facts only): OpenFace's wiki page "Output Format" and its
``lib/local/Utilities/src/RecorderCSV.cpp`` (the header has no spaces; the gaze columns come
after ``success``, before the eye landmarks and the pose; the regression AUs are sorted by
name; numbers are written with 3 decimals for the timestamp, 2 for the confidence and the
AUs, 6 for the gaze vectors, 3 for the gaze angles, 1 for the translation and 3 for the pose
angles), ``RotationHelpers.h`` (Euler angles ``R = Rx * Ry * Rz``) and
``lib/local/GazeAnalyser/src/GazeEstimation.cpp`` (a gaze vector is the unit vector from the
eyeball's centre through the pupil, in the camera frame; ``GetGazeAngle``: the two vectors'
mean ``g``, ``gaze_angle_x = atan2(g_x, -g_z)``, ``gaze_angle_y = atan2(g_y, -g_z)``; eye 0
is the ``left_eye_28`` model's, the 68-point scheme's points 36-41).

Columns (see also the README):

- ``frame``: OpenFace counts frames from 1: myoface's frame 0 is frame 1.
- ``face_id``: always 0 (one face per video).
- ``timestamp``: the frame's time in the video, s.
- ``confidence``: 1.0 for a measured frame, 0.0 otherwise. It is *not* a probability: myoface
  has no calibrated confidence (the fit's residual is in ``contractions.csv``).
- ``success``: 1 when the frame was measured (``quality`` "ok"), 0 otherwise. As OpenFace does,
  an unmeasured frame has 0 in every other column.
- ``gaze_0_x, gaze_0_y, gaze_0_z``: the gaze of eye 0, the leftmost in the image of a face
  turned to the camera: the person's RIGHT eye (``gaze_r_*`` in ``contractions.csv``), as a
  unit vector in OpenFace's camera frame (x right, y down, z away from the camera; looking
  into the camera is about ``(0, 0, -1)``): the model's eyeball axis turned by the measured
  gaze (head frame) and the head's rotation. ``gaze_1_*``: eye 1, the person's LEFT eye. Six
  decimals. Empty cells where that eye was not read (closed lids, turned away: OpenFace reads
  an eye it cannot see; myoface says it does not), and where the CSV has no gaze or no 3-D
  pose (the snakes').
- ``gaze_angle_x, gaze_angle_y``: radians, of the mean of the eyes' vectors ``g`` (of the one
  read, when only one was): ``atan2(g_x, -g_z)`` (positive when the eyes turn to the image's
  right, the person's left) and ``atan2(g_y, -g_z)`` (positive when they turn down); both
  about 0 looking into the camera. Three decimals; empty when neither eye was read.
- ``pose_Tx, pose_Ty, pose_Tz``: the origin of myoface's head frame in OpenFace's camera frame
  (OpenCV's: x right, y down, z away from the camera; mm). myoface's head-frame origin is on the
  face's midline about 75 mm behind the nose tip (OpenFace's is its own model's centre), and the
  distance rests on the fit's assumed field of view and the face model's size (one video has
  no absolute scale), so compare movements, not absolute positions, between tools.
- ``pose_Rx, pose_Ry, pose_Rz``: the head's rotation in that camera frame, radians, as Euler
  angles with ``R = Rx Ry Rz``: pitch, yaw, roll (OpenFace's convention). A frontal face is
  0, 0, 0. Empty cells when the CSV has no 3-D pose (the snakes' 2-D head frame).
- ``AUxx_r``: intensities on OpenFace's 0-5 scale (0 absent, 1 trace ... 5 maximum; FACS's
  A-E are 1-5), from the fitted contractions through the project's AU table
  (``data/facs_action_units.toml``, :func:`au_intensities`); bilateral AUs are the mean of the
  two sides. ``AU07_r`` is empty (see :data:`UNMEASURED_AUS`), as is an AU whose principal
  muscles are not in the CSV (e.g. AU04 from the snakes, which do not estimate the
  corrugators).

After OpenFace's columns, myoface's expressions (:mod:`myoface.analysis.expressions`):
``expr_happiness, expr_sadness, expr_surprise, expr_fear, expr_anger, expr_disgust,
expr_neutral`` (strengths in [0, 1], 3 decimals) and ``expression`` (the label), as in
``contractions.csv``. OpenFace 2.2 writes no expression or emotion columns (its CSV has
landmarks, pose, gaze, shape parameters and AUs only), so there is no convention to follow;
they come last, so that a reader that takes OpenFace's columns by name or by position up to
``AU45_r`` reads the file as OpenFace's. Empty on a frame that was not measured
(``success`` 0).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from myoface._io import atomic_output, read_text
from myoface.analysis.au_intensity import (  # noqa: F401 (re-exported: the AUs' columns)
    OPENFACE_AUS,
    OPENFACE_SCALE,
    UNMEASURED_AUS,
    AUBasis,
    au_basis,
    au_intensities,
    fit_units,
)
from myoface.analysis.camera import POSE_COLUMNS
from myoface.analysis.contractions_csv import (
    CSV_OTHER_COLUMNS,
    read_contractions_csv,
    read_gaze,
    read_head_poses,
)
from myoface.analysis.expressions import EXPRESSION_COLUMNS, LABEL_COLUMN
from myoface.errors import MyofaceFormatError

#: OpenFace 2.2's gaze columns, in its order: eye 0's vector, eye 1's, the mean's angles
OPENFACE_GAZE_COLUMNS = (
    *(f"gaze_{e}_{a}" for e in (0, 1) for a in "xyz"),
    "gaze_angle_x",
    "gaze_angle_y",
)
#: myoface's eye (``contractions.csv``'s side) of OpenFace's eye 0 and eye 1: eye 0 is the
#: leftmost in the image of a face turned to the camera, the person's right
OPENFACE_EYES = ("r", "l")
#: the columns of the OpenFace CSV written by :func:`write_openface_csv`, in order
OPENFACE_COLUMNS = (
    "frame",
    "face_id",
    "timestamp",
    "confidence",
    "success",
    *OPENFACE_GAZE_COLUMNS,
    "pose_Tx",
    "pose_Ty",
    "pose_Tz",
    "pose_Rx",
    "pose_Ry",
    "pose_Rz",
    *(f"AU{n:02d}_r" for n in OPENFACE_AUS),
)
#: myoface's columns after OpenFace's (OpenFace 2.2 has no expression columns): the
#: expressions of :mod:`myoface.analysis.expressions`
MYOFACE_COLUMNS = (*EXPRESSION_COLUMNS, LABEL_COLUMN)
#: OpenFace's camera frame (x right, y down, z away from the camera) from myoface's (x right,
#: y up, z towards the viewer); also the head frame's axes when the face looks at the camera
_FLIP = np.diag([1.0, -1.0, -1.0])


def openface_pose(pose) -> tuple[float, float, float, float, float, float]:
    """(pose_Tx, pose_Ty, pose_Tz mm, pose_Rx, pose_Ry, pose_Rz rad) of a
    :class:`~myoface.analysis.camera.HeadPose` in OpenFace's convention: camera frame x right, y
    down, z away from the camera; ``R = Rx(pitch) Ry(yaw) Rz(roll)`` maps the head's own axes
    (OpenFace's: x to the image's right, y down, z away from the camera when it faces the
    camera) into the camera frame."""
    from scipy.spatial.transform import Rotation

    r = _FLIP @ np.asarray(pose.rotation, dtype=np.float64) @ _FLIP
    t = _FLIP @ np.asarray(pose.translation_mm, dtype=np.float64)
    rx, ry, rz = Rotation.from_matrix(r).as_euler("XYZ")  # intrinsic X-Y-Z: R = Rx Ry Rz
    return (float(t[0]), float(t[1]), float(t[2]), float(rx), float(ry), float(rz))


def openface_gaze(pose, angles_deg) -> list[float]:
    """OpenFace's gaze (:data:`OPENFACE_GAZE_COLUMNS`: eye 0's unit vector, eye 1's, then
    ``gaze_angle_x, gaze_angle_y`` rad) of a :class:`~myoface.analysis.camera.HeadPose` and the
    eyes' gaze ``angles_deg`` (4,) in :data:`~myoface.analysis.gaze.GAZE_COLUMNS`' order
    (``gaze_l_yaw_deg, gaze_l_pitch_deg, gaze_r_yaw_deg, gaze_r_pitch_deg``, head frame; NaN
    where an eye was not read, its vector then NaN). The angles are of the mean of the
    vectors read (NaN when none was)."""
    from myoface.analysis.gaze import gaze_directions

    a = np.asarray(angles_deg, dtype=np.float64).reshape(2, 2)
    side = {"l": a[0], "r": a[1]}
    rot = _FLIP @ np.asarray(pose.rotation, dtype=np.float64)
    vecs = []
    for eye in OPENFACE_EYES:
        yaw, pitch = side[eye]
        ok = np.isfinite(yaw) and np.isfinite(pitch)
        vecs.append(rot @ gaze_directions(yaw, pitch) if ok else np.full(3, np.nan))
    read = [v for v in vecs if np.isfinite(v).all()]
    if read:
        g = np.mean(read, axis=0)
        angles = [float(np.arctan2(g[0], -g[2])), float(np.arctan2(g[1], -g[2]))]
    else:
        angles = [float("nan")] * 2
    return [*(float(x) for v in vecs for x in v), *angles]


def _muscle_columns(header) -> list[str]:
    """The contraction columns of a contractions.csv header (muscles and the jaw)."""
    other = set(CSV_OTHER_COLUMNS) | set(POSE_COLUMNS) | {"residual_mm"}
    return [c for c in header if c and c not in other]


def read_for_openface(path):
    """(frames (T,) int, times (T,) s, quality (T,), contractions (T, M), muscle ids, poses or
    None, gaze angles (T, 4) deg or None) of a ``contractions.csv``."""
    import csv

    p = Path(path)
    text = read_text(p, "contractions CSV")
    rows = list(csv.reader(text.splitlines()))
    if not rows:
        raise MyofaceFormatError(f"{p}: no header and no rows")
    header = [c.strip() for c in rows[0]]
    if "frame" not in header:
        raise MyofaceFormatError(f"{p}: no 'frame' column (is it a contractions.csv?)")
    ids = _muscle_columns(header)
    times, table, quality = read_contractions_csv(p, ids)
    fcol = header.index("frame")
    try:
        frames = np.array([int(r[fcol]) for r in rows[1:] if any(c.strip() for c in r)])
    except (ValueError, IndexError):
        raise MyofaceFormatError(f"{p}: a 'frame' cell is not a whole number") from None
    poses = None

    if all(c in header for c in POSE_COLUMNS):
        poses = read_head_poses(p)
    gaze = read_gaze(p)
    return frames, times, list(quality), table, ids, poses, None if gaze is None else gaze[0]


def openface_rows(
    frames, times, quality, table, ids, poses=None, gaze=None, expressions=None
) -> list[list[str]]:
    """The OpenFace CSV's rows (cells as text, :data:`OPENFACE_COLUMNS` then
    :data:`MYOFACE_COLUMNS`) of an analysis; ``gaze``: the eyes' angles (T, 4) deg
    (:func:`~myoface.analysis.contractions_csv.read_gaze`) or None; ``expressions``:
    ``(scores (T, 7), labels)`` (:func:`~myoface.analysis.expressions.read_expressions`), or
    None: computed from ``table``."""
    from myoface.analysis.expressions import expression_labels, expression_scores

    aus = au_intensities(table, ids)
    if expressions is None:
        s = expression_scores(table, ids)
        expressions = (s, expression_labels(s))
    escores, elabels = expressions
    out = []
    for k, (f, t, q) in enumerate(zip(frames, times, quality, strict=True)):
        ok = q == "ok" and np.isfinite(table[k]).all()
        head = [str(int(f) + 1), "0", f"{t:.3f}"]
        if not ok:  # OpenFace's row for a frame it could not track: zeros, success 0
            zeros = [*(["0.000000"] * 6), *(["0.000"] * 2), *(["0.0"] * 3), *(["0.000"] * 3)]
            mine = [""] * len(MYOFACE_COLUMNS)  # (myoface's expressions: not measured)
            out.append([*head, "0.00", "0", *zeros, *(["0.00"] * 17), *mine])
            continue
        pose = poses[k] if poses is not None else None
        gcells = [""] * len(OPENFACE_GAZE_COLUMNS)
        if pose is None:
            pcells = [""] * 6
        else:
            v = openface_pose(pose)
            pcells = [f"{x:.1f}" for x in v[:3]] + [f"{x:.3f}" for x in v[3:]]
            if gaze is not None:
                g = openface_gaze(pose, gaze[k])
                gcells = [_cell(x, 6) for x in g[:6]] + [_cell(x, 3) for x in g[6:]]
        acells = ["" if not np.isfinite(a) else f"{a:.2f}" for a in aus[k]]
        ecells = [*(_cell(x, 3) for x in escores[k]), elabels[k]]
        out.append([*head, "1.00", "1", *gcells, *pcells, *acells, *ecells])
    return out


def _cell(x: float, digits: int) -> str:
    return "" if not np.isfinite(x) else f"{x:.{digits}f}"


def write_openface_csv(contractions_csv, path: str | os.PathLike) -> Path:
    """Write the OpenFace-2.2-compatible CSV (:data:`OPENFACE_COLUMNS`; see the module's
    docstring) of the analysis in ``contractions_csv`` to ``path`` (replaced whole); returns
    ``path``."""
    from myoface.analysis.expressions import read_expressions

    read = read_for_openface(contractions_csv)
    expr = read_expressions(contractions_csv, read[3], read[4])
    rows = openface_rows(*read, expressions=expr)
    lines = [",".join((*OPENFACE_COLUMNS, *MYOFACE_COLUMNS)), *(",".join(r) for r in rows)]
    with atomic_output(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    return Path(path)
