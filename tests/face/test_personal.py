"""Personal faces: conformation of the generic face to a scan, face files, muscles per side."""

from __future__ import annotations

import json

import numpy as np
import pytest
import trimesh

from myoface.cli import main
from myoface.errors import MyofaceValueError
from myoface.face import FaceMesh, default_mirror_map, load_default_face
from myoface.face.facefile import read_face, save_face
from myoface.face.mesh import point_mesh_distance
from myoface.face.personal import (
    INNER_IBUG,
    align_to_generic,
    face_from_scan,
    fit_similarity_3d,
    ibug_points_of,
    read_landmarks,
)
from myoface.model import build_face_model, load_face_model
from myoface.muscles import load_default_muscles
from tests.conftest import needs_mediapipe, shared_path


def closed(face: FaceMesh) -> FaceMesh:
    """The face with its eye and mouth openings closed by fans and a 25 mm band around its rim
    (a scan covers more than the face and has no holes in the eyes)."""
    v, t = [face.vertices], [face.triangles]
    n = face.n_vertices
    for loop in face.boundary_loops[1:]:
        v.append(face.vertices[loop].mean(0, keepdims=True))
        t.append(np.column_stack([loop, np.roll(loop, -1), np.full(len(loop), n)]))
        n += 1
    rim = face.boundary_loops[0]
    p = face.vertices[rim]
    out = p[:, :2] - p[:, :2].mean(0)
    out /= np.linalg.norm(out, axis=1, keepdims=True)
    ring = np.column_stack([p[:, :2] + 25 * out, p[:, 2] - 15])
    v.append(ring)
    k = np.arange(len(rim))
    a, b = rim, np.roll(rim, -1)
    c, d = n + k, n + np.roll(k, -1)
    t += [np.column_stack([a, b, d]), np.column_stack([a, d, c])]
    return FaceMesh(np.concatenate(v), np.concatenate(t), name="closed")


def warp(x: np.ndarray) -> np.ndarray:
    """A smooth, person-like change of shape: a wider jaw, a longer nose, a higher forehead."""
    y = x.copy()
    low = np.clip(-x[:, 1] / 90, 0, 1)
    y[:, 0] *= 1 + 0.12 * low
    nose = np.exp(-((x[:, 0] / 15) ** 2 + ((x[:, 1] + 5) / 25) ** 2))
    y[:, 2] += 6 * nose
    y[:, 1] += 0.08 * np.clip(x[:, 1], 0, None)
    return y


def pose(x: np.ndarray, yaw_deg=12.0, t=(5.0, -20.0, 40.0), s=1.07) -> np.ndarray:
    a = np.radians(yaw_deg)
    r = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    return s * x @ r.T + np.asarray(t)


@pytest.fixture(scope="module")
def synthetic_scan(default_face):
    """A scan of a known person: the closed generic face, warped and posed; its landmarks."""
    base = closed(default_face)
    person = base.with_vertices(pose(warp(base.vertices)))
    lm = ibug_points_of(person.vertices[: default_face.n_vertices])
    return person, lm


def test_similarity_fit_recovers_a_known_transform():
    rng = np.random.default_rng(0)
    src = rng.normal(size=(30, 3))
    a = 0.4
    r = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    s, r_fit, t = fit_similarity_3d(src, 2.5 * src @ r.T + [1, 2, 3])
    assert s == pytest.approx(2.5) and np.allclose(r_fit, r) and np.allclose(t, [1, 2, 3])


def test_conformation_reproduces_the_scanned_surface(synthetic_scan, default_face):
    scan, lm = synthetic_scan
    conf = face_from_scan(scan, lm)
    head = conf.scan
    d = point_mesh_distance(conf.face.vertices, head.vertices, head.triangles)
    # the nodes sample the range map (0.7 deg x 1.3 mm cells here) bilinearly: on this smooth
    # surface that puts them within a few tenths of a millimetre of it
    assert d.mean() < 0.1 and d.max() < 1.0
    err = conf.landmark_error_mm[INNER_IBUG]
    assert err.mean() < 0.5 and np.median(err) < 0.3
    # except where the surface folds back on itself, which one radius per ray cannot hold:
    # the inner mouth corners sit in a pocket behind the lips (the outermost hit is the lip)
    folds = [60, 64]
    assert np.delete(err, np.searchsorted(INNER_IBUG, folds)).max() < 1.0
    # the person's own shape, not the generic one: the result is the warped face in its pose
    truth = pose(warp(default_face.vertices))
    s, r, t = fit_similarity_3d(conf.face.vertices, truth)
    res = np.linalg.norm(s * conf.face.vertices @ r.T + t - truth, axis=1)
    assert np.median(res) < 0.7
    assert conf.face.uv is not None and conf.face.texture is not None


