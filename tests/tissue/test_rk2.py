"""The parallel RK2 kernel: held to the serial reference, thread-count invariance, the stable
time step cached once per model, and the energy of a step change of the kinematic targets."""

import threading

import numpy as np
import pytest

from myoface.tissue import (
    kinetic_energy,
    make_lattice,
    potential_energy,
    relax,
    rest_state,
    step_rk2,
)
from myoface.tissue import model as model_mod
from myoface.tissue import rk2 as rk2_mod
from myoface.tissue.rk2 import rk2_integrator, run_rk2, run_rk2_serial


def _step_change(model, seed=0, radius_mm=25.0, amp_mm=4.0):
    """Drive the fascia nodes within ``radius_mm`` of a random skin point by a smooth
    displacement (cosine fall-off, as a muscle does, eq. 6): the model with those nodes kinematic,
    and the (K, 3) targets."""
    rng = np.random.default_rng(seed)
    fas = model.layer_nodes("fascia")
    centre = model.rest_positions[rng.integers(model.n_vertices)]
    d = np.linalg.norm(model.rest_positions[fas] - centre, axis=1)
    near = d < radius_mm
    m2 = model.with_kinematic(fas[near])
    tg = m2.rest_positions[m2.kinematic_index].copy()
    rows = np.searchsorted(m2.kinematic_index, fas[near])
    tg[rows] += np.cos(d[near] / radius_mm * np.pi / 2)[:, None] * rng.normal(0, amp_mm, 3)
    return m2, tg


def _start(model, targets, seed=0, v_scale=0.0):
    s = rest_state(model)
    s.x[model.kinematic_index] = targets
    if v_scale:
        rng = np.random.default_rng(seed)
        s.v[model.free_index] = rng.normal(0, v_scale, (len(model.free_index), 3))
    return s.x, s.v


def test_parallel_kernel_follows_the_serial_reference(default_tissue):
    m, tg = _step_change(default_tissue, seed=3)
    x0, v0 = _start(m, tg, seed=3, v_scale=20.0)
    xa, va, xb, vb = x0.copy(), v0.copy(), x0.copy(), v0.copy()
    n = 300
    ra = run_rk2(m, xa, va, n, m.stable_dt)
    rb = run_rk2_serial(m, xb, vb, n, m.stable_dt)
    assert ra[0] == rb[0] == n and ra[2] == rb[2] == -1
    move = np.abs(xb - x0).max()
    assert move > 1.0  # the lattice really moved
    # Same arithmetic per spring and per tetrahedron; what differs is the order of the sums at a
    # node: the parallel kernel adds it prism by prism (each prism's volume term, plus the springs
    # that prism computes, summed per node before they are added), the serial one every spring,
    # then every tetrahedron's term, as they come. That is a reassociation: a few ulps of a force
    # per evaluation, ~1e-13 of the motion after n steps of this damped (contractive) system.
    # 1e-9 of the motion leaves 4 orders of magnitude for it; any modelling slip (a spring or
    # prism missed or counted twice, a wrong sign or midpoint) moves nodes by far more than 1e-9 mm.
    np.testing.assert_allclose(xa, xb, rtol=0, atol=1e-9 * move)
    np.testing.assert_allclose(va, vb, rtol=0, atol=1e-9 * np.abs(vb).max())


def test_trajectory_does_not_depend_on_the_number_of_blocks(default_tissue):
    # each node gathers the same terms in the same order whatever the cut: bit for bit
    m, tg = _step_change(default_tissue, seed=1)
    x0, v0 = _start(m, tg, seed=1, v_scale=20.0)
    out = []
    for nb in (1, 2, 5):
        x, v = x0.copy(), v0.copy()
        run_rk2(m, x, v, 50, m.stable_dt, n_blocks=nb)
        out.append((x, v))
    for x, v in out[1:]:
        np.testing.assert_array_equal(x, out[0][0])
        np.testing.assert_array_equal(v, out[0][1])


