"""The assembled face model: muscles driving the tissue, jaw, symmetry, robustness, Waters."""

import threading
import warnings

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from myoface.errors import MyofaceFileNotFoundError, MyofaceValueError
from myoface.model import FaceState, build_face_model, load_face_model, relax, simulate
from myoface.tissue import kinetic_energy, potential_energy
from tests.conftest import shared_path


@pytest.fixture(scope="module")
def fm():
    return build_face_model()


@pytest.fixture(scope="module")
def mirror(fm):
    v = fm.face.vertices
    d, idx = cKDTree(v).query(v * [-1, 1, 1])
    assert d.max() < 1e-6
    return idx


def displacement(fm, contractions):
    res = fm.relax(contractions)
    assert res.converged
    return fm.skin_vertices(res.state) - fm.face.vertices


def test_zero_contraction_is_rest(fm):
    d = displacement(fm, {})
    assert np.abs(d).max() < 1e-9


def test_bone_nodes_stay_fixed(fm):
    x = fm.relax({"zygomaticus_major_l": 1.0, "frontalis_major_r": 1.0}).state.x
    bone = fm.tissue.layer_nodes("bone")
    np.testing.assert_array_equal(x[bone], fm.tissue.rest_positions[bone])


def test_jaw_rotates_only_the_lower_bone(fm):
    x = fm.relax({"jaw": 1.0}).state.x
    bone = fm.tissue.layer_nodes("bone")
    moved = np.linalg.norm(x[bone] - fm.tissue.rest_positions[bone], axis=1)
    w = fm.muscles.jaw.weights
    assert np.all(moved[w == 0] == 0) and np.all(moved[w > 0.5] > 1.0)


def test_a_lateral_pterygoid_turns_the_mandible_and_the_chin_goes_to_the_other_side(fm):
    """AD30: the left lateral pterygoid swings the chin to the subject's right (-x); only the
    bone under the lower face turns, the skin follows it through the tissue, the upper face
    stays, the right muscle does the mirror image, the pair cancels, and the lower teeth
    follow the bone of the chin (the jaw's pose)."""
    chin = fm.face.landmarks["chin"]
    above = fm.face.vertices[:, 1] > fm.face.vertices[fm.face.landmark("nose_base"), 1].max() + 30
    w = fm.muscles.jaw.weights
    bone = fm.tissue.layer_nodes("bone")
    left = fm.relax({"lateral_pterygoid_l": 0.5})
    x = left.state.x
    moved = x[bone] - fm.tissue.rest_positions[bone]
    assert np.all(np.linalg.norm(moved[w == 0], axis=1) == 0)
    # the bone of the chin turns 4 mm (half the 8 mm travel), sideways and a little forward
    bone_chin = moved[chin].mean(0)
    assert -4.2 < bone_chin[0] < -3.2 and abs(bone_chin[1]) < 0.1, bone_chin
    d = displacement(fm, {"lateral_pterygoid_l": 0.5})
    skin_chin = d[chin].mean(0)
    assert skin_chin[0] < -2.5 and abs(skin_chin[1]) < 0.5, skin_chin
    # the eyes, brows and forehead stay (the lattice's free edge by the temple moves 0.55 mm,
    # as 0.6 with the jaw half open and 0.36 with a zygomatic major at 0.5)
    assert np.median(np.linalg.norm(d[above], axis=1)) < 0.05
    brows = np.r_[fm.face.landmark("eyebrow_l"), fm.face.landmark("eyebrow_r")]
    assert np.abs(d[brows]).max() < 0.1
    right = displacement(fm, {"lateral_pterygoid_r": 0.5})
    assert right[chin].mean(0)[0] > 2.5
    both = displacement(fm, {"lateral_pterygoid_l": 0.5, "lateral_pterygoid_r": 0.5})
    assert np.abs(both).max() < 1e-6
    rot, shift = fm.jaw_pose(left.state)
    weight_one = chin[w[chin] > 0.999]
    rest = fm.tissue.rest_positions[bone][weight_one]
    # (the bone follows the turn linearised, the teeth the rotation: 0.06 mm apart here)
    np.testing.assert_allclose(rest @ rot.T + shift, x[bone][weight_one], atol=0.1)
    assert np.abs(rest @ rot.T + shift - rest)[:, 0].min() > 3.0


