"""Property tests of every parser of user input: whatever bytes, text or values come in, only a
MyofaceError comes out (the project's rule for bad input: one clear error), never a bare ValueError, TypeError, UnicodeDecodeError, ...

Timelines, contractions CSVs, initial-contour JSON, landmark files, muscle files, AU keys,
intensities and the ``--au`` / ``--muscle`` requests of ``myoface synth``; image files (any
colour space), OBJ and geoface meshes (coordinates far beyond a head), head poses and
resynthesis performances, the command line's number types and :func:`user_message`.
"""

from __future__ import annotations

import csv
import io
import json
import re
from pathlib import Path

import numpy as np
import pytest

hypothesis = pytest.importorskip("hypothesis")
from hypothesis import HealthCheck, example, given, settings  # noqa: E402
from hypothesis import strategies as st  # noqa: E402

from myoface.errors import MyofaceError  # noqa: E402

SETTINGS = settings(
    max_examples=50,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)

#: a number of 5000 digits (Python's int() refuses more than 4300)
BIG = "1" * 5000

#: JSON-like values, with the awkward ones: NaN, infinities, huge integers, deep nesting
scalars = (
    st.none()
    | st.booleans()
    | st.integers()
    | st.integers(min_value=10**300, max_value=10**400)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=20)
)
values = st.recursive(
    scalars,
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=12,
)


def only_myoface_errors(fn, *args):
    """Call ``fn``; any exception other than a MyofaceError fails the test."""
    try:
        fn(*args)
    except MyofaceError:
        pass


@pytest.fixture(scope="module")
def scratch(tmp_path_factory) -> Path:
    """A folder for the examples' files (each example overwrites the last)."""
    return tmp_path_factory.mktemp("prop")


def _write(d: Path, data: bytes | str, suffix: str) -> Path:
    p = d / f"input{suffix}"
    if isinstance(data, str):
        p.write_text(data, encoding="utf-8")
    else:
        p.write_bytes(data)
    return p


def _json_text(v) -> str:
    return json.dumps(v, allow_nan=True)


# ------------------------------------------------------------------------------- timelines

EVENT_KEYS = ("kind", "name", "start", "duration", "intensity", "onset", "offset", "other")
event_like = st.dictionaries(
    st.sampled_from(EVENT_KEYS),
    scalars | st.sampled_from(["au", "expression", "viseme", "muscle", "12", "L12", "happiness"]),
    max_size=8,
)
timeline_like = st.fixed_dictionaries(
    {},
    optional={
        "events": st.lists(event_like, max_size=4) | values,
        "duration": scalars,
        "title": scalars,
    },
)


@SETTINGS
@given(data=st.binary(max_size=300), suffix=st.sampled_from([".toml", ".json"]))
def test_timeline_file_of_any_bytes(scratch, data, suffix):
    from myoface.control import load_timeline

    _check_timeline(_or_none(load_timeline, _write(scratch, data, suffix)))


def _or_none(fn, *args):
    """``fn(*args)``, or None when it raised a MyofaceError (any other exception fails)."""
    try:
        return fn(*args)
    except MyofaceError:
        return None


def _check_timeline(tl) -> None:
    """What an accepted timeline is: a finite duration > 0, and contractions in [0, 1] over
    the whole of it for the default face's muscles (an event it cannot drive on this face is
    refused with a MyofaceError, not a bare error)."""
    if tl is None:
        return
    from myoface.face import load_default_face
    from myoface.muscles.io import load_default_muscles

    assert np.isfinite(tl.duration) and tl.duration > 0
    ids = [m.id for m in load_default_muscles(load_default_face()).muscles] + ["jaw"]
    times = np.linspace(0.0, min(tl.duration, 1e6), 7)
    c = _or_none(tl.contractions, times, ids)
    if c is not None:
        assert c.shape == (7, len(ids)) and np.isfinite(c).all()
        assert (c >= 0).all() and (c <= 1).all()


