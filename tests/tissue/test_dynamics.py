"""Integrators: spring frequency, damping, energy, equilibrium, fixed bone, errors."""

import warnings

import numpy as np
import pytest

from myoface.errors import MyofaceSimulationError, MyofaceValueError
from myoface.tissue import (
    RelaxWarning,
    TissueState,
    kinetic_energy,
    make_lattice,
    potential_energy,
    relax,
    rest_state,
    stable_time_step,
    step_rk2,
    stiffness_matrix,
)


def test_single_spring_oscillates_at_sqrt_k_over_m():
    k, m, rest = 2000.0, 0.05, 5.0
    lat = make_lattice(
        [[0, 0, 0], [rest, 0, 0]],
        [[0, 1]],
        materials=[[k, 10 * k, 10.0]],
        mass=m,
        kinematic=[True, False],
    )
    omega = np.sqrt(k / m)
    dt = (2 * np.pi / omega) / 2000
    s = TissueState(np.array([[0, 0, 0], [rest + 0.1, 0, 0]], float), np.zeros((2, 3)))
    xs = []
    for _ in range(6000):  # three periods
        s = step_rk2(lat, s, dt=dt)
        xs.append(s.x[1, 0] - rest)
    xs = np.array(xs)
    up = np.flatnonzero((xs[:-1] < 0) & (xs[1:] >= 0))
    period = np.diff(up).mean() * dt
    assert 2 * np.pi / period == pytest.approx(omega, rel=2e-3)
    # undamped: the amplitude is kept (RK2 loses very little over three periods at this dt)
    assert np.abs(xs[-2000:]).max() == pytest.approx(0.1, rel=1e-2)


def test_rest_state_is_equilibrium_to_1e9(default_tissue):
    r = relax(default_tissue)
    assert r.converged
    assert np.abs(r.state.x - default_tissue.rest_positions).max() < 1e-9
    s = step_rk2(default_tissue, rest_state(default_tissue), n_steps=50)
    assert np.abs(s.x - default_tissue.rest_positions).max() < 1e-9


def _driven_mouth(model, face):
    """Drive the fascia nodes within 20 mm of the left mouth corner by a smooth displacement."""
    fas = model.layer_nodes("fascia")
    d = np.linalg.norm(model.rest_positions[fas] - face.vertices[291], axis=1)
    near = d < 20
    m2 = model.with_kinematic(fas[near])
    tg = m2.rest_positions[m2.kinematic_index].copy()
    pos = np.searchsorted(m2.kinematic_index, fas[near])
    tg[pos] += np.cos(d[near] / 20 * np.pi / 2)[:, None] * np.array([2.0, 3.0, -1.5])
    return m2, tg


def test_bone_fixed_and_skin_follows(default_tissue, default_face):
    m2, tg = _driven_mouth(default_tissue, default_face)
    r = relax(m2, None, tg)
    assert r.converged
    bone = m2.layer_nodes("bone")
    np.testing.assert_array_equal(r.state.x[bone], m2.rest_positions[bone])
    np.testing.assert_array_equal(r.state.x[m2.kinematic_index], tg)
    move = r.state.x[291] - m2.rest_positions[291]
    assert move[1] > 1.0 and move[0] > 0.5  # the skin above follows the fascia up and out
    s = step_rk2(m2, rest_state(m2), tg, n_steps=200)
    np.testing.assert_array_equal(s.x[bone], m2.rest_positions[bone])


@pytest.mark.slow
def test_implicit_and_rk2_reach_the_same_equilibrium(default_tissue, default_face):
    m2, tg = _driven_mouth(default_tissue, default_face)
    a = relax(m2, None, tg, method="implicit", tol_mm=1e-6)
    b = relax(m2, None, tg, method="rk2", tol_mm=1e-8)
    assert a.converged and b.converged
    assert np.abs(a.state.x - b.state.x).max() < 2e-3
    from myoface.tissue import internal_forces

    x0 = m2.rest_positions.copy()
    x0[m2.kinematic_index] = tg
    f0 = np.abs(internal_forces(m2, x0)[m2.free_index]).max()
    assert a.max_force < 1e-3 * f0 and b.max_force < 1e-3 * f0


def test_damped_energy_never_increases(default_tissue):
    m = default_tissue
    rng = np.random.default_rng(0)
    s = rest_state(m)
    free = m.free_index
    s.x[free] += rng.normal(0, 0.3, (len(free), 3))
    dt = stable_time_step(m)
    energies = []
    for _ in range(300):
        s = step_rk2(m, s, dt=dt)
        energies.append(potential_energy(m, s.x) + kinetic_energy(m, s.v))
    e = np.array(energies)
    assert e[-1] < 0.5 * e[0]
    assert np.all(np.diff(e) <= 1e-9 * e[0])


def test_stiffness_matrix_is_force_jacobian_at_rest(default_tissue):
    from myoface.tissue import internal_forces

    m = default_tissue
    k = stiffness_matrix(m, m.rest_positions)
    rng = np.random.default_rng(2)
    dx = np.zeros_like(m.rest_positions)
    dx[m.free_index] = rng.normal(0, 1e-6, (len(m.free_index), 3))
    df = internal_forces(m, m.rest_positions + dx)[m.free_index].reshape(-1)
    kdx = k @ dx[m.free_index].reshape(-1)
    np.testing.assert_allclose(-df, kdx, rtol=1e-3, atol=1e-6 * np.abs(kdx).max())
    assert abs(k - k.T).max() < 1e-9 * abs(k).max()


def test_rk2_blowup_raises_with_step_index():
    lat = make_lattice(
        [[0, 0, 0], [5, 0, 0]],
        [[0, 1]],
        materials=[[2000.0, 2000.0, 1.0]],
        mass=0.05,
        kinematic=[True, False],
    )
    s = TissueState(np.array([[0, 0, 0], [5.5, 0, 0]], float), np.zeros((2, 3)))
    with pytest.raises(MyofaceSimulationError, match="step"):
        step_rk2(lat, s, dt=1.0, n_steps=5000)


def test_relax_rejects_bad_input(default_tissue):
    with pytest.raises(MyofaceValueError, match="targets must have shape"):
        relax(default_tissue, None, np.zeros((3, 3)))
    bad = default_tissue.rest_positions[default_tissue.kinematic_index].copy()
    bad[0, 0] = np.nan
    with pytest.raises(MyofaceValueError, match="finite"):
        relax(default_tissue, None, bad)
    with pytest.raises(MyofaceValueError, match="method must be one of"):
        relax(default_tissue, method="euler")


def test_unconverged_relax_warns_and_flags(default_tissue, default_face):
    m2, tg = _driven_mouth(default_tissue, default_face)
    with pytest.warns(RelaxWarning):
        r = relax(m2, None, tg, max_iter=2)
    assert not r.converged
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert relax(m2, None, tg).converged