def test_one_worker_runs_every_block_in_order(default_tissue):
    """A team of one thread with several blocks claims each half-step's blocks in turn: the
    same trajectory, bit for bit, and the same early stop as one block."""
    import numba

    m, tg = _step_change(default_tissue, seed=8, amp_mm=1.0)
    x0, v0 = _start(m, tg, seed=8, v_scale=20.0)
    tol = 1e-3  # mm per step: reached after several hundred steps
    threads = numba.get_num_threads()
    out = []
    try:
        numba.set_num_threads(1)
        for nb in (1, 3):
            x, v = x0.copy(), v0.copy()
            out.append((run_rk2(m, x, v, 20_000, m.stable_dt, tol, n_blocks=nb), x, v))
    finally:
        numba.set_num_threads(threads)
    (ra, xa, va), (rb, xb, vb) = out
    assert 100 < ra[0] < 20_000 and ra[2] == -1 and ra == rb
    np.testing.assert_array_equal(xa, xb)
    np.testing.assert_array_equal(va, vb)


def test_thread_count_chosen_by_measurement_gives_the_same_trajectory(default_tissue, monkeypatch):
    # short calls and a probe of the other thread count at every call: still bit for bit
    monkeypatch.setattr(rk2_mod, "CHUNK_STEPS", 7)
    monkeypatch.setattr(rk2_mod, "PROBE_STEPS", 3)
    monkeypatch.setattr(rk2_mod, "PROBE_MIN_S", 0.0)
    monkeypatch.setattr(rk2_mod, "PROBE_MAX_S", 0.0)
    m, tg = _step_change(default_tissue, seed=6)
    x0, v0 = _start(m, tg, seed=6, v_scale=20.0)
    xa, va, xb, vb = x0.copy(), v0.copy(), x0.copy(), v0.copy()
    assert run_rk2(m, xa, va, 60, m.stable_dt) == run_rk2(m, xb, vb, 60, m.stable_dt, n_blocks=1)
    np.testing.assert_array_equal(xa, xb)
    np.testing.assert_array_equal(va, vb)
    # a blow-up is reported at the same step, counted from the start of the run
    xa, va, xb, vb = x0.copy(), v0.copy(), x0.copy(), v0.copy()
    ra = run_rk2(m, xa, va, 200, 12 * m.stable_dt)  # unstable: NaN after a few tens of steps
    rb = run_rk2(m, xb, vb, 200, 12 * m.stable_dt, n_blocks=1)
    assert ra[2] >= 7 and (ra[0], ra[2]) == (rb[0], rb[2])


def _prism_lattice(with_volume: bool):
    """One prism, every node free, the paper's discontinuous law; stretched and moving."""
    rng = np.random.default_rng(0)
    pos = np.array([[0, 0, 0], [4, 0, 0], [0, 4, 0], [0, 0, 3], [4, 0, 3], [0, 4, 3]], float)
    springs = [[0, 1], [1, 2], [2, 0], [3, 4], [4, 5], [5, 3], [0, 3], [1, 4], [2, 5], [0, 4]]
    lat = make_lattice(
        pos,
        springs,
        mass=0.02,
        damping=0.5,
        elements=[[0, 1, 2, 3, 4, 5]] if with_volume else None,
        volume_weight=5.0,
        biphasic="paper",
    )
    return lat, pos + rng.normal(0, 0.8, pos.shape), rng.normal(0, 5.0, pos.shape)


def test_parallel_kernel_on_a_lattice_with_every_node_free():
    # no kinematic node, so every spring and prism is kept
    lat, x0, v0 = _prism_lattice(with_volume=True)
    xa, va, xb, vb = x0.copy(), v0.copy(), x0.copy(), v0.copy()
    run_rk2(lat, xa, va, 400, 1e-4, n_blocks=2)
    run_rk2_serial(lat, xb, vb, 400, 1e-4)
    # reassociation of the prism's terms only, as above
    np.testing.assert_allclose(xa, xb, rtol=0, atol=1e-9 * np.abs(xb - x0).max())