#: timelines that are mostly valid (known kinds and names, times and intensities in range,
#: now and then a bad value), so that the properties of accepted ones are exercised
good_event = st.fixed_dictionaries(
    {
        "kind": st.sampled_from(["au", "au", "expression", "muscle", "blink", "bogus"]),
        "start": st.floats(0, 3) | st.sampled_from([-1.0, float("nan")]),
        "duration": st.floats(0.05, 2) | st.sampled_from([0.0, float("inf")]),
    },
    optional={"intensity": st.floats(0, 1) | st.sampled_from([1.5, -0.2, "C"])},
).flatmap(
    lambda e: st.sampled_from(
        {
            "au": ["12", "6", "L12", "26", "99"],
            "expression": ["happiness", "surprise", "nope"],
            "muscle": ["zygomaticus_major_l", "jaw", "nope"],
            "blink": ["both", "left"],
            "bogus": ["x"],
        }[e["kind"]]
    ).map(lambda n, e=e: {**e, "name": n})
)
good_timeline = st.fixed_dictionaries(
    {"events": st.lists(good_event, min_size=1, max_size=4)},
    optional={"duration": st.floats(0.1, 5)},
)


@SETTINGS
@given(doc=timeline_like | values | good_timeline)
def test_timeline_of_any_values(scratch, doc):
    from myoface.control import load_timeline
    from myoface.control.timeline import Timeline

    _check_timeline(_or_none(Timeline.from_dict, doc))
    _check_timeline(_or_none(load_timeline, _write(scratch, _json_text(doc), ".json")))


# ---------------------------------------------------------------------- contractions CSV

csv_free_text = st.lists(
    st.lists(
        st.sampled_from(
            ["time_s", "time", "quality", "jaw", "zygomaticus_major_l", "frame", "ok", "lost"]
        )
        | st.sampled_from(["", "0", "0.5", "1", "1.5", "-1", "nan", "inf", "1e400", '"a,b"'])
        | st.text(max_size=6),
        min_size=0,
        max_size=5,
    ).map(",".join),
    max_size=6,
).map("\n".join)


#: the columns a contractions CSV may have, and cells, good and bad
CSV_COLUMNS = ["frame", "time_s", "time", "quality", "jaw", "zygomaticus_major_l", "other"]
csv_cells = st.sampled_from(["", "0", "0.5", "1", "1.5", "-0.1", "nan", "inf", "ok", "no_face"]) | (
    st.floats(allow_nan=True, allow_infinity=True).map(repr)
)


@st.composite
def csv_text(draw):
    """CSV text shaped like a contractions CSV: a header of known and unknown columns, rows
    of cells that are mostly valid (times rising, contractions in [0, 1]) and sometimes not."""
    head = draw(st.lists(st.sampled_from(CSV_COLUMNS), min_size=1, max_size=6))
    if draw(st.booleans()):
        head = ["time_s", "quality", *[c for c in head if c not in ("time_s", "quality")]]
    rows = []
    t = 0.0
    for _ in range(draw(st.integers(0, 5))):
        t += draw(st.sampled_from([0.0, 0.04, 0.5]))
        row = []
        for c in head:
            if c in ("time_s", "time") and draw(st.integers(0, 9)):
                row.append(f"{t:g}")
            elif c == "quality" and draw(st.integers(0, 9)):
                row.append(draw(st.sampled_from(["ok", "no_face"])))
            elif draw(st.integers(0, 3)):
                row.append(f"{draw(st.floats(0, 1)):.3f}")
            else:
                row.append(draw(csv_cells))
        if draw(st.integers(0, 9)) == 0:
            row = row[: draw(st.integers(0, len(row)))] + draw(st.lists(csv_cells, max_size=2))
        rows.append(row)
    return "\n".join(",".join(r) for r in [head, *rows]) + "\n"


CSV_IDS = ["jaw", "zygomaticus_major_l", "depressor_labii_inferioris_l"]


