"""Muscle fields, the default set, the jaw, muscle files and Waters' data."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from myoface.errors import MyofaceFileNotFoundError, MyofaceFormatError, MyofaceValueError
from myoface.muscles import (
    Jaw,
    LinearMuscle,
    SheetMuscle,
    SphincterMuscle,
    WatersMuscle,
    harmonic_weights,
    load_default_muscles,
    load_muscles,
    read_waters_expressions,
    read_waters_muscles,
    rotate_about_axis,
)
from tests.conftest import shared_path

PAPER_TWELVE = [
    f"{m}_{s}"
    for m in (
        "frontalis_inner",
        "frontalis_major",
        "frontalis_outer",
        "zygomaticus_major",
        "depressor_labii_inferioris",
        "levator_labii_superioris_alaeque_nasi",
    )
    for s in "lr"
]


@pytest.fixture(scope="module")
def muscles(default_face):
    return load_default_muscles(default_face)


def mirror_map(vertices):
    d, idx = cKDTree(vertices).query(vertices * [-1, 1, 1])
    assert d.max() < 1e-6  # the canonical face is mirror symmetric
    return idx


def test_linear_muscle_is_eq6_cosine_blend():
    m = LinearMuscle("m", [0, 0, -20], [0, 0, 0], radius_mm=10, max_shortening_mm=4)
    pts = np.array([[0, 0, 0], [5, 0, 0], [10, 0, 0], [12, 0, 0]], float)
    f = m.field(pts, np.zeros(4))
    expected = 4 * np.cos(np.array([0, 0.5, 1.0, 1.0]) * np.pi / 2)
    expected[3] = 0
    np.testing.assert_allclose(f[:, 2], -expected, atol=1e-12)  # towards the origin (-z)
    np.testing.assert_allclose(f[:, :2], 0, atol=1e-12)


def test_sheet_muscle_moves_along_the_surface_and_fades_at_edges():
    m = SheetMuscle("s", [0, 40, -5], [0, 0, 0], 20, 10, 8, normal=[0, 0, 1])
    pts = np.array([[0, 0, 0], [0, 20, 0], [0, 41, 0], [5, 0, 0], [10, 0, 0], [0, -10, 0]], float)
    f = m.field(pts, np.zeros(len(pts)))
    np.testing.assert_allclose(f[:, [0, 2]], 0, atol=1e-12)  # tangential: no push into bone
    assert f[0, 1] == pytest.approx(8)
    assert f[1, 1] == pytest.approx(8 * np.cos(20 / np.hypot(40, 5) * np.pi / 2))
    assert f[2, 1] == pytest.approx(0, abs=1e-12)
    assert 0 < f[3, 1] < f[0, 1] and f[4, 1] == pytest.approx(0, abs=1e-12)
    assert f[5, 1] == pytest.approx(0, abs=1e-12)


def test_sphincter_draws_ring_towards_centre():
    m = SphincterMuscle("o", [0, 0, 0], [0, 0, 1], [1, 0, 0], (20, 10), 0.5, 5, protrusion_mm=2)
    pts = np.array([[20, 0, 0], [-20, 0, 0], [0, 10, 0], [0, -10, 0], [0, 0, 0], [40, 0, 0]], float)
    f = m.field(pts, np.zeros(len(pts)))
    np.testing.assert_allclose(f[0], [-5, 0, 2], atol=1e-12)
    np.testing.assert_allclose(f[1], [5, 0, 2], atol=1e-12)
    np.testing.assert_allclose(f[2], [0, -5, 2], atol=1e-12)
    np.testing.assert_allclose(f[3], [0, 5, 2], atol=1e-12)
    np.testing.assert_allclose(f[4], 0, atol=1e-12)
    np.testing.assert_allclose(f[5], 0, atol=1e-12)


def test_waters_muscle_zone_and_falloff():
    m = WatersMuscle("w", [0, 0, 10], [0, 0, 0], 1.0, 20.0, 30.0, clamp=2.0)
    pts = np.array([[0, 0, 5], [0, 5, 5], [0, 0, 25], [0, 0, -5]], float)
    f = m.field(pts, np.zeros(4))
    # inside the cone: towards the bone point; factor clamp (cos a / cos zone - 1) R
    r = np.cos((5 - 1) / 19 * np.pi / 2)
    np.testing.assert_allclose(f[0], [0, 0, -5 * 2 * (1 / np.cos(np.pi / 6) - 1) * r])
    np.testing.assert_allclose(f[1:], 0, atol=1e-12)  # outside the zone / beyond fall-off / behind


def test_region_keeps_lower_lip_muscles_off_the_upper_lip():
    m = LinearMuscle("m", [0, -20, 0], [0, 0, 0], 10, 5, region="lower")
    pts = np.zeros((2, 3))
    f = m.field(pts, np.array([1.0, 0.0]))
    assert f[0, 1] < 0 and np.all(f[1] == 0)


def test_lower_share_weights_the_lower_lip_and_corner():
    """A linear muscle's lower_share: the lower lip (jaw weight 1) takes that share of the field,
    the corner on the slit (1/2) the mean of it and 1, the upper lip all of it; mirrored too."""
    m = LinearMuscle("m", [0, 20, 0], [0, 0, 0], 10, 5, lower_share=0.3)
    pts = np.zeros((3, 3))
    f = m.field(pts, np.array([0.0, 0.5, 1.0]))
    np.testing.assert_allclose(f[:, 1], 5 * np.array([1.0, 0.65, 0.3]))
    assert m.mirrored("n").lower_share == 0.3
    with pytest.raises(MyofaceValueError, match="lower_share"):
        LinearMuscle("m", [0, 20, 0], [0, 0, 0], 10, 5, lower_share=1.5)


def test_bound_skin_stiffens_the_fat_under_its_vertices(tmp_path, default_face):
    """[bound_skin]: the fat layer's springs under the listed vertices (both ends under them)
    take the given stiffness, and no other spring changes."""
    from myoface.model import FaceModel
    from myoface.tissue.model import LAYERS

    f = tmp_path / "m.toml"
    body = (
        '[[muscle]]\nid = "pull"\nsides = "lr"\ntype = "linear"\n'
        "origin = { vertex = 345, depth_mm = 12 }\ninsertion = { vertex = 291, depth_mm = 6 }\n"
        "radius_mm = 10\nmax_shortening_mm = 3\nlower_share = 0.5\n"
    )
    f.write_text(body + "[bound_skin]\nvertices = [17, 18, 200]\nfat = [3000.0, 30000.0, 0.3]\n")
    ms = load_muscles(f, default_face)
    assert ms["pull_r"].lower_share == 0.5
    np.testing.assert_array_equal(ms.bound_skin.vertices, [17, 18, 200])
    bound = FaceModel(default_face, ms).tissue
    free = FaceModel(default_face, load_muscles(_write(tmp_path / "n.toml", body), default_face))
    free = free.tissue
    changed = bound.spring_material != free.spring_material
    nv = default_face.n_vertices
    assert changed.any() and np.all(free.spring_material[changed] == LAYERS.index("fat"))
    ends = np.stack([bound.spring_i[changed] % nv, bound.spring_j[changed] % nv])
    assert set(np.unique(ends)) <= {17, 18, 200}
    np.testing.assert_array_equal(bound.materials[bound.spring_material[changed]][:, 0], 3000.0)
    for bad, msg in (("vertices = [99999]", "outside"), ("vertices = []", "list of vertex")):
        f.write_text(body + f"[bound_skin]\n{bad}\nfat = [1.0, 2.0, 0.1]\n")
        with pytest.raises(MyofaceFormatError, match=msg):
            load_muscles(f, default_face)


def _write(path, text):
    path.write_text(text)
    return path


def test_default_set_has_the_required_muscles(muscles):
    required = PAPER_TWELVE + [
        f"{m}_{s}"
        for m in ("corrugator_supercilii", "depressor_anguli_oris", "mentalis", "risorius")
        for s in "lr"
    ]
    required += ["orbicularis_oris", "orbicularis_oculi_l", "orbicularis_oculi_r", "jaw"]
    assert set(required) <= set(muscles.ids)
    assert muscles.ids[-1] == "jaw" and muscles.jaw_index == len(muscles) - 1
    kinds = {m.kind for m in muscles.muscles}
    assert {"linear", "sheet", "sphincter"} <= kinds


def test_default_set_origins_in_bone_insertions_under_skin(muscles, default_face):
    tree = cKDTree(default_face.vertices)
    for m in muscles.muscles:
        if m.kind == "sphincter":
            continue
        d_origin = tree.query(m.origin)[0]
        if m.kind == "pterygoid":  # a muscle of the mandible: both ends deep in the head
            assert d_origin >= 9.0 and tree.query(m.insertion)[0] >= 9.0, m.id
            continue
        d_ins = tree.query(m.insertion)[0]
        assert d_origin >= 9.0, m.id  # below the 9 mm of tissue
        assert d_ins < 9.0, m.id


def test_default_set_is_mirror_symmetric(muscles):
    flip = np.array([-1.0, 1.0, 1.0])
    pairs = muscles.mirror_pairs()
    assert len(pairs) == 19  # 16 tissue muscles, 2 lid muscles and the lateral pterygoid a side
    for left, right in pairs:
        ml, mr = muscles[left], muscles[right]
        assert ml.insertion[0] > 0 > mr.insertion[0]  # _l is the subject's left, +x
        np.testing.assert_allclose(mr.origin, ml.origin * flip, atol=1e-9)
        np.testing.assert_allclose(mr.insertion, ml.insertion * flip, atol=1e-9)
    assert abs(muscles["orbicularis_oris"].center[0]) < 1e-9
    assert muscles.jaw.mirror_error_mm() < 1e-9
    pl, pr = muscles["lateral_pterygoid_l"], muscles["lateral_pterygoid_r"]
    np.testing.assert_allclose(pr.pivot, pl.pivot * flip, atol=1e-9)
    np.testing.assert_allclose(pr.reference, pl.reference * flip, atol=1e-9)
    assert pr.turn_rad == -pl.turn_rad != 0


def test_basis_mirror_symmetric(muscles, default_face):
    v = default_face.vertices
    mi = mirror_map(v)
    b = muscles.basis(v, muscles.jaw.weights)
    flip = np.array([-1.0, 1.0, 1.0])
    for left, right in muscles.mirror_pairs():
        bl = b[:, :, muscles.index(left)]
        br = b[:, :, muscles.index(right)]
        np.testing.assert_allclose(br[mi] * flip, bl, atol=1e-9)
    bo = b[:, :, muscles.index("orbicularis_oris")]
    np.testing.assert_allclose(bo[mi] * flip, bo, atol=1e-9)
    assert np.all(b[:, :, muscles.jaw_index] == 0)


def test_jaw_weights_follow_anatomy(muscles, default_face):
    w = muscles.jaw.weights
    f = default_face
    assert np.all((w >= 0) & (w <= 1))
    np.testing.assert_allclose(w[f.landmark("menton")], 1)
    np.testing.assert_allclose(w[f.landmark("nose_tip")], 0)
    corners = set(f.landmark("mouth_corner_l")) | set(f.landmark("mouth_corner_r"))
    # the lips follow whole (lower) or not at all (upper), but for the corners
    lower_out = [i for i in f.landmark("lip_lower_outer") if i not in corners]
    upper_out = [i for i in f.landmark("lip_upper_outer") if i not in corners]
    assert np.all(w[lower_out] == 1) and np.all(w[upper_out] == 0)
    # the inner margins: the middle held, the three vertices nearest each corner turn smoothly
    # round the commissure (the lower lip always following more than the upper beside it)
    lo_in, up_in = w[f.landmark("lip_lower_inner")], w[f.landmark("lip_upper_inner")]
    assert np.all(lo_in[3:-3] == 1) and np.all(up_in[3:-3] == 0)
    assert np.all(lo_in[1:3] > up_in[1:3]) and np.all(lo_in[-3:-1] > up_in[-3:-1])
    assert np.all(np.diff(lo_in[:4]) > 0) and np.all(np.diff(up_in[:4]) < 0)
    assert all(0.2 < w[i] < 0.8 for i in corners)  # the corners stretch between the lips
    assert np.all(w[f.vertices[:, 1] > 0] == 0)  # eyes, brows, forehead never follow the jaw


def test_default_jaw_turns_and_slides_forward_and_down(muscles):
    """The condyles slide forward and down the articular eminence (myoface.muscles.jaw)."""
    jaw = muscles.jaw
    _, down, forward = jaw.slide_mm
    assert down < 0 and forward > 0
    assert 0.3 < np.arctan2(-down, forward) < 0.8  # the eminence's 30-40 deg, give or take


def test_jaw_opens_in_two_phases_and_the_pose_moves_the_hinge_by_the_slide(muscles):
    """A hinge first (rotation linear in the control, no slide), then the condyles slide while
    the mandible turns on to its largest angle; the motion has no kink where the slide starts."""
    jaw = muscles.jaw
    k, h = jaw.translation_from, jaw.hinge_angle_rad
    assert 0 < k < 1 and 0 < h < jaw.max_angle_rad
    for c in (0.0, 0.5 * k, k):  # the hinge phase
        assert jaw.angle_rad(c) == pytest.approx(h * c)
        np.testing.assert_array_equal(jaw.slide(c), 0.0)
    assert jaw.angle_rad(1.0) == pytest.approx(jaw.max_angle_rad)
    np.testing.assert_allclose(jaw.slide(1.0), jaw.slide_mm)
    c = np.linspace(0, 1, 201)
    angle = np.array([jaw.angle_rad(x) for x in c])
    slide = np.array([np.linalg.norm(jaw.slide(x)) for x in c])
    assert np.all(np.diff(angle) > 0) and np.all(np.diff(slide) >= 0)
    rate = np.diff(angle) / np.diff(c)
    assert np.abs(np.diff(rate)).max() < 0.05 * h  # smooth: the rate changes by little steps
    rot0, shift0 = jaw.pose(0.0)
    np.testing.assert_allclose(rot0, np.eye(3), atol=1e-15)
    np.testing.assert_allclose(shift0, 0.0, atol=1e-12)
    for c in (0.3, 0.8, 1.0):
        rot, shift = jaw.pose(c)
        np.testing.assert_allclose(rot @ rot.T, np.eye(3), atol=1e-12)
        assert np.arccos((np.trace(rot) - 1) / 2) == pytest.approx(jaw.angle_rad(c))
        # the hinge (the condyles) moves by exactly the slide
        np.testing.assert_allclose(rot @ jaw.hinge_point + shift, jaw.hinge_point + jaw.slide(c))
        # a point of weight 1 follows the pose, one of weight 0 stays, one of weight 1/2 on
        # the hinge moves by half the slide
        p = np.array([[0.0, -60.0, 40.0], [5.0, -50.0, 30.0], jaw.hinge_point])
        q = jaw.rotate(p, np.array([1.0, 0.0, 0.5]), c)
        np.testing.assert_allclose(q[0], rot @ p[0] + shift, atol=1e-9)
        np.testing.assert_array_equal(q[1], p[1])
        np.testing.assert_allclose(q[2], p[2] + 0.5 * jaw.slide(c), atol=1e-9)


def test_a_jaw_without_a_translation_phase_is_the_papers_hinge(muscles):
    jaw = muscles.jaw
    plain = Jaw(jaw.hinge_point, jaw.hinge_axis, 0.3, jaw.weights)
    for c in (0.0, 0.4, 1.0):
        assert plain.angle_rad(c) == pytest.approx(0.3 * c)
        np.testing.assert_array_equal(plain.slide(c), 0.0)
    for bad, match in (
        (dict(hinge_angle_rad=0.5), "hinge_angle_rad must be in"),
        (dict(translation_from=1.0), "translation_from must be in"),
        (dict(slide_mm=[0.0, 1.0]), "slide_mm must be a finite 3-vector"),
    ):
        with pytest.raises(MyofaceValueError, match=match):
            Jaw(jaw.hinge_point, jaw.hinge_axis, 0.3, jaw.weights, **bad)


def test_jaw_file_slide(tmp_path, default_face):
    f = tmp_path / "m.toml"
    head = (
        '[[muscle]]\nid = "pull"\ntype = "linear"\norigin = { vertex = 345, depth_mm = 12 }\n'
        "insertion = { vertex = 291 }\nradius_mm = 10\nmax_shortening_mm = 3\n"
        '[jaw]\nhinge = { xyz_mm = [0, -20, -30] }\nmax_angle_rad = 0.4\nlower = ["chin"]\n'
        'upper = ["nose_base"]\n'
    )
    f.write_text(head)
    assert np.all(load_muscles(f, default_face).jaw.slide_mm == 0)  # default: a pure hinge
    f.write_text(head + "slide_mm = [0, -5, 8]\nhinge_angle_rad = 0.2\ntranslation_from = 0.5\n")
    jaw = load_muscles(f, default_face).jaw
    np.testing.assert_array_equal(jaw.slide_mm, [0, -5, 8])
    assert (jaw.hinge_angle_rad, jaw.translation_from) == (0.2, 0.5)
    f.write_text(head + "slide_mm = [0, -5]\n")
    with pytest.raises(MyofaceFormatError, match="slide_mm must be 3 finite numbers"):
        load_muscles(f, default_face)


def test_jaw_and_point_specs_of_the_wrong_type_are_format_errors(tmp_path, default_face):
    """A vertex list, a landmark or a depth of the wrong type says so (the parser's property
    test found ``lower = 0`` raising a TypeError)."""
    f = tmp_path / "m.toml"
    muscle = (
        '[[muscle]]\nid = "pull"\ntype = "linear"\norigin = { vertex = 345, depth_mm = 12 }\n'
        "insertion = { vertex = 291 }\nradius_mm = 10\nmax_shortening_mm = 3\n"
    )
    jaw = "[jaw]\nhinge = { xyz_mm = [0, -20, -30] }\nmax_angle_rad = 0.4\n"
    for body, match in (
        (muscle + jaw + 'lower = 0\nupper = ["nose_base"]\n', r"\[jaw\].lower must be a list"),
        (muscle + jaw + 'lower = ["chin"]\nupper = "nose_base"\n', r"\[jaw\].upper must be a list"),
        (muscle + jaw + 'lower = [1.5]\nupper = ["nose_base"]\n', "landmark must be a name"),
        (muscle + jaw + 'lower = [true]\nupper = ["nose_base"]\n', "landmark must be a name"),
        (muscle.replace("depth_mm = 12", 'depth_mm = "deep"'), "depth_mm must be a number"),
        (muscle.replace("{ vertex = 291 }", "{ landmark = 3 }"), "landmark must be a name"),
        (muscle.replace("{ vertex = 291 }", "{ vertex = true }"), "vertex must be an index"),
        ("jaw = 3\n" + muscle, r"\[jaw\] must be a table"),
        ("meta = 1\n" + muscle, r"\[meta\] must be a table"),
        (
            muscle.replace('type = "linear"', 'type = "sphincter"')
            .replace("origin = { vertex = 345, depth_mm = 12 }\n", "")
            .replace("insertion = { vertex = 291 }\nradius_mm = 10\nmax_shortening_mm = 3\n", "")
            + "center = { vertex = 13 }\nsemi_axes_mm = [20, 8]\nfalloff = 1.0\n"
            + "max_contraction_mm = 4.0\nprotrusion_mm = []\n",
            "protrusion_mm must be a number",
        ),
    ):
        f.write_text(body)
        with pytest.raises(MyofaceFormatError, match=match):
            load_muscles(f, default_face)


def test_rotate_about_axis_is_rigid_rotation():
    rng = np.random.default_rng(0)
    p = rng.normal(size=(10, 3))
    q = rotate_about_axis(p, np.array([1.0, 2, 3]), np.array([0, 0, 2.0]), np.pi / 2)
    np.testing.assert_allclose(
        np.linalg.norm(q[1:] - q[0], axis=1), np.linalg.norm(p[1:] - p[0], axis=1)
    )
    r = rotate_about_axis(np.array([[2.0, 2, 3]]), np.array([1.0, 2, 3]), [0, 0, 1], np.pi / 2)
    np.testing.assert_allclose(r, [[1, 3, 3]], atol=1e-12)


def test_harmonic_weights_linear_on_a_path():
    tris = np.array([[0, 1, 5], [1, 2, 5], [2, 3, 5], [3, 4, 5]])  # a fan: 5 is the hub
    w = harmonic_weights(6, tris, ones=[0], zeros=[4])
    assert w[0] == 1 and w[4] == 0 and np.all(np.diff(w[:5]) <= 1e-12)


def test_validate_contractions(muscles):
    c = muscles.validate({"zygomaticus_major_l": 0.5})
    assert c.shape == (len(muscles),) and c[muscles.index("zygomaticus_major_l")] == 0.5
    with pytest.raises(MyofaceValueError, match=r"got 1.7 for zygomaticus_major_l"):
        muscles.validate({"zygomaticus_major_l": 1.7})
    with pytest.raises(MyofaceValueError, match="did you mean zygomaticus_major_l"):
        muscles.validate({"zygomaticus_major_left": 0.5})
    with pytest.raises(MyofaceValueError, match="finite"):
        muscles.validate(np.full(len(muscles), np.nan))
    with pytest.raises(MyofaceValueError, match="shape"):
        muscles.validate(np.zeros(3))
    with pytest.raises(MyofaceValueError, match="must be a number"):
        muscles.validate({"jaw": "open"})
    with pytest.raises(MyofaceValueError, match="got -0.1 for jaw"):
        muscles.validate({"jaw": -0.1})


def test_muscle_file_errors(tmp_path, default_face):
    with pytest.raises(MyofaceFileNotFoundError):
        load_muscles(tmp_path / "missing.toml", default_face)
    bad = tmp_path / "bad.toml"
    bad.write_text("[[muscle]\nid=")
    with pytest.raises(MyofaceFormatError, match="not a valid TOML"):
        load_muscles(bad, default_face)
    bad.write_text('[[muscle]]\nid = "x"\ntype = "linear"\norigin = { vertex = 9999 }\n')
    with pytest.raises(MyofaceFormatError, match="missing keys"):
        load_muscles(bad, default_face)
    bad.write_text(
        '[[muscle]]\nid = "x"\ntype = "linear"\norigin = { vertex = 9999 }\n'
        "insertion = { vertex = 1 }\nradius_mm = 5\nmax_shortening_mm = 2\n"
    )
    with pytest.raises(MyofaceFormatError, match="vertex must be an index"):
        load_muscles(bad, default_face)
    bad.write_text('[[muscle]]\nid = "x"\ntype = "spring"\n')
    with pytest.raises(MyofaceFormatError, match="type must be one of"):
        load_muscles(bad, default_face)


def test_muscle_file_roundtrip_custom(tmp_path, default_face):
    f = tmp_path / "m.toml"
    f.write_text(
        '[[muscle]]\nid = "pull"\nsides = "lr"\ntype = "linear"\n'
        "origin = { vertex = 345, depth_mm = 12 }\ninsertion = { xyz_mm = [24, -43, 40] }\n"
        "radius_mm = 10\nmax_shortening_mm = 3\n"
    )
    ms = load_muscles(f, default_face)
    assert ms.ids == ("pull_l", "pull_r") and ms.jaw is None
    np.testing.assert_allclose(ms["pull_r"].insertion, [-24, -43, 40])


def test_waters_muscles_and_expressions():
    folder = shared_path("waters-geoface")
    ms = read_waters_muscles(folder)
    assert len(ms) == 18 and ms.jaw is None
    zm = ms["zygomatic_major_l"]
    assert zm.source_name == "Right_Zygomatic_Major" and zm.skin_point[0] > 0
    # the zygomatic major pulls the mouth corner up and outwards
    d = zm.field(zm.skin_point[None, :], np.zeros(1))[0]
    assert d[1] > 0 and d[0] > 0
    ex = read_waters_expressions(folder, ms)
    assert sorted(ex) == ["anger", "disgust", "fear", "happiness", "sadness", "surprise"]
    for c in ex.values():
        ms.validate(c)
    # happiness is led by the zygomatic majors (clamped at their clamp value 1.0 -> c = 1)
    h = ex["happiness"]
    assert h[ms.index("zygomatic_major_l")] == 1.0 and h[ms.index("zygomatic_major_r")] == 1.0
