"""The contractions CSV: one row per frame (muscles, jaw, head pose, quality), written whole
or streamed row by row, and read back for resynthesis."""

from __future__ import annotations

import csv
import os
from pathlib import Path

import numpy as np

from myoface._io import atomic_output, check_output_path, read_text
from myoface.analysis.camera import POSE_COLUMNS, HeadPose
from myoface.analysis.expressions import (
    EXPRESSION_COLUMNS,
    LABEL_COLUMN,
    ExpressionReader,
    expression_cells,
)
from myoface.analysis.gaze import GAZE_COLUMNS, GAZE_STATE_COLUMNS, GAZE_STATES
from myoface.analysis.trackers.base import FrameMeasurement
from myoface.errors import (
    MyofaceFileNotFoundError,
    MyofaceFormatError,
    MyofaceValueError,
    MyofaceWarning,
    writing,
)

#: the head columns of the snakes' (2-D head frame) rows in a contractions CSV
HEAD_2D_COLUMNS = FrameMeasurement.HEAD_COLUMNS


def contractions_csv_header(ids, first=None) -> list[str]:
    """The columns of a contractions CSV whose measurements are of the kind of ``first`` (see
    :func:`write_contractions_csv`): each kind names its head columns (``HEAD_COLUMNS``);
    without a measurement, the 2-D head frame's."""
    head = HEAD_2D_COLUMNS if first is None else first.HEAD_COLUMNS
    expr = [*EXPRESSION_COLUMNS, LABEL_COLUMN]  # (myoface.analysis.expressions)
    return ["frame", "time_s", "quality", *ids, "jaw_angle_rad", *head, *expr]


#: muscles of the default set added after contractions CSVs were first written (2026-12-05,
#: the mandible's sideways turn): a CSV without their columns holds them at rest, as the
#: analysis does by default (:attr:`~myoface.analysis.weights.FitSettings.jaw_sideways`),
#: without a warning
QUIETLY_AT_REST = ("lateral_pterygoid_l", "lateral_pterygoid_r")


def jaw_angle_function(jaw):
    """The jaw's rotation (rad) as a function of its control: ``jaw`` a
    :class:`~myoface.muscles.jaw.Jaw` (its :meth:`~myoface.muscles.jaw.Jaw.angle_rad`: the
    hinge, then the condyles' slide), or a number, the largest angle of a plain hinge
    (``c * jaw``), or None (no jaw: 0)."""
    if jaw is None:
        return lambda c: 0.0
    if hasattr(jaw, "angle_rad"):
        return jaw.angle_rad
    k = float(jaw)
    return lambda c: c * k


def contractions_csv_row(f, ids, jaw, expressions: ExpressionReader | None = None) -> str:
    """One measurement ``f`` as a line of a contractions CSV (no newline); ``jaw``: the
    model's jaw, or a function of the jaw control giving its angle (see
    :func:`jaw_angle_function`); ``expressions``: the video's
    :class:`~myoface.analysis.expressions.ExpressionReader`, given the rows in order (the
    expressions read above the person's rest reference, at the row's head pose), or None:
    the row's expressions read from its contractions alone."""
    angle = jaw if callable(jaw) else jaw_angle_function(jaw)
    vals = ["" if not np.isfinite(v) else f"{v:.5f}" for v in f.contractions]
    jaw_cell = ""
    if "jaw" in ids and np.isfinite(f.contractions[ids.index("jaw")]):
        jaw_cell = f"{angle(float(f.contractions[ids.index('jaw')])):.5f}"
    head = f.head_cells()
    ok = f.quality == "ok"
    pose = getattr(f, "pose", None)  # (the 3-D fit's; the snakes' rows have none)
    angles = None if pose is None else pose.angles_deg
    expr = expression_cells(f.contractions if ok else [np.nan], ids, expressions, angles)
    return ",".join([str(f.index), f"{f.time_s:.4f}", f.quality, *vals, jaw_cell, *head, *expr])