@SETTINGS
@given(data=st.binary(max_size=300) | csv_free_text.map(str.encode) | csv_text().map(str.encode))
def test_contractions_csv_of_any_bytes(scratch, data):
    """Whatever the bytes, a MyofaceError or a table with the documented properties: finite,
    non-decreasing times, one row of every muscle asked for per time (a muscle without a
    column at rest, 0), one quality per row, and every measured ('ok') row finite in
    [0, 1]."""
    import warnings

    from myoface.analysis.contractions_csv import read_contractions_csv

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # unknown columns are a warning, not an error
        try:
            times, table, quality = read_contractions_csv(_write(scratch, data, ".csv"), CSV_IDS)
        except MyofaceError:
            return
    assert times.ndim == 1 and np.isfinite(times).all() and (np.diff(times) >= 0).all()
    assert table.shape == (len(times), len(CSV_IDS)) and len(quality) == len(times)
    ok = np.array([q == "ok" for q in quality], dtype=bool)
    assert np.isfinite(table[ok]).all() and (table[ok] >= 0).all() and (table[ok] <= 1).all()
    text = data.decode("utf-8-sig")  # (accepted: it was UTF-8 text)
    rows = [r for r in csv.reader(io.StringIO(text, newline="")) if any(c.strip() for c in r)]
    header = [c.strip() for c in rows[0]]
    for j, m in enumerate(CSV_IDS):
        if m not in header:
            assert (table[:, j] == 0).all()


# ----------------------------------------------------------------------- init contours JSON

SECTIONS = ["lips", "upper_lip", "chin", "brow_l", "nonsense"]


@SETTINGS
@given(
    data=st.binary(max_size=300)
    | values.map(_json_text).map(str.encode)
    | st.dictionaries(st.sampled_from(SECTIONS), values, max_size=3)
    .map(lambda c: {"contours": c})
    .map(_json_text)
    .map(str.encode)
)
def test_init_json_of_any_bytes(scratch, data):
    """Whatever the bytes, a MyofaceError or contours with the documented properties: known
    section names, each a finite (K, 2) array of K >= 2 points."""
    from myoface.analysis.initfiles import load_init
    from myoface.analysis.sections import SECTIONS as KNOWN

    try:
        got = load_init(_write(scratch, data, ".json"))
    except MyofaceError:
        return
    assert got and set(got) <= set(KNOWN)
    for a in got.values():
        assert a.dtype == np.float64 and a.ndim == 2 and a.shape[1] == 2 and len(a) >= 2
        assert np.isfinite(a).all()


# ------------------------------------------------------------------------- landmark files


@SETTINGS
@given(
    data=st.binary(max_size=400)
    | st.binary(max_size=200).map(lambda b: b"\x93NUMPY\x01\x00" + b)
    | values.map(_json_text).map(str.encode)
    | st.lists(st.lists(st.floats(), min_size=3, max_size=3), max_size=70)
    .map(lambda rows: "\n".join(" ".join(map(str, r)) for r in rows))
    .map(str.encode),
    suffix=st.sampled_from([".json", ".ljson", ".npy", ".txt", ".csv"]),
)
def test_landmark_file_of_any_bytes(scratch, data, suffix):
    """A MyofaceError, or 68 finite 3-D points (what every accepted landmark file gives)."""
    from myoface.face.personal import read_landmarks

    _check_landmarks(_or_none(read_landmarks, _write(scratch, data, suffix)))


def _check_landmarks(pts) -> None:
    if pts is not None:
        assert pts.shape == (68, 3) and pts.dtype == np.float64 and np.isfinite(pts).all()


@SETTINGS
@given(
    groups=st.dictionaries(
        st.text(max_size=6),
        st.fixed_dictionaries(
            {"landmarks": st.fixed_dictionaries({"points": values})},
            optional={"labels": values},
        )
        | values,
        max_size=2,
    )
)
def test_ljson_groups_of_any_values(scratch, groups):
    from myoface.face.personal import read_landmarks

    _check_landmarks(
        _or_none(read_landmarks, _write(scratch, _json_text({"groups": groups}), ".ljson"))
    )


# ----------------------------------------------------------------------------- muscle files