def test_springs_inside_and_outside_prisms_each_count_once():
    """Springs that no prism holds (a node off the prism; a second spring on a prism edge) are
    evaluated on their own, the others with their prism: each once, whatever the blocks."""
    rng = np.random.default_rng(1)
    pos = np.array(
        [[0, 0, 0], [4, 0, 0], [0, 4, 0], [0, 0, 3], [4, 0, 3], [0, 4, 3], [5, 5, 5]], float
    )
    springs = [[0, 1], [1, 2], [2, 0], [3, 4], [4, 5], [5, 3], [0, 3], [1, 4], [2, 5], [4, 0]]
    springs += [[6, 5], [1, 6], [0, 1]]  # off the prism, and [0, 1] a second time
    lat = make_lattice(
        pos,
        springs,
        mass=0.02,
        damping=0.5,
        elements=[[0, 1, 2, 3, 4, 5]],
        volume_weight=5.0,
    )
    x0 = pos + rng.normal(0, 0.8, pos.shape)
    v0 = rng.normal(0, 5.0, pos.shape)
    xb, vb = x0.copy(), v0.copy()
    run_rk2_serial(lat, xb, vb, 400, 1e-4)
    for nb in (1, 2, 3):
        xa, va = x0.copy(), v0.copy()
        run_rk2(lat, xa, va, 400, 1e-4, n_blocks=nb)
        np.testing.assert_allclose(xa, xb, rtol=0, atol=1e-9 * np.abs(xb - x0).max())


def test_every_spring_of_the_face_is_computed_with_a_prism_once(default_tissue):
    m = default_tissue
    live = ~(m.kinematic[m.spring_i] & m.kinematic[m.spring_j])
    plan = rk2_integrator(m).plan(1)
    assert len(plan.spring_i) == 0  # none left to the separate spring loop
    k = plan.pair_consts.reshape(-1, rk2_mod.SPRING_ROWS, rk2_mod.PRISM_CHUNK)
    held = k[:, 1] > 0  # alpha > 0: a lane with a spring
    assert held.sum() == live.sum()
    np.testing.assert_array_equal(np.sort(k[:, 0][held]), np.sort(m.rest_length[live]))


def test_springs_alone_follow_the_serial_reference_bit_for_bit():
    # the springs' terms are added to each node in the same order, with the same arithmetic
    lat, x0, v0 = _prism_lattice(with_volume=False)
    xa, va, xb, vb = x0.copy(), v0.copy(), x0.copy(), v0.copy()
    run_rk2(lat, xa, va, 400, 1e-4, n_blocks=2)
    run_rk2_serial(lat, xb, vb, 400, 1e-4)
    np.testing.assert_array_equal(xa, xb)
    np.testing.assert_array_equal(va, vb)


def test_stable_dt_is_computed_once_per_model(default_tissue, monkeypatch):
    m, tg = _step_change(default_tissue, seed=2)  # a fresh model: nothing cached yet
    calls = []
    real = model_mod.stable_time_step

    def counting(model, *args, **kw):
        calls.append(model)
        return real(model, *args, **kw)

    monkeypatch.setattr(model_mod, "stable_time_step", counting)
    dt = m.stable_dt
    assert dt is m.stable_dt  # the cached value itself, not a recomputation
    s = step_rk2(m, rest_state(m), tg)
    step_rk2(m, s, tg, n_steps=3)
    relax(m, s, tg, method="rk2", max_iter=5, tol_mm=1e6)
    assert calls == [m]
    assert s.t == pytest.approx(dt)
    assert dt == real(m)  # the same value a fresh computation gives
    assert 0 < dt < 1e-3


