"""Files of the analysis loop: initial contours (JSON) and contractions (CSV)."""

import json

import numpy as np
import pytest

from myoface.analysis.contractions_csv import read_contractions_csv, write_contractions_csv
from myoface.analysis.initfiles import load_init, save_init
from myoface.analysis.sections import SECTIONS
from myoface.analysis.trackers.base import FrameMeasurement, Tracker
from myoface.errors import MyofaceFileNotFoundError, MyofaceFormatError


def test_every_section_is_a_contour_of_the_default_face(default_face):
    from myoface.analysis.sections import FEATURES, model_fiducials, section_vertices

    for sec in SECTIONS:
        v = section_vertices(default_face, sec)
        assert len(v) >= 3 and len(set(v.tolist())) == len(v), sec
    fids = model_fiducials(default_face)
    assert len(fids) == sum(len(f) for f in FEATURES.values())
    names = {f.name: f for f in fids}
    corner_l = default_face.landmark("mouth_corner_l")[0]
    assert names["lips:corner_l"].vertex == corner_l  # the rightmost lip point in the image


def test_init_roundtrip_and_errors(tmp_path):
    p = tmp_path / "init.json"
    conts = {"eyebrow_l": np.array([[10.0, 20], [20, 18], [30, 21]])}
    save_init(p, conts)
    back = load_init(p)
    np.testing.assert_allclose(back["eyebrow_l"], conts["eyebrow_l"])
    with pytest.raises(MyofaceFileNotFoundError):
        load_init(tmp_path / "none.json")
    for doc, match in [
        ("{", "not valid JSON"),
        (json.dumps({"contours": {"mouth": [[1, 2], [3, 4]]}}), "unknown section 'mouth'"),
        (json.dumps({"contours": {"chin": [[1, 2, 3]]}}), "at least 2"),
        (json.dumps({"contours": {"chin": [[1, 2], [None, 4]]}}), "NaN"),
        (json.dumps({"curves": {}}), "expected"),
    ]:
        p.write_text(doc)
        with pytest.raises(MyofaceFormatError, match=match):
            load_init(p)


def test_contractions_csv_roundtrip(tmp_path):
    import csv

    ids = ("zygomaticus_major_l", "jaw")
    frames = [
        FrameMeasurement(0, 0.0, "ok", np.array([0.0, 0.1]), np.zeros(2)),
        FrameMeasurement(1, 0.04, "escaped:chin", np.full(2, np.nan), np.array([1.0, -2.0])),
        FrameMeasurement(2, 0.08, "ok", np.array([0.5, 0.3]), np.zeros(2)),
    ]
    p = tmp_path / "c.csv"
    write_contractions_csv(p, ids, frames, jaw=0.3)
    with open(p, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert rows[1]["zygomaticus_major_l"] == "" and rows[1]["quality"] == "escaped:chin"
    assert float(rows[2]["jaw_angle_rad"]) == pytest.approx(0.09)
    t, table, q = read_contractions_csv(p, ["jaw", "zygomaticus_major_l", "risorius_l"])
    np.testing.assert_allclose(t, [0, 0.04, 0.08])
    assert table[2].tolist() == [0.3, 0.5, 0.0] and np.isnan(table[1, 0])
    assert q == ["ok", "escaped:chin", "ok"]


def test_contractions_csv_jaw_angle_follows_the_models_jaw(tmp_path):
    """The jaw_angle_rad column is the model's jaw angle at the measured control (the hinge,
    then the condyles' slide with more turn), not the control times the largest angle."""
    import csv

    import myoface as mf

    jaw = mf.build_face_model().muscles.jaw
    ids = ("jaw",)
    frames = [FrameMeasurement(k, 0.04 * k, "ok", np.array([c]), np.zeros(2))
              for k, c in enumerate((0.0, 0.3, 0.8, 1.0))]  # fmt: skip
    p = tmp_path / "c.csv"
    write_contractions_csv(p, ids, frames, jaw)
    with open(p, newline="") as fh:
        got = [float(r["jaw_angle_rad"]) for r in csv.DictReader(fh)]
    np.testing.assert_allclose(got, [jaw.angle_rad(c) for c in (0.0, 0.3, 0.8, 1.0)], atol=1e-5)
    assert got[-1] == pytest.approx(jaw.max_angle_rad, abs=1e-5)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("frame,jaw\n0,0.1\n", "missing column 'time_s'"),
        ("time_s,smile\n0,0.1\n", "no column names a muscle"),
        ("time_s,jaw\n0,nan\n", r"must be a number in \[0, 1\]"),
        ("time_s,jaw\n0,1.5\n", r"must be a number in \[0, 1\]"),
        ("time_s,jaw\n1,0.1\n0,0.1\n", "non-decreasing"),
        ("time_s,jaw\n", "no rows"),
    ],
)
def test_contractions_csv_errors(tmp_path, text, match):
    p = tmp_path / "bad.csv"
    p.write_text(text)
    with pytest.raises(MyofaceFormatError, match=match):
        read_contractions_csv(p, ["jaw"])


def test_low_contrast_frame_is_reported_not_measured():
    """A washed-out frame (a fade to grey) is recorded as low contrast with empty values."""
    from myoface.analysis.sections import project_sections
    from myoface.analysis.trackers.snakes import Analyzer, SnakeTracker
    from myoface.model import build_face_model
    from myoface.render import Camera, Renderer, to_srgb8
    from myoface.render.dressing import default_skin_texture

    fm = build_face_model()
    cam = Camera.front(fm.face.vertices, width=160, height=160, fov_deg=None)
    r = Renderer(fm.face, cam, texture=to_srgb8(default_skin_texture(fm.face, 256, makeup=True)))
    img = r.render(fm.skin_vertices()).astype(np.float64)
    faded = (0.15 * img + 0.85 * img.mean()).astype(np.uint8)
    before = _model_digest(fm)
    init = project_sections(fm, cam)
    assert isinstance(SnakeTracker(fm, init), Tracker)
    an = Analyzer(fm, init, head_frame="contours", head_reference=())
    q = [an.measure(f, k).quality for k, f in enumerate([img.astype(np.uint8), faded])]
    assert q[0] == "ok" and q[1] == "low_contrast", q
    m = an.measure(faded, 2)
    assert np.isnan(m.contractions).all()
    an.close()
    # the tracker owns its state: the caller's face model is as it was
    after = _model_digest(fm)
    assert len(before) > 20
    assert {k: after.get(k) for k in before} == before


def _model_digest(fm) -> dict:
    """A hash of each array the face model and its parts hold, by path (three levels deep).
    Lazily computed caches appear as new paths; a path present before must keep its hash."""
    import hashlib

    out = {}

    def walk(obj, path, depth):
        if isinstance(obj, np.ndarray):
            out[path] = hashlib.sha256(np.ascontiguousarray(obj).tobytes()).hexdigest()
        elif depth < 3 and hasattr(obj, "__dict__"):
            for k, v in vars(obj).items():
                walk(v, f"{path}.{k}", depth + 1)
        elif depth < 3 and isinstance(obj, list | tuple):
            for k, v in enumerate(obj):
                walk(v, f"{path}[{k}]", depth + 1)
        elif depth < 3 and isinstance(obj, dict):
            for k, v in obj.items():
                walk(v, f"{path}[{k!r}]", depth + 1)

    walk(fm, "model", 0)
    return out