@pytest.fixture(scope="module")
def default_face_and_ids():
    from myoface.face import load_default_face
    from myoface.muscles.io import load_default_muscles

    face = load_default_face()
    ms = load_default_muscles(face)
    return face, [m.id for m in ms.muscles] + ["jaw"]


@st.composite
def muscle_files(draw) -> bytes:
    """Any bytes, or the default muscle file with lines dropped or repeated and numbers
    replaced by others (in range or not): mostly-valid files, so that accepted ones occur."""
    if draw(st.integers(0, 3)) == 0:
        return draw(st.binary(max_size=300))
    from importlib import resources

    text = (resources.files("myoface") / "data" / "default_muscles.toml").read_text()
    # its comment lines left out: they say nothing to the parser, and with them the file (16 kB
    # since 2026-12-02) made an example's repr pass hypothesis' 30 kB warning
    lines = [ln for ln in text.splitlines() if not ln.lstrip().startswith("#")]
    for _ in range(draw(st.integers(0, 3))):  # a few mutations, anywhere
        k = draw(st.integers(0, len(lines) - 1))
        what = draw(st.sampled_from(["drop", "repeat", "number"]))
        if what == "drop":
            del lines[k]
        elif what == "repeat":
            lines.insert(k, lines[k])
        elif "=" in lines[k]:
            key = lines[k].split("=", 1)[0]
            val = draw(st.sampled_from(["0", "-1", "1e9", "nan", "inf", "0.5", "[]", '"x"']))
            lines[k] = f"{key}= {val}"
    out = lines
    return "\n".join(out).encode()


@SETTINGS
@given(data=muscle_files())
def test_muscle_file_of_any_bytes(scratch, default_face_and_ids, data):
    """A MyofaceError, or a muscle set with the documented properties: unique ids, the jaw
    (when there is one) last, and every number in it finite."""
    from myoface.muscles.io import load_muscles

    face, _ = default_face_and_ids
    ms = _or_none(load_muscles, _write(scratch, data, ".toml"), face)
    if ms is None:
        return
    ids = list(ms.ids)
    assert len(set(ids)) == len(ids)
    assert "jaw" not in ids[:-1]
    for m in ms.muscles:
        for v in vars(m).values():
            if isinstance(v, float | np.ndarray) and np.asarray(v).dtype.kind == "f":
                assert np.isfinite(v).all(), (m.id, v)


# --------------------------------------------------------------------- AUs and intensities


@SETTINGS
@given(key=st.text(max_size=12) | st.integers() | scalars | values)
def test_parse_au_of_anything(key):
    from myoface.control.facs import parse_au

    only_myoface_errors(parse_au, key)


@SETTINGS
@given(value=st.text(max_size=12) | scalars | values)
def test_parse_intensity_of_anything(value):
    from myoface.control.facs import parse_intensity

    try:
        v = parse_intensity(value, "x")
    except MyofaceError:
        return
    assert 0.0 <= v <= 1.0


request = (
    st.sampled_from(["12", "L12", "AU6", "6R", "zygomaticus_major", "jaw", "risorius_l", ""])
    | st.text(max_size=10)
).flatmap(
    lambda k: (
        st.sampled_from(["0.5", "1", "C", "nan", "-0", "2", "", "1e999", "=="]).map(
            lambda v: f"{k}={v}"
        )
        | st.text(max_size=10).map(lambda v: f"{k}{v}")
    )
)


@SETTINGS
@given(aus=st.lists(request, max_size=4), muscles=st.lists(request, max_size=4))
def test_synth_requests_of_any_text(default_face_and_ids, aus, muscles):
    from myoface.commands.synth import _pairs
    from myoface.control import au_contractions, muscle_contractions

    _, ids = default_face_and_ids
    try:
        c = au_contractions(_pairs(aus, "au"), ids)
        assert ((c >= 0) & (c <= 1)).all()
        c = muscle_contractions(_pairs(muscles, "muscle"), ids)
        assert ((c >= 0) & (c <= 1)).all()
    except MyofaceError:
        pass


# ------------------------------------------------------------------- .myoface face files