def test_stable_dt_from_several_threads_is_one_value(default_tissue):
    m, _ = _step_change(default_tissue, seed=4)
    got = []
    threads = [threading.Thread(target=lambda: got.append(m.stable_dt)) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(set(got)) == 1 and got[0] == m.stable_dt


@pytest.mark.parametrize("seed", [0, 5])
def test_step_change_energy_never_grows_and_motion_is_bounded(default_tissue, seed):
    """After a step change of the kinematic targets (as when a muscle contracts at once) the
    damped lattice only loses energy: E(t) = T + U never exceeds E(0) = U(x0) (v0 = 0), so every
    free node's speed stays below sqrt(2 E(0) / m_i) and its travel below t sqrt(2 E(0) / m_i)."""
    m, tg = _step_change(default_tissue, seed=seed)
    x0, _ = _start(m, tg)
    s = rest_state(m)
    e0 = potential_energy(m, x0)
    assert e0 > 0
    energies = []
    for _ in range(60):
        s = step_rk2(m, s, tg, n_steps=5)
        energies.append(potential_energy(m, s.x) + kinetic_energy(m, s.v))
    e = np.array([e0, *energies])
    # 1e-9 E(0): the rounding of the energy sums (~1e-12 relative), far below any real growth
    assert np.all(np.diff(e) <= 1e-9 * e0)
    assert e[-1] < e[0]
    free = m.free_index
    travel = np.linalg.norm(s.x[free] - x0[free], axis=1)
    speed = np.linalg.norm(s.v[free], axis=1)
    v_max = np.sqrt(2.0 * e0 / m.mass[free])
    assert np.all(speed <= v_max)
    assert np.all(travel <= s.t * v_max)
    assert travel.max() > 0.1  # the skin did follow the targets


def test_early_stop_at_the_same_step_as_the_serial_reference(default_tissue):
    """The team kernel tests a step's max |v| dt only once every block has finished it (at the
    start of the next step, or after the run): it stops at the same step as the serial kernel,
    with the same last move, for any number of blocks."""
    m, tg = _step_change(default_tissue, seed=7, amp_mm=1.0)
    x0, v0 = _start(m, tg, seed=7, v_scale=20.0)
    xs, vs = x0.copy(), v0.copy()
    tol = 1e-3  # mm per step: reached after several hundred steps
    ref = run_rk2_serial(m, xs, vs, 20_000, m.stable_dt, tol)
    assert 100 < ref[0] < 20_000 and ref[1] < tol and ref[2] == -1
    for nb in (1, 2, 3):
        x, v = x0.copy(), v0.copy()
        got = run_rk2(m, x, v, 20_000, m.stable_dt, tol, n_blocks=nb)
        assert got[0] == ref[0] and got[2] == -1
        assert got[1] == pytest.approx(ref[1], rel=1e-6)
        np.testing.assert_allclose(x, xs, rtol=0, atol=1e-9 * np.abs(xs - x0).max())
    # a run that ends exactly at the step that reaches the tolerance reports it as the last
    x, v = x0.copy(), v0.copy()
    got = run_rk2(m, x, v, ref[0], m.stable_dt, tol, n_blocks=2)
    assert got[0] == ref[0] and got[1] == pytest.approx(ref[1], rel=1e-6)


def test_default_step_survives_a_step_change_into_the_stiff_phase():
    """Risorius, buccinator, depressor anguli oris and the jaw at 1 from rest: at the rest
    lattice's stable step the explicit scheme blows up (step 28); step_rk2 with its default
    step runs the same time again in halved steps, finite, with energy not growing."""
    import myoface as mf
    from myoface.tissue import kinetic_energy, potential_energy

    fm = mf.build_face_model()
    c = fm.validate(
        {"risorius_l": 1.0, "buccinator_l": 1.0, "depressor_anguli_oris_l": 1.0, "jaw": 1.0}
    )
    s = fm.step(None, c, n_steps=300)
    assert np.isfinite(s.x).all()
    assert s.t == pytest.approx(300 * fm.tissue.stable_dt)
    x0 = fm.tissue.rest_positions.copy()
    x0[fm.tissue.kinematic_index] = fm.targets(c)
    e0 = potential_energy(fm.tissue, x0)
    e1 = potential_energy(fm.tissue, s.x) + kinetic_energy(fm.tissue, s.v)
    assert e1 <= e0 * (1 + 1e-9) + 1e-9