def write_contractions_csv(path, ids, frames: list[FrameMeasurement], jaw) -> None:
    """``frame,time_s,quality,<muscle ids...>,jaw_angle_rad,head_dx_px,head_dy_px,head_scale,
    head_rot_deg`` (empty cells where a frame could not be measured, and head cells where the
    face was not found). With the 3-D fit's measurements
    (:class:`~myoface.analysis.trackers.landmark_fit.FitMeasurement`) the head columns are the 3-D pose and the
    fit's residual: ``head_yaw_deg, head_pitch_deg, head_roll_deg, head_tx_mm, head_ty_mm,
    head_tz_mm, residual_mm`` (see :class:`~myoface.analysis.camera.HeadPose`), then each eye's
    gaze, ``gaze_l_yaw_deg, gaze_l_pitch_deg, gaze_r_yaw_deg, gaze_r_pitch_deg`` (degrees, head
    frame: yaw towards the subject's left, pitch up; empty where the eye was not read) and
    ``gaze_l_state, gaze_r_state`` (``ok``, ``closed``, ``hidden`` or ``not_found``; see
    :mod:`myoface.analysis.gaze`). Last, with every tracker, the expressions read from the
    contractions (:mod:`myoface.analysis.expressions`): ``expr_happiness, expr_sadness,
    expr_surprise, expr_fear, expr_anger, expr_disgust, expr_neutral`` (strengths in [0, 1])
    and ``expression`` (the label; empty where the frame was not measured), each row's read
    above the person's rest reference learnt from the rows before it
    (:class:`~myoface.analysis.expressions.ExpressionReader`). Written whole
    (atomically); :class:`ContractionsCsvWriter`
    writes the same rows one by one."""
    ids = list(ids)
    kinds = {type(f) for f in frames}
    if len(kinds) > 1:
        raise MyofaceValueError(
            f"one CSV holds one tracker's measurements; got {sorted(k.__name__ for k in kinds)}"
        )
    cols = contractions_csv_header(ids, frames[0] if frames else None)
    lines = [",".join(cols)]
    angle = jaw_angle_function(jaw)
    reader = ExpressionReader(ids)  # (one per video: the person's rest reference)
    lines += [contractions_csv_row(f, ids, angle, reader) for f in frames]
    with writing(path), atomic_output(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")


class ContractionsCsvWriter:
    """A contractions CSV (:func:`write_contractions_csv`'s columns) written row by row as the
    frames are measured, each row flushed to the file at once: whenever the run stops, the
    file holds the header and every row measured so far, each complete.

    The file appears under its final name with the header and the first row (written to a
    temporary name beside it, then renamed over any older file, so a reader never sees a
    half file); the following rows are appended to it. Before the first row there is no
    file (and an older one is left as it was).

    >>> with ContractionsCsvWriter("out/contractions.csv", ids, model.muscles.jaw) as w:  # doctest: +SKIP
    ...     for m in measurements:
    ...         w.write(m)

    Parameters
    ----------
    path : the CSV file; its folder must exist.
    ids : the measurements' contraction ids (``Analyzer.ids``).
    jaw : the model's :class:`~myoface.muscles.jaw.Jaw` (or a plain hinge's largest angle, rad),
        for the ``jaw_angle_rad`` column (see :func:`jaw_angle_function`).

    Attributes
    ----------
    n_rows : int -- rows written so far.
    expressions : the :class:`~myoface.analysis.expressions.ExpressionReader` of the rows
        (causal: each row's expression columns are final when it is written).
    """

    def __init__(self, path, ids, jaw):
        self.path = check_output_path(path)
        self.ids = list(ids)
        self.jaw_angle = jaw_angle_function(jaw)
        self.n_rows = 0
        self.expressions = ExpressionReader(self.ids)  # (the rows' rest reference)
        self._fh = None
        self._kind = None

    def write(self, m) -> None:
        """Append the row of measurement ``m`` and flush it to the file."""
        if self._fh is None:  # the first row says which head columns the file has
            self._kind = type(m)
        elif type(m) is not self._kind:
            raise MyofaceValueError(
                f"{self.path}: a {type(m).__name__} after {self._kind.__name__} rows"
            )
        row = contractions_csv_row(m, self.ids, self.jaw_angle, self.expressions)
        with writing(self.path):  # a full disk names the CSV
            if self._fh is None:
                head = ",".join(contractions_csv_header(self.ids, m))
                self._fh = self._publish(head + "\n" + row + "\n")
            else:
                self._fh.write(row + "\n")  # one write: a stop between rows, never inside one
                self._fh.flush()
        self.n_rows += 1

    def _publish(self, text: str):
        """The file opened for appending, holding ``text``, renamed to :attr:`path`."""
        import tempfile

        fd, tmp = tempfile.mkstemp(
            prefix=f".{self.path.stem}.", suffix=".part.csv", dir=self.path.parent
        )
        try:
            umask = os.umask(0)
            os.umask(umask)
            os.fchmod(fd, 0o666 & ~umask)  # mkstemp's 0600 -> the usual permissions
            fh = os.fdopen(fd, "a", encoding="utf-8", newline="")
        except BaseException:
            os.close(fd)
            os.unlink(tmp)
            raise
        try:
            fh.write(text)
            fh.flush()
            os.replace(tmp, self.path)
        except BaseException:
            fh.close()
            Path(tmp).unlink(missing_ok=True)
            raise
        return fh

    def close(self) -> None:
        """Close the file (it stays, with the rows written)."""
        if self._fh is not None:
            self._fh.close()
            self._fh = None

    def discard(self) -> None:
        """Close and remove the file (a run that measured nothing worth keeping)."""
        had = self._fh is not None
        self.close()
        if had:
            self.path.unlink(missing_ok=True)

    def __enter__(self) -> ContractionsCsvWriter:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


#: the columns of a contractions CSV that are not muscles (see :func:`write_contractions_csv`)
CSV_OTHER_COLUMNS = (
    "frame",
    "time_s",
    "time",
    "quality",
    "jaw_angle_rad",
    "head_dx_px",
    "head_dy_px",
    "head_scale",
    "head_rot_deg",
    # the 3-D fit's (myoface.analysis.trackers.landmark_fit.FitMeasurement.HEAD_COLUMNS)
    *POSE_COLUMNS,
    "residual_mm",
    # ... and its gaze (myoface.analysis.gaze)
    *GAZE_COLUMNS,
    *GAZE_STATE_COLUMNS,
    # ... and the expressions read from the contractions (myoface.analysis.expressions)
    *EXPRESSION_COLUMNS,
    LABEL_COLUMN,
)


def read_contractions_csv(
    path, muscle_ids, *, warn_missing: bool = False
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """(times (T,), contractions (T, M) over ``muscle_ids``, quality).

    A muscle of ``muscle_ids`` without a column stays at rest (0): the analysis estimates the
    paper's 12 muscles and the jaw, fewer than a face model has. Columns that are neither a
    muscle of ``muscle_ids`` nor one of :data:`CSV_OTHER_COLUMNS` are ignored with a
    :class:`~myoface.errors.MyofaceWarning` that lists them (e.g. a CSV of another face
    model's muscles); with ``warn_missing`` (a resynthesis, which drives every muscle), the
    one warning also names the muscles without a column.

    Raises a clear :class:`~myoface.errors.MyofaceFormatError` for a file that is not UTF-8
    CSV text, a missing time column, a header without any known muscle, a repeated column,
    a row longer than the header, and NaN or out-of-range values in measured ('ok') rows.
    """
    import csv
    import io
    import warnings

    p = Path(path)
    if not p.is_file():
        raise MyofaceFileNotFoundError(f"no such CSV file: {p}")
    text = read_text(p, "contractions CSV")
    try:
        rows = [r for r in csv.reader(io.StringIO(text, newline="")) if any(c.strip() for c in r)]
    except csv.Error as exc:
        raise MyofaceFormatError(f"{p}: not a CSV file: {exc}") from None
    if not rows:
        raise MyofaceFormatError(f"{p}: no header and no rows")
    head = [c.strip() for c in rows[0]]
    rows = rows[1:]
    if not rows:
        raise MyofaceFormatError(f"{p}: no rows")
    seen = set()
    for c in head:
        if c in seen:
            raise MyofaceFormatError(f"{p}: column {c[:40]!r} appears twice in the header")
        seen.add(c)
    col = {c: i for i, c in enumerate(head)}
    tcol = "time_s" if "time_s" in col else "time" if "time" in col else None
    if tcol is None:
        raise MyofaceFormatError(f"{p}: missing column 'time_s' (or 'time')")
    ids = list(muscle_ids)
    known = [m for m in ids if m in col]
    if not known:
        raise MyofaceFormatError(
            f"{p}: no column names a muscle of this face model (its muscles: "
            f"{', '.join(ids[:6])}{', ...' if len(ids) > 6 else ''})"
        )
    unknown = [c for c in head if c not in CSV_OTHER_COLUMNS and c not in ids]
    missing = [m for m in ids if m not in col and m not in QUIETLY_AT_REST]
    if unknown or (warn_missing and missing):
        said = []
        if unknown:
            said.append(
                f"{len(unknown)} column(s) name no muscle of this face model and are ignored: "
                f"{_listed(unknown)}"
            )
        if missing:
            rest = f"{len(missing)} of its {len(ids)} muscles have no column and stay at rest"
            said.append(f"{rest}: {_listed(missing)}" if warn_missing else rest)
        warnings.warn(f"{p.name}: {'; '.join(said)}", MyofaceWarning, stacklevel=2)
    times = np.empty(len(rows))
    table = np.zeros((len(rows), len(ids)))
    quality = []

    def cell(r, name):
        i = col.get(name)
        return r[i].strip() if i is not None and i < len(r) else ""

    for k, r in enumerate(rows):
        if len(r) > len(head):
            raise MyofaceFormatError(
                f"{p}: row {k + 2} has {len(r)} cells; the header has {len(head)}"
            )
        try:
            times[k] = float(cell(r, tcol))
        except ValueError:
            raise MyofaceFormatError(f"{p}: row {k + 2}: bad time {cell(r, tcol)[:40]!r}") from None
        q = cell(r, "quality") or "ok"
        quality.append(q)
        for m in known:
            c = cell(r, m)
            if c == "" and q != "ok":
                table[k, ids.index(m)] = np.nan
                continue
            try:
                v = float(c)
            except ValueError:
                raise MyofaceFormatError(
                    f"{p}: row {k + 2}: bad value {c[:40]!r} for {m}"
                ) from None
            if not np.isfinite(v) or not 0 <= v <= 1:
                raise MyofaceFormatError(
                    f"{p}: row {k + 2}: {m} must be a number in [0, 1]; got {c[:40]!r}"
                )
            table[k, ids.index(m)] = v
    if not np.isfinite(times).all() or np.any(np.diff(times) < 0):
        raise MyofaceFormatError(f"{p}: times must be finite and non-decreasing")
    return times, table, quality


def _listed(names, n: int = 8) -> str:
    """Up to ``n`` of ``names``, quoted (each at most 40 characters), and "..." for more."""
    shown = ", ".join(repr(c[:40]) for c in names[:n])
    return shown + (f", ... ({len(names)} in all)" if len(names) > n else "")


def hold_last_measured(table: np.ndarray) -> np.ndarray:
    """Fill the unmeasured rows (NaN) of a contraction table with the last measured row (zeros
    before the first), so a model can be driven through them; returns a new array."""
    out = np.array(table, dtype=np.float64)
    last = np.zeros(out.shape[1])
    for k in range(len(out)):
        if np.isnan(out[k]).any():
            out[k] = last
        else:
            last = out[k]
    return out


#: the largest head angle (degrees) a contractions CSV's pose may give: a turn of the head is
#: within a half turn of the camera (a yaw of 1e9 degrees is no pose)
MAX_POSE_ANGLE_DEG = 180.0
#: the largest head translation (mm) a contractions CSV's pose may give: a face 10 m from the
#: camera is a few pixels wide
MAX_POSE_TRANSLATION_MM = 10_000.0


def read_head_poses(path) -> list:
    """The head poses of a contractions CSV written with the 3-D fit (its
    :data:`POSE_COLUMNS`): one :class:`HeadPose` per row, None where the row has none (no face
    found). Angles must be within :data:`MAX_POSE_ANGLE_DEG` degrees and translations within
    :data:`MAX_POSE_TRANSLATION_MM` mm (else a :class:`MyofaceFormatError` saying the bound)."""
    p = Path(path)
    rows = list(csv.DictReader(read_text(p, "contractions CSV").splitlines()))
    missing = [c for c in POSE_COLUMNS if not rows or c not in rows[0]]
    if missing:
        raise MyofaceFormatError(
            f"{p}: no head pose columns ({', '.join(missing)}); they are written by "
            "myoface analyze --tracker landmarks (the 3-D fit)"
        )
    out = []
    for k, r in enumerate(rows):
        cells = [(r.get(c) or "").strip() for c in POSE_COLUMNS]
        if not all(cells):
            out.append(None)
            continue
        try:
            vals = {c: float(v) for c, v in zip(POSE_COLUMNS, cells, strict=True)}
        except ValueError:
            raise MyofaceFormatError(
                f"{p}: row {k + 2}: a head pose cell is not a number"
            ) from None
        if not all(np.isfinite(v) for v in vals.values()):
            raise MyofaceFormatError(f"{p}: row {k + 2}: a head pose cell is not finite")
        for c, v in vals.items():
            bound, unit = (
                (MAX_POSE_ANGLE_DEG, "degrees")
                if c.endswith("_deg")
                else (MAX_POSE_TRANSLATION_MM, "mm")
            )
            if abs(v) > bound:
                raise MyofaceFormatError(
                    f"{p}: row {k + 2}: {c} is {v:.4g}; a head pose's {unit} are within +-{bound:g}"
                )
        out.append(HeadPose.from_columns(vals))
    return out


#: the largest gaze angle (degrees) a contractions CSV may give: an eye looks forward of its
#: head (the reader's own range is +-45, :data:`myoface.analysis.gaze.MAX_GAZE_DEG`)
MAX_GAZE_ANGLE_DEG = 90.0


def read_gaze(path) -> tuple[np.ndarray, list[tuple[str, str]]] | None:
    """The eyes' gaze of a contractions CSV written with the 3-D fit: ``(angles (T, 4)
    degrees in :data:`~myoface.analysis.gaze.GAZE_COLUMNS`' order, NaN where an eye was not
    read, states (T,) of ``(left, right)``)``; None when the CSV has no gaze columns (older
    CSVs, the snakes'). A state is "ok" where both angles are given, else as written (empty:
    the frame was not measured). An angle beyond :data:`MAX_GAZE_ANGLE_DEG`, not a number,
    or missing beside an "ok" state is a :class:`MyofaceFormatError`."""
    p = Path(path)
    rows = list(csv.DictReader(read_text(p, "contractions CSV").splitlines()))
    if not rows or not all(c in rows[0] for c in GAZE_COLUMNS):
        return None
    angles = np.full((len(rows), len(GAZE_COLUMNS)), np.nan)
    states = []
    for k, r in enumerate(rows):
        cells = [(r.get(c) or "").strip() for c in GAZE_COLUMNS]
        st = [(r.get(c) or "").strip() for c in GAZE_STATE_COLUMNS]
        for j, c in enumerate(cells):
            if c == "":
                continue
            try:
                v = float(c)
            except ValueError:
                raise MyofaceFormatError(
                    f"{p}: row {k + 2}: {GAZE_COLUMNS[j]} is not a number: {c[:40]!r}"
                ) from None
            if not (np.isfinite(v) and abs(v) <= MAX_GAZE_ANGLE_DEG):
                raise MyofaceFormatError(
                    f"{p}: row {k + 2}: {GAZE_COLUMNS[j]} must be within "
                    f"+-{MAX_GAZE_ANGLE_DEG:g} degrees; got {c[:40]!r}"
                )
            angles[k, j] = v
        for e, side in enumerate(("l", "r")):
            both = np.isfinite(angles[k, 2 * e : 2 * e + 2])
            if st[e] == "ok" and not both.all():
                raise MyofaceFormatError(
                    f"{p}: row {k + 2}: gaze_{side}_state is ok without angles"
                )
            if st[e] not in ("", *GAZE_STATES):
                raise MyofaceFormatError(
                    f"{p}: row {k + 2}: gaze_{side}_state must be one of {GAZE_STATES}; "
                    f"got {st[e][:40]!r}"
                )
            if not both.all():
                angles[k, 2 * e : 2 * e + 2] = np.nan
            elif not st[e]:
                st[e] = "ok"
        states.append((st[0], st[1]))
    return angles, states


def display_gaze(angles) -> np.ndarray:
    """The eyes' common gaze (T, 2) rad, ``(yaw, pitch)`` for the renderer (which turns both
    eyes alike) from :func:`read_gaze`'s angles (T, 4) degrees: the mean of the eyes read in
    each row; a row with neither (closed lids, no face) holds the last (straight ahead before
    the first); within the renderer's range (+-45 degrees)."""
    a = np.asarray(angles, dtype=np.float64).reshape(-1, 2, 2)
    out = np.zeros((len(a), 2))
    last = np.zeros(2)
    lim = np.radians(45.0)
    for k, row in enumerate(a):
        read = row[np.isfinite(row).all(axis=1)]
        if len(read):
            last = np.clip(np.radians(read.mean(axis=0)), -lim, lim)
        out[k] = last
    return out


def display_poses(poses) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(rotation, translation mm)`` per row of ``poses`` (:func:`read_head_poses`) for
    :meth:`~myoface.render.Renderer.render`: the head's orientation as the camera saw it, and
    its translation from its median position (so that a renderer framing the face at rest
    keeps it in view while it moves as in the video); rows without a pose hold the last one."""
    known = [p for p in poses if p is not None]
    ref = np.median([p.translation_mm for p in known], axis=0) if known else np.zeros(3)
    out, last = [], (np.eye(3), np.zeros(3))
    for p in poses:
        if p is not None:
            last = (p.rotation, p.translation_mm - ref)
        out.append(last)
    return out