TINY_OBJ = b"v 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nf 1 2 3\nf 1 3 4\n"
face_meta = st.fixed_dictionaries(
    {"format": st.just("myoface face")},
    optional={
        "version": scalars,
        "name": scalars,
        "landmarks": st.dictionaries(st.text(max_size=6), values, max_size=3) | values,
    },
)


@st.composite
def face_files(draw) -> bytes:
    """A zip holding face.json / mesh.obj / texture.png of any content, or any bytes."""
    import io
    import zipfile

    if draw(st.booleans()):
        return draw(st.binary(max_size=200))
    members = {
        "face.json": draw((face_meta | values).map(_json_text).map(str.encode)),
        "mesh.obj": draw(st.just(TINY_OBJ) | st.binary(max_size=100)),
    }
    if draw(st.booleans()):
        members["texture.png"] = draw(st.binary(max_size=100))
    if draw(st.booleans()):
        members["muscles.toml"] = draw(st.binary(max_size=50))
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w") as z:
        for name, data in members.items():
            if draw(st.booleans()):
                z.writestr(name, data)
    return buf.getvalue()


@SETTINGS
@given(data=face_files())
def test_face_file_of_any_content(scratch, data):
    """A MyofaceError, or a face whose mesh is finite with triangles indexing its vertices."""
    from myoface.face.facefile import read_face

    got = _or_none(read_face, _write(scratch, data, ".myoface"))
    if got is not None:
        face, muscles, meta = got
        assert np.isfinite(face.vertices).all() and len(face.vertices) >= 3
        tri = np.asarray(face.triangles)
        assert tri.min() >= 0 and tri.max() < len(face.vertices)
        assert muscles is None or isinstance(muscles, str)
        assert isinstance(meta, dict)


# --------------------------------------------------------------------------- image files


@st.composite
def image_files(draw) -> bytes:
    """Any bytes, or an image that Pillow writes, in one of its modes (CMYK, palette, grey,
    grey + alpha, 16-bit grey, 32-bit integer and float, ...), sometimes cut short."""
    if draw(st.integers(0, 3)) == 0:
        return draw(st.binary(max_size=300))
    from PIL import Image

    fmt, modes = draw(
        st.sampled_from(
            [
                ("PNG", ["RGB", "RGBA", "P", "L", "LA", "1", "I;16"]),
                ("JPEG", ["RGB", "L", "CMYK"]),
                ("TIFF", ["RGB", "CMYK", "LAB", "F", "I", "I;16", "YCbCr"]),
                ("BMP", ["RGB", "P", "L", "1"]),
                ("GIF", ["P", "L"]),
            ]
        )
    )
    mode = draw(st.sampled_from(modes))
    w, h = draw(st.integers(1, 12)), draw(st.integers(1, 12))
    rng = np.random.default_rng(draw(st.integers(0, 2**16)))
    im = Image.fromarray(rng.integers(0, 256, (h, w, 3), dtype=np.uint8)).convert(
        "L" if mode in ("I;16", "I", "F") else "RGB"
    )
    im = im.convert(mode) if mode != "I;16" else Image.fromarray(np.asarray(im).astype(np.uint16))
    buf = io.BytesIO()
    try:
        im.save(buf, format=fmt)
    except (OSError, ValueError, KeyError):  # a mode this format cannot hold
        buf = io.BytesIO()
        im.convert("RGB").save(buf, format="PNG")
    data = buf.getvalue()
    if draw(st.integers(0, 4)) == 0:
        data = data[: draw(st.integers(0, len(data)))]
    return data