def test_muscles_move_the_skin_in_their_anatomical_direction(fm):
    f = fm.face
    corner_l = f.landmark("mouth_corner_l")[0]
    brow_l = f.landmark("eyebrow_l")
    d = displacement(fm, {"zygomaticus_major_l": 1.0})
    assert d[corner_l, 1] > 3.0 and d[corner_l, 0] > 1.0  # up and back towards the cheekbone
    assert np.abs(d[f.landmark("mouth_corner_r")[0]]).max() < 0.5  # the other side stays
    d = displacement(fm, {"depressor_anguli_oris_l": 1.0})
    assert d[corner_l, 1] < -2.0
    for m in ("frontalis_inner_l", "frontalis_major_l", "frontalis_outer_l"):
        d = displacement(fm, {m: 1.0})
        assert d[brow_l, 1].max() > 2.0, m
    d = displacement(fm, {"corrugator_supercilii_l": 1.0})
    assert d[brow_l[:3], 0].mean() < -1.0  # the inner brow is drawn towards the midline
    d = displacement(fm, {"depressor_labii_inferioris_l": 1.0})
    assert d[f.landmark("lip_lower_outer"), 1].min() < -1.0
    assert np.abs(d[f.landmark("lip_upper_inner")[1:-1]]).max() < 0.5  # not the upper lip
    d = displacement(fm, {"mentalis_l": 1.0, "mentalis_r": 1.0})
    assert d[f.landmark("chin_boss"), 1].mean() > 1.0
    d = displacement(fm, {"levator_labii_superioris_alaeque_nasi_l": 1.0})
    assert d[f.landmark("nose_ala_l")[0], 1] > 1.0
    d = displacement(fm, {"orbicularis_oris": 1.0})
    assert d[corner_l, 0] < -2.0  # the lips purse: corners move in
    d = displacement(fm, {"orbicularis_oculi_l": 1.0})
    eye = f.vertices[f.landmark("eye_l")]
    opening0 = eye[:, 1].max() - eye[:, 1].min()
    eye1 = eye + d[f.landmark("eye_l")]
    assert eye1[:, 1].max() - eye1[:, 1].min() < opening0 - 1.0  # the eye narrows


def test_jaw_opens_the_lips(fm):
    f = fm.face
    upper, lower = f.landmark("lip_upper_inner")[5], f.landmark("lip_lower_inner")[5]
    gap0 = f.vertices[upper, 1] - f.vertices[lower, 1]
    x = fm.skin_vertices(fm.relax({"jaw": 1.0}).state)
    gap = x[upper, 1] - x[lower, 1]
    assert gap - gap0 > 10.0  # the lips part by more than 1 cm
    # the nose stays: its tip, dragged only through the skin (its bone never follows the jaw),
    # moves by less than a twentieth of the lips' opening (1.2 mm for 37 mm at full opening)
    nose = np.linalg.norm(x[f.landmark("nose_tip")] - f.vertices[f.landmark("nose_tip")])
    assert nose < 0.05 * (gap - gap0)


@pytest.mark.xfail(
    strict=True,
    raises=AssertionError,
    reason="known regression (the recalibrated muscles of 2026-11): the stronger muscles invert "
    "fat and muscle-layer prisms at the mouth corners and beside the nose (up to 29 in AU12, "
    "97 in disgust), and the equilibrium's asymmetry grows to 0.95 mm, 8% of the largest "
    "displacement (0.33 mm before)",
)
def test_symmetric_contractions_give_a_symmetric_face(fm, mirror):
    """Mirror-symmetric within 5% of the largest displacement.

    The rest lattice and the muscle targets are exactly symmetric; the equilibrium is not, to
    a few tenths of a mm, because each prism's split into tetrahedra (volume term) and its shear
    diagonals follow the triangle's vertex order, which the mirror reverses.
    """
    rng = np.random.default_rng(0)
    for _ in range(3):
        c = {}
        for left, right in fm.muscles.mirror_pairs():
            c[left] = c[right] = float(rng.uniform(0, 1))
        c["orbicularis_oris"] = float(rng.uniform(0, 1))
        c["jaw"] = float(rng.uniform(0, 1))
        d = displacement(fm, c)
        x = fm.face.vertices + d
        asym = np.abs(x[mirror] * [-1, 1, 1] - x).max()
        assert asym < 0.05 * np.abs(d).max(), asym
        # and a one-sided contraction is clearly not symmetric
    d = displacement(fm, {"zygomaticus_major_l": 1.0})
    x = fm.face.vertices + d
    assert np.abs(x[mirror] * [-1, 1, 1] - x).max() > 0.5 * np.abs(d).max()


