"""Force kernels: numba vs numpy reference, biphasic law, volume gradient, invariances."""

import numpy as np
import pytest

from myoface.tissue import (
    LAW_CONTINUOUS,
    LAW_PAPER,
    internal_forces,
    make_lattice,
    potential_energy,
)
from myoface.tissue.forces import (
    PRISM_CHUNK,
    PRISM_WORK,
    element_volumes_numpy,
    make_thread_buffers,
    prism_volume_forces_range,
    prism_volume_forces_split,
    spring_energy_numpy,
    spring_forces_numba,
    spring_forces_numpy,
    spring_forces_parallel,
    spring_forces_range,
    volume_energy_numpy,
    volume_forces_numba,
    volume_forces_numpy,
)


def _perturbed(model, scale=0.3, seed=0):
    rng = np.random.default_rng(seed)
    return model.rest_positions + rng.normal(0.0, scale, model.rest_positions.shape)


def _spring_args(m):
    return (m.spring_i, m.spring_j, m.rest_length, m.spring_material, m.materials)


@pytest.mark.parametrize("law", [LAW_CONTINUOUS, LAW_PAPER])
def test_spring_kernel_matches_numpy_reference(default_tissue, law):
    m = default_tissue
    x = _perturbed(m, 1.0)
    ref = spring_forces_numpy(x, *_spring_args(m), law)
    got = np.zeros_like(x)
    spring_forces_numba(x, *_spring_args(m), law, got)
    np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-8 * np.abs(ref).max())
    par = np.zeros_like(x)
    spring_forces_parallel(x, *_spring_args(m), law, par, make_thread_buffers(len(x)))
    np.testing.assert_allclose(par, ref, rtol=1e-10, atol=1e-8 * np.abs(ref).max())


def test_volume_kernel_matches_numpy_reference(default_tissue):
    m = default_tissue
    x = _perturbed(m, 0.5)
    ref = volume_forces_numpy(x, m.elements, m.rest_volume, m.volume_weight, m.volume_sign)
    got = np.zeros_like(x)
    volume_forces_numba(x, m.elements, m.rest_volume, m.volume_weight, m.volume_sign, got)
    np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-8 * np.abs(ref).max())


@pytest.mark.parametrize("law", [LAW_CONTINUOUS, LAW_PAPER])
def test_range_kernels_add_up_to_the_numpy_reference(default_tissue, law):
    """The parallel RK2's kernels over ranges of springs and of prisms (each thread adds its
    own ranges to its own buffer), over two ranges, give the reference forces."""
    m = default_tissue
    x = _perturbed(m, 1.0)
    got = np.zeros_like(x)
    half = m.n_springs // 2
    spring_forces_range(x, *_spring_args(m), law, 0, half, got)
    spring_forces_range(x, *_spring_args(m), law, half, m.n_springs, got)
    ref = spring_forces_numpy(x, *_spring_args(m), law)
    np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-8 * np.abs(ref).max())

    args = (m.elements, m.rest_volume, m.volume_weight, m.volume_sign)
    got = np.zeros_like(x)
    half = m.n_elements // 2
    prism_volume_forces_range(x, *args, 0, half, got)
    prism_volume_forces_range(x, *args, half, m.n_elements, got)
    ref = volume_forces_numpy(x, *args)
    np.testing.assert_allclose(got, ref, rtol=1e-10, atol=1e-8 * np.abs(ref).max())


def test_chunked_prism_kernel_equals_the_range_kernel_bit_for_bit(default_tissue):
    """The RK2's chunked prism kernel (gather, vectorised arithmetic, scatter) computes the same
    numbers and adds them in the same order as the one-pass range kernel: equal to the last bit,
    over ranges that start and end inside a chunk, on a deformed lattice."""
    m = default_tissue
    x = _perturbed(m, 1.0)
    args = (m.elements, m.rest_volume, m.volume_weight, m.volume_sign)
    cuts = [0, 3, 3 + 2 * PRISM_CHUNK + 1, m.n_elements]
    ref = np.zeros_like(x)
    got = np.zeros_like(x)
    work = np.full(PRISM_WORK * PRISM_CHUNK, np.nan)  # stale lanes must not leak into forces
    for e0, e1 in zip(cuts[:-1], cuts[1:], strict=True):
        prism_volume_forces_range(x, *args, e0, e1, ref)
        prism_volume_forces_split(x, *args, e0, e1, got, work)
    assert np.abs(ref).max() > 0
    np.testing.assert_array_equal(got, ref)