@SETTINGS
@given(data=image_files(), suffix=st.sampled_from([".png", ".jpg", ".tif", ".bmp", ".gif"]))
def test_image_file_of_any_content(scratch, data, suffix):
    """A MyofaceError, or an (H, W, 3) uint8 RGB image: whatever the bytes, the colour space
    or the file's name (the one reader of images: photos, textures, a folder's frames)."""
    from myoface.face.image import read_image
    from myoface.render.renderer import load_texture

    path = _write(scratch, data, suffix)
    img = _or_none(read_image, path)
    from_bytes = _or_none(lambda: read_image(data, "image", name="bytes"))
    assert (from_bytes is None) == (img is None)  # the same reading from a file or bytes
    if img is not None:
        assert img.ndim == 3 and img.shape[2] == 3 and img.dtype == np.uint8 and img.size
        np.testing.assert_array_equal(from_bytes, img)
        small = read_image(path, max_side=4)
        assert small.dtype == np.uint8 and small.shape[2] == 3 and max(small.shape[:2]) <= 4
        tex = load_texture(img)
        assert tex.dtype == np.float32 and tex.shape == img.shape
        assert np.isfinite(tex).all() and (tex >= 0).all() and (tex <= 1).all()


# ---------------------------------------------------------------------------- mesh files

obj_numbers = st.sampled_from(
    ["0", "1", "-1", "1e308", "-1e308", "1e400", "nan", "inf", "2e6", "999999", "1e-300", "x"]
) | st.floats(allow_nan=True, allow_infinity=True).map(repr)
obj_index = st.sampled_from(["1", "2", "3", "4", "-1", "0", "99", "1/1", "2/2", "3/9", "1//1"])


@st.composite
def obj_text(draw) -> str:
    """OBJ text of vertices (numbers near and beyond the readers' bound, NaN, words), texture
    coordinates and faces (indices in and out of range, negative, with uv)."""
    lines = []
    for _ in range(draw(st.integers(0, 8))):
        kind = draw(st.sampled_from(["v", "v", "v", "vt", "f", "f", "#", ""]))
        if kind == "v":
            lines.append("v " + " ".join(draw(st.lists(obj_numbers, min_size=2, max_size=4))))
        elif kind == "vt":
            lines.append("vt " + " ".join(draw(st.lists(obj_numbers, min_size=1, max_size=3))))
        elif kind == "f":
            lines.append("f " + " ".join(draw(st.lists(obj_index, min_size=2, max_size=5))))
        else:
            lines.append(kind + draw(st.text(max_size=8)))
    return "\n".join(lines) + "\n"


@SETTINGS
@given(
    text=obj_text(),
    scale=st.sampled_from([1.0, 10.0, 1e6, 1e-6]),
    split=st.booleans(),
)
def test_obj_file_of_any_content(scratch, text, scale, split):
    """A MyofaceError, or a mesh whose every coordinate is finite and within the readers'
    bound, with triangles that index its vertices (and uv, when it has them, per vertex)."""
    from myoface.face import load_mesh
    from myoface.face.mesh import MAX_COORDINATE_MM

    mesh = _or_none(
        lambda: load_mesh(_write(scratch, text, ".obj"), scale_mm=scale, split_uv_seams=split)
    )
    if mesh is not None:
        v = mesh.vertices
        assert np.isfinite(v).all() and np.abs(v).max() <= MAX_COORDINATE_MM
        assert mesh.triangles.min() >= 0 and mesh.triangles.max() < len(v)
        assert mesh.uv is None or mesh.uv.shape == (len(v), 2)


@SETTINGS
@given(
    faceline=st.binary(max_size=100)
    | st.lists(obj_numbers, max_size=13).map(lambda xs: "3\n" + " ".join(xs)).map(str.encode),
    index=st.binary(max_size=60)
    | st.lists(obj_index, max_size=9).map(lambda xs: "2\n" + " ".join(xs)).map(str.encode),
)
def test_geoface_files_of_any_content(scratch, faceline, index):
    from myoface.face.io import read_waters_geoface
    from myoface.face.mesh import MAX_COORDINATE_MM

    folder = scratch / "geoface"
    folder.mkdir(exist_ok=True)
    (folder / "faceline.dat").write_bytes(faceline)
    (folder / "index.dat").write_bytes(index)
    mesh = _or_none(read_waters_geoface, folder)
    if mesh is not None:
        assert np.isfinite(mesh.vertices).all()
        assert np.abs(mesh.vertices).max() <= MAX_COORDINATE_MM


# ------------------------------------------------------------------ head poses, resynthesis