def test_held_out_landmarks_land_closer_than_the_generic_face(synthetic_scan, default_face):
    scan, lm = synthetic_scan
    use = INNER_IBUG[::2]
    held = np.setdiff1d(INNER_IBUG, use)
    from myoface.face.personal import conform_to_maps, head_maps

    head, maps, al = head_maps(scan, lm, default_face)
    lm_head = al.to_head(lm)
    conf = conform_to_maps(maps, lm_head, default_face, use=use)
    after = conf.landmark_error_mm[held]
    generic = al.scale * default_face.vertices  # the generic face after the similarity alone
    before = np.linalg.norm(ibug_points_of(generic) - lm_head, axis=1)[held]
    assert np.median(after) < 0.5 * np.median(before)
    assert np.median(after) < 1.5


def test_landmarks_that_are_not_a_face_are_refused(default_face):
    rng = np.random.default_rng(1)
    with pytest.raises(MyofaceValueError, match="do not fit a face"):
        align_to_generic(rng.normal(scale=50, size=(68, 3)), default_face)


def test_a_cube_is_not_a_head(synthetic_scan):
    _, lm = synthetic_scan
    box = trimesh.creation.box(extents=(300, 300, 300))
    cube = FaceMesh(np.asarray(box.vertices) + lm[INNER_IBUG].mean(0), np.asarray(box.faces))
    with pytest.raises(MyofaceValueError, match="not on this mesh"):
        face_from_scan(cube, lm)