def test_energy_matches_numpy_reference(default_tissue):
    m = default_tissue
    x = _perturbed(m, 1.0)
    ref = spring_energy_numpy(x, *_spring_args(m), m.spring_law) + volume_energy_numpy(
        x, m.elements, m.rest_volume, m.volume_weight, m.volume_sign
    )
    assert potential_energy(m, x) == pytest.approx(ref, rel=1e-10)


def test_forces_are_minus_energy_gradient(default_tissue):
    """Spring + volume forces equal the central finite difference of the energy."""
    m = default_tissue
    x = _perturbed(m, 0.5)
    f = internal_forces(m, x)
    rng = np.random.default_rng(1)
    h = 1e-5
    for i in rng.choice(len(x), 8, replace=False):
        for a in range(3):
            xp, xm = x.copy(), x.copy()
            xp[i, a] += h
            xm[i, a] -= h
            fd = -(potential_energy(m, xp) - potential_energy(m, xm)) / (2 * h)
            assert f[i, a] == pytest.approx(fd, rel=1e-5, abs=1e-4)


def test_volume_force_is_finite_difference_gradient_of_Q():
    """q_i = dQ/dx_i (T&W 1993, Section III-B) on a single prism, every coordinate."""
    pos = np.array([[0, 0, 1], [1, 0, 1], [0, 1, 1], [0, 0, 0], [1, 0, 0], [0, 1, 0]], float)
    el = np.array([[0, 1, 2, 3, 4, 5]])
    v0 = element_volumes_numpy(pos, el)
    sign = 1.0 if v0[0] > 0 else -1.0
    assert abs(v0[0]) == pytest.approx(0.5)  # a unit right prism
    rng = np.random.default_rng(0)
    x = pos + rng.normal(0, 0.1, pos.shape)
    kv = np.array([3.0])
    rest = np.abs(v0)
    f = volume_forces_numpy(x, el, rest, kv, sign)
    h = 1e-6
    for i in range(6):
        for a in range(3):
            xp, xm = x.copy(), x.copy()
            xp[i, a] += h
            xm[i, a] -= h
            dq = (
                volume_energy_numpy(xp, el, rest, kv, sign)
                - volume_energy_numpy(xm, el, rest, kv, sign)
            ) / (2 * h)
            assert f[i, a] == pytest.approx(-dq, rel=1e-6, abs=1e-9)


def test_internal_forces_sum_to_zero(default_tissue):
    x = _perturbed(default_tissue, 1.0)
    f = internal_forces(default_tissue, x)
    assert np.abs(f.sum(axis=0)).max() < 1e-9 * np.abs(f).sum()


def test_rigid_motion_gives_no_force(default_tissue):
    m = default_tissue
    rng = np.random.default_rng(3)
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    if np.linalg.det(q) < 0:
        q[:, 0] *= -1
    x = m.rest_positions @ q.T + np.array([12.0, -5.0, 30.0])
    f = internal_forces(m, x)
    scale = np.abs(internal_forces(m, _perturbed(m, 0.01))).max()
    assert np.abs(f).max() < 1e-7 * scale


@pytest.mark.parametrize("law", ["continuous", "paper"])
def test_biphasic_switch(law):
    """Below e^c the spring pulls with alpha e, above it stiffens to beta (eq. 2)."""
    alpha, beta, strain_c, rest = 100.0, 1000.0, 0.1, 10.0
    ec = strain_c * rest
    for e in (0.5 * ec, 0.99 * ec, 1.01 * ec, 3.0 * ec, -2.0 * ec):
        m = make_lattice(
            [[0, 0, 0], [rest, 0, 0]], [[0, 1]], materials=[[alpha, beta, strain_c]], biphasic=law
        )
        x = np.array([[0, 0, 0], [rest + e, 0, 0]], float)
        fx = internal_forces(m, x)[1, 0]
        if e <= ec:
            expected = -alpha * e
        elif law == "paper":
            expected = -beta * e
        else:
            expected = -(alpha * ec + beta * (e - ec))
        assert fx == pytest.approx(expected, rel=1e-12)
    # the stiffness really changes across the threshold: slope just above is beta
    m = make_lattice(
        [[0, 0, 0], [rest, 0, 0]], [[0, 1]], materials=[[alpha, beta, strain_c]], biphasic=law
    )

    def fx(e):
        return internal_forces(m, np.array([[0, 0, 0], [rest + e, 0, 0]], float))[1, 0]

    h = 1e-4
    assert -(fx(0.5 * ec + h) - fx(0.5 * ec)) / h == pytest.approx(alpha, rel=1e-6)
    assert -(fx(2 * ec + h) - fx(2 * ec)) / h == pytest.approx(beta, rel=1e-6)