def test_targets_are_exactly_symmetric(fm, mirror):
    c = {k: 0.6 for k in fm.ids}
    tg = fm.targets(c)
    kin = fm.tissue.kinematic_index
    nv = fm.face.n_vertices
    pos = {n: i for i, n in enumerate(kin)}
    j = np.array([pos[(n // nv) * nv + mirror[n % nv]] for n in kin])
    np.testing.assert_allclose(tg[j] * [-1, 1, 1], tg, atol=1e-9)


@settings(
    max_examples=12, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(st.lists(st.floats(0.0, 1.0), min_size=64, max_size=64))
def test_no_nan_for_any_contraction_vector(fm, values):
    c = np.array(values[: fm.n_muscles])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a slow convergence is reported, not an error here
        res = fm.relax(c, max_iter=400)
    assert np.isfinite(res.state.x).all()
    # the paper's explicit integrator from rest, after a step change to c: finite, and with the
    # kinematic nodes held the damped lattice is autonomous, so its total energy cannot grow
    # past the elastic energy of the step (1e-9 relative and 1e-9 nJ absolute: floating-point
    # summation over ~16,000 terms)
    s = fm.step(None, c, n_steps=300)
    assert np.isfinite(s.x).all()
    x0 = fm.tissue.rest_positions.copy()
    x0[fm.tissue.kinematic_index] = fm.targets(c)
    e0 = potential_energy(fm.tissue, x0)
    e1 = potential_energy(fm.tissue, s.x) + kinetic_energy(fm.tissue, s.v)
    assert e1 <= e0 * (1 + 1e-9) + 1e-9, (e1, e0)


def test_rk2_simulation_reaches_the_relaxed_equilibrium(fm):
    c = {"zygomaticus_major_l": 0.8, "zygomaticus_major_r": 0.8, "jaw": 0.3}
    target = fm.skin_vertices(fm.relax(c).state)
    times = np.linspace(0.0, 0.4, 5)
    sim = simulate(fm, lambda t: c, times)
    skins = sim.skin
    assert isinstance(sim.state, FaceState)
    np.testing.assert_array_equal(fm.skin_vertices(sim.state), skins[-1])
    assert skins.shape == (5, fm.face.n_vertices, 3)
    err = np.abs(skins - target).max(axis=(1, 2))
    assert err[-1] < 0.05 and err[-1] < err[1]


def test_model_input_errors(fm, tmp_path):
    with pytest.raises(MyofaceValueError, match="method"):
        fm.relax({}, method="middle")
    with pytest.raises(MyofaceValueError, match="got 3 for"):
        fm.relax({"jaw": 3})
    with pytest.raises(MyofaceFileNotFoundError):
        load_face_model(tmp_path / "nope.obj")
    with pytest.raises(MyofaceFileNotFoundError, match="not a Waters geoface folder"):
        load_face_model(tmp_path)


def test_waters_model_assembles_and_reproduces_his_expressions():
    fm = load_face_model(shared_path("waters-geoface"))
    # the paper's model has about 960 elements and 6,500 springs; ours is finer (3 layers of
    # prisms under each of Waters' 876 triangles): report, and check the structure
    _check_layer_volumes(fm)
    print(f"Waters geoface: {fm.tissue.summary()}")
    assert sorted(fm.expressions) == [
        "anger",
        "disgust",
        "fear",
        "happiness",
        "sadness",
        "surprise",
    ]
    v0 = fm.face.vertices
    top = v0[:, 1] > np.percentile(v0[:, 1], 70)  # forehead and brows
    moves = {}
    for name, c in fm.expressions.items():
        res = fm.relax(c)
        assert res.converged, name
        moves[name] = fm.skin_vertices(res.state) - v0
    assert np.isfinite(np.concatenate(list(moves.values()))).all()
    # surprise and sadness lift the brow region, anger pulls it down
    assert moves["surprise"][top, 1].mean() > 0.3
    assert moves["sadness"][top, 1].max() > 2.0
    # happiness: the zygomatic majors raise the mouth corners
    corners = [
        np.argmin(np.abs(v0[:, 0] - s * 16) + np.abs(v0[:, 1] + 22) + np.abs(v0[:, 2] - 78))
        for s in (-1, 1)
    ]
    assert all(moves["happiness"][i, 1] > 1.0 for i in corners)


def test_load_mesh_with_muscle_file(tmp_path):
    """Any triangle mesh plus a muscle file: here a dome with one linear muscle and a jaw."""
    import trimesh

    dome = trimesh.creation.icosphere(subdivisions=3, radius=60.0)
    keep = dome.vertices[dome.faces].mean(axis=1)[:, 2] > 5.0
    dome = trimesh.Trimesh(dome.vertices, dome.faces[keep], process=True)
    dome.remove_unreferenced_vertices()
    path = tmp_path / "dome.obj"
    dome.export(path)
    top = int(np.argmax(dome.vertices[:, 2]))
    low = [int(i) for i in np.flatnonzero(dome.vertices[:, 1] < -40)]
    (tmp_path / "dome.muscles.toml").write_text(
        "[[muscle]]\n"
        'id = "lift"\ntype = "linear"\n'
        f"origin = {{ vertex = {top}, depth_mm = 15, offset_mm = [0, 30, 0] }}\n"
        f"insertion = {{ vertex = {top}, depth_mm = 6 }}\n"
        "radius_mm = 25\nmax_shortening_mm = 5\n"
        "[jaw]\nhinge = { xyz_mm = [0, 0, -40] }\nmax_angle_rad = 0.2\n"
        f"lower = {low}\nupper = [{top}]\n"
    )
    fm = load_face_model(path)
    assert fm.ids == ("lift", "jaw")
    lifted = fm.relax({"lift": 1.0}).state
    d = fm.skin_vertices(lifted) - fm.face.vertices
    assert d[top, 1] > 1.0  # pulled up, towards the origin
    d = fm.skin_vertices(fm.relax({"lift": 0.0, "jaw": 1.0}, lifted).state) - fm.face.vertices
    assert d[low, 1].mean() < -1.0 and abs(d[top]).max() < abs(d[low]).max()


def test_default_topology_obj_gets_default_muscles(tmp_path, default_face):
    from myoface.face import save_mesh

    path = tmp_path / "face.obj"
    save_mesh(default_face, path)
    fm = load_face_model(path)
    assert fm.ids == build_face_model().ids


def _check_layer_volumes(fm):
    """Each layer of prisms has the thickness it was built with: its rest volume is the skin's
    area times the layer's thickness, less what curvature and the local thinning at sharp
    creases take (a layer of thickness h under a surface of mean curvature radius R loses about
    h / R of its volume: under 10 % for h <= 4 mm and R >= 40 mm), and no prism is flat."""
    t = fm.tissue
    tri = fm.face.vertices[fm.face.triangles]
    area = (
        0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1).sum()
    )
    thick = np.diff(t.params.depths_mm)
    vol = np.abs(t.rest_volume)
    assert vol.min() > 0
    for layer in (1, 2, 3):
        ratio = vol[t.element_layer == layer].sum() / (area * thick[layer - 1])
        assert 0.75 < ratio < 1.1, (layer, ratio)


def test_default_lattice_layers_have_their_thickness(fm):
    _check_layer_volumes(fm)


def test_model_is_immutable_and_states_are_values(fm):
    with pytest.raises(AttributeError, match="immutable"):
        fm.ids = ("x",)
    s0 = fm.rest_state()
    with pytest.raises(ValueError):
        s0.x[0, 0] = 1.0  # read-only arrays
    res = fm.relax({"zygomaticus_major_l": 0.7}, s0)
    # relaxing returned a new state and left the one it started from (and the model) as they were
    np.testing.assert_array_equal(s0.x, fm.tissue.rest_positions)
    np.testing.assert_array_equal(fm.skin_vertices(), fm.face.vertices)
    assert (
        res.state is not s0 and res.state.contractions[fm.ids.index("zygomaticus_major_l")] == 0.7
    )
    # its lattice too: frozen, with read-only arrays
    with pytest.raises(AttributeError):
        fm.tissue.kinematic = np.zeros(fm.tissue.n_nodes, bool)
    with pytest.raises(ValueError):
        fm.tissue.rest_positions[0, 0] = 1.0
    with pytest.raises(AttributeError, match="immutable"):
        fm.stable_dt = 1.0


def test_the_stable_step_is_the_lattices_computed_once(fm):
    from myoface.tissue import stable_time_step

    assert fm.stable_dt is fm.tissue.stable_dt
    assert fm.stable_dt == stable_time_step(fm.tissue) > 0


def test_two_threads_share_one_model(fm):
    """A model relaxed by two threads at once gives each thread what one thread alone gets."""
    rng = np.random.default_rng(1)
    cs = [rng.uniform(0, 0.8, fm.n_muscles) for _ in range(4)]
    alone = [fm.relax(c).state.x for c in cs]
    out: dict = {}

    def work(k):
        for j in range(k, len(cs), 2):
            out[j] = relax(fm, cs[j]).state.x

    threads = [threading.Thread(target=work, args=(k,)) for k in (0, 1)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    for j, x in enumerate(alone):
        np.testing.assert_array_equal(out[j], x)


def test_memo_computes_once_across_threads(fm):
    calls = []
    barrier = threading.Barrier(4)

    def compute():
        calls.append(1)
        return object()

    got = []

    def work():
        barrier.wait()
        got.append(fm.memo(("test_memo", id(calls)), compute))

    threads = [threading.Thread(target=work) for _ in range(4)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    assert len(calls) == 1 and all(g is got[0] for g in got)