pose_cells = st.sampled_from(
    ["", "0", "12.5", "-179", "180", "181", "1e9", "-1e9", "nan", "inf", "430", "1e5", "x", BIG]
) | st.floats(allow_nan=True, allow_infinity=True).map(repr)


@SETTINGS
@given(
    rows=st.lists(st.lists(pose_cells, min_size=6, max_size=6), min_size=1, max_size=4),
    quality=st.lists(st.sampled_from(["ok", "no_face"]), min_size=4, max_size=4),
    dt=st.sampled_from([0.0, 1 / 30, 0.001, 60.0, 61.0]),
)
def test_head_poses_and_performances_of_any_values(scratch, rows, quality, dt):
    """A MyofaceError, or head poses that are rotations and translations within their bounds,
    and a performance whose video is 1/240 to 60 s a frame and at most an hour long."""
    import warnings
    from types import SimpleNamespace

    from myoface.analysis.camera import POSE_COLUMNS
    from myoface.analysis.contractions_csv import (
        MAX_POSE_TRANSLATION_MM,
        display_poses,
        read_head_poses,
    )
    from myoface.analysis.resynthesis import MAX_VIDEO_S, read_performance

    header = ["time_s", "quality", "jaw", *POSE_COLUMNS]
    lines = [",".join(header)]
    for k, r in enumerate(rows):
        jaw = "0.5" if quality[k] == "ok" else ""
        lines.append(",".join([f"{k * dt:g}", quality[k], jaw, *r]))
    path = _write(scratch, "\n".join(lines) + "\n", ".csv")
    poses = _or_none(read_head_poses, path)
    if poses is not None:
        assert len(poses) == len(rows)
        for rot, shift in display_poses(poses):
            assert np.allclose(rot @ rot.T, np.eye(3), atol=1e-6)
            assert np.isfinite(shift).all() and np.abs(shift).max() <= 2 * MAX_POSE_TRANSLATION_MM
    model = SimpleNamespace(ids=("zygomaticus_major_l", "jaw"))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a muscle without a column: a warning
        perf = _or_none(read_performance, path, model)
    if perf is not None:
        assert 0 < perf.fps <= 240 and perf.n_frames / perf.fps <= MAX_VIDEO_S + 1e-9
        assert np.isfinite(perf.contractions).all()


# ---------------------------------------------------------- option values, messages


@SETTINGS
@given(
    text=st.text(max_size=12)
    | st.sampled_from(["12=1.5", "12=nan", "X=3", "L12=C", "=", "12==0.5", f"12={BIG}", BIG])
)
@example(text="0\n0=")  # (a name with a newline was echoed as it was: two lines)
def test_option_values_of_any_text(text):
    """The command line's number and request types: a value in its limits, or argparse's
    usage error with a message of at most a line's length (never the 5000 digits)."""
    import argparse

    from myoface.commands._common import integer, number
    from myoface.commands.synth import _request

    for parse in (number(0.0, 1.0), integer(0, 10), integer(1), _request("au"), _request("muscle")):
        try:
            got = parse(text)
        except argparse.ArgumentTypeError as exc:
            assert len(str(exc)) < 300 and "\n" not in str(exc)
            continue
        if parse.__name__ == "number":
            assert 0.0 <= got <= 1.0
        elif parse.__name__ == "integer":
            assert isinstance(got, int) and got >= 0
        else:
            assert got == text


@SETTINGS
@given(text=st.text(max_size=200) | st.sampled_from([BIG, f"[Errno 1094995529] {BIG}"]))
@example(text="[Errno")  # (the user's own text, not an errno prefix)
def test_user_message_is_one_short_line(text):
    from myoface.errors import user_message

    exc = ValueError(text)
    try:
        int(text)
    except ValueError as e:  # Python's own message for a huge integer among them
        exc = e
    line = user_message(exc, limit=120)
    assert "\n" not in line and 0 < len(line) <= 120
    # (no errno prefix "[Errno N] "; a text that merely holds "[Errno" is the user's own)
    assert "set_int_max_str_digits" not in line and not re.search(r"\[Errno -?\d+\] ", line)