def test_maps_with_a_hole_under_the_face_are_refused(synthetic_scan, default_face):
    scan, lm = synthetic_scan
    from myoface.face.personal import conform_to_maps, head_maps

    _, maps, al = head_maps(scan, lm, default_face)
    r = maps.radius_mm.copy()
    h, w = r.shape
    r[h // 3 : h // 2, w // 2 - 20 : w // 2 + 20] = np.nan  # a hole across the nose and eyes
    maps.radius_mm = r
    with pytest.raises(MyofaceValueError, match="holes under the face"):
        conform_to_maps(maps, al.to_head(lm), default_face)


def test_right_muscles_follow_the_right_side_of_an_asymmetric_face(default_face):
    v = default_face.vertices.copy()
    right = v[:, 0] < -1.0
    v[right, 1] += 4.0  # the subject's right side sits 4 mm higher
    face = default_face.with_vertices(v)
    ms = load_default_muscles(face)
    sym = load_default_muscles(default_face)
    zr, zl = ms["zygomaticus_major_r"], ms["zygomaticus_major_l"]
    assert zr.insertion[1] - sym["zygomaticus_major_r"].insertion[1] == pytest.approx(4.0, abs=0.3)
    assert zl.insertion[1] == pytest.approx(sym["zygomaticus_major_l"].insertion[1], abs=0.3)
    mirror = default_mirror_map()
    assert np.array_equal(mirror[mirror], np.arange(len(mirror)))


def test_face_file_round_trip(tmp_path, default_face):
    rng = np.random.default_rng(2)
    tex = rng.integers(0, 255, size=(32, 48, 3), dtype=np.uint8)
    face = FaceMesh(
        default_face.vertices * 1.05,
        default_face.triangles,
        default_face.uv,
        tex,
        default_face.landmarks,
        name="someone",
    )
    path = save_face(tmp_path / "p.myoface", face, provenance={"note": "test"})
    back, muscles, meta = read_face(path)
    assert np.allclose(back.vertices, face.vertices, atol=1e-5)
    assert np.array_equal(back.texture, tex) and np.allclose(back.uv, face.uv, atol=1e-6)
    assert back.landmarks.keys() == face.landmarks.keys()
    assert muscles is None and meta["provenance"] == {"note": "test"} and back.name == "someone"
    fm = load_face_model(path)  # default topology: the default muscles
    assert fm.n_muscles == build_face_model().n_muscles
    res = fm.relax({"zygomaticus_major_l": 1.0})
    assert res.converged


def test_bad_face_files(tmp_path):
    from myoface.errors import MyofaceFormatError

    junk = tmp_path / "junk.myoface"
    junk.write_text("not a zip")
    with pytest.raises(MyofaceFormatError, match="not a zip"):
        load_face_model(junk)


# --------------------------------------------------------------------------- the real scan


@pytest.mark.shared_data
def test_landmark_file_is_read_in_ibug_order():
    lm = read_landmarks(shared_path("scan", "james.ljson"))
    # iBUG order: 36-41 is the eye on the image left (scan -x), 42-47 the other; 30 the nose tip
    assert lm[36:42, 0].mean() < lm[30, 0] < lm[42:48, 0].mean()
    assert lm[17:27, 1].min() > lm[36:48, 1].max() > lm[30, 1] > lm[48:68, 1].max()


@pytest.mark.shared_data
def test_cli_from_scan_on_the_real_scan(tmp_path, capsys):
    obj = shared_path("scan", "james.obj")
    out = tmp_path / "james.myoface"
    rc = main(
        [
            "face",
            "from-scan",
            str(obj),
            "--landmarks",
            str(shared_path("scan", "james.ljson")),
            "-o",
            str(out),
            "--preview",
            str(tmp_path / "p.png"),
        ]
    )
    assert rc == 0 and out.is_file() and (tmp_path / "p.png").is_file()
    _, _, meta = read_face(out)
    fit = meta["provenance"]["fit"]
    # the nodes sample the scan's range map: they lie on the scan (its cells are ~1.3 mm)
    assert fit["mesh_to_scan_mean_mm"] < 0.2 and fit["mesh_to_scan_max_mm"] < 2.0
    # the 852-triangle mesh is flat between nodes ~8 mm apart: the scan's fine relief (nostrils,
    # lips, eyelids) is within a few mm of it
    assert fit["scan_to_mesh_mean_mm"] < 2.5
    assert fit["landmark_error_mean_mm"] < 1.0
    fm = load_face_model(out)
    assert fm.face.texture is not None and fm.face.name == "james"
    assert main(["synth", "--face", str(out), "--au", "12=0.8", "-o", str(tmp_path / "s.png")]) == 0


@pytest.mark.shared_data
def test_cli_from_scan_refuses_a_cube_without_writing(tmp_path, capsys):
    box = trimesh.creation.box(extents=(200, 200, 200))
    cube = tmp_path / "cube.obj"
    box.export(cube)
    out = tmp_path / "cube.myoface"
    rc = main(
        [
            "face",
            "from-scan",
            str(cube),
            "--landmarks",
            str(shared_path("scan", "james.ljson")),
            "-o",
            str(out),
        ]
    )
    assert rc == 1 and not out.exists()
    assert "not on this mesh" in capsys.readouterr().err


@needs_mediapipe
@pytest.mark.shared_data
def test_cli_from_photo_and_a_photo_without_a_face(tmp_path, capsys):
    video = shared_path("video", "single_face.mp4")
    out = tmp_path / "p.myoface"
    assert main(["face", "from-photo", str(video), "--frame", "0", "-o", str(out)]) == 0
    fm = load_face_model(out)
    assert fm.face.texture is not None
    # the face keeps the default topology and the generic face's size
    width = np.ptp(fm.face.vertices[:, 0])
    assert 0.8 < width / np.ptp(load_default_face().vertices[:, 0]) < 1.2
    # the rest gap of the lips is reported (issue 34): the sample's closed mouth
    said = [ln for ln in capsys.readouterr().out.splitlines() if ln.startswith("lips")]
    assert len(said) == 1 and "(closed" in said[0], said
    bad = tmp_path / "none.myoface"
    rc = main(["face", "from-photo", str(shared_path("video", "no_face.mp4")), "-o", str(bad)])
    assert rc == 1 and not bad.exists()
    assert "no face found in the photo" in capsys.readouterr().err


def test_lips_a_little_apart_are_closed_and_an_open_mouth_is_left(default_face):
    """close_lips: inner lip contours 1 mm apart meet at their midpoints (texture
    coordinates too; the corners and every other vertex unchanged); 5 mm further apart (an
    open mouth: the default face's lower lip lowered; the face itself rests with its lips
    closed) they are left as they are."""
    from myoface.face.personal import close_lips

    lm = default_face.landmarks
    up, lo = np.asarray(lm["lip_upper_inner"]), np.asarray(lm["lip_lower_inner"])
    up, lo = up[up != lo], lo[up != lo]  # (the corners are shared)
    v = default_face.vertices.astype(np.float64)
    uv = np.asarray(default_face.uv, dtype=np.float64)
    open_mouth = v.copy()
    open_mouth[lo, 1] -= 5.0
    _, _, gap, closed = close_lips(open_mouth, uv, lm, 2.0)
    assert gap > 4.0 and not closed
    apart = v.copy()
    mid = 0.5 * (v[up] + v[lo])
    apart[up], apart[lo] = mid + [0, 0.5, 0], mid - [0, 0.5, 0]
    out, out_uv, gap, closed = close_lips(apart, uv, lm, 2.0)
    assert closed and gap == pytest.approx(1.0)
    np.testing.assert_allclose(out[up], out[lo])
    np.testing.assert_allclose(out[up], mid, atol=1e-12)
    np.testing.assert_allclose(out_uv[up], out_uv[lo])
    others = np.setdiff1d(np.arange(len(v)), np.r_[up, lo])  # the corners among them
    np.testing.assert_array_equal(out[others], apart[others])
    np.testing.assert_array_equal(out_uv[others], uv[others])
    assert not np.shares_memory(out, apart) and (apart[up] != out[up]).any()


@needs_mediapipe
@pytest.mark.shared_data
def test_the_sample_videos_closed_lips_stay_closed():
    """The sample video's first frame (lips closed at rest): MediaPipe finds the inner lip
    contours ~1 mm apart; the face made from it has them meeting, and renders no mouth
    opening between them."""
    from myoface.analysis.video import open_video
    from myoface.face.personal import CLOSED_LIPS_MM, face_from_photo

    frame = next(iter(open_video(shared_path("video", "single_face.mp4"))))
    face, info = face_from_photo(frame)
    assert 0.0 < info["lip_gap_mm"] < CLOSED_LIPS_MM and info["lips_closed"]
    lm = face.landmarks
    np.testing.assert_allclose(
        face.vertices[lm["lip_upper_inner"]], face.vertices[lm["lip_lower_inner"]]
    )


@needs_mediapipe
@pytest.mark.shared_data
def test_landmarks_found_on_the_scan_agree_with_the_annotation():
    import imageio.v3 as iio

    from myoface.face import load_mesh
    from myoface.face.personal import find_landmarks

    scan = load_mesh(shared_path("scan", "james.obj"), split_uv_seams=True)
    scan.texture = iio.imread(shared_path("scan", "james.jpg"))
    found = find_landmarks(scan)
    given = read_landmarks(shared_path("scan", "james.ljson"))
    d = np.linalg.norm(found - given, axis=1)
    # MediaPipe's vertices and the iBUG annotation define brows and lips slightly differently
    # (the table maps them to the nearest vertex): eyes and nose agree within a few mm
    assert np.median(d[27:48]) < 6.0
    assert np.median(d[INNER_IBUG]) < 8.0


def test_face_json_is_documented_json(tmp_path, default_face):
    path = save_face(tmp_path / "d.myoface", default_face, muscles_toml="# none\n")
    import zipfile

    with zipfile.ZipFile(path) as z:
        meta = json.loads(z.read("face.json"))
        assert set(z.namelist()) == {"face.json", "mesh.obj", "muscles.toml"}
    assert meta["format"] == "myoface face" and meta["units"] == "mm"
