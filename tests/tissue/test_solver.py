"""The Newton equilibrium solver: kernels against references, equilibrium against the L-BFGS
reference, warm starts, two threads sharing a model, bad input."""

import threading

import numpy as np
import pytest
import scipy.sparse as sp
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.sparse.linalg import spsolve

from myoface.errors import MyofaceValueError
from myoface.tissue import internal_forces, potential_energy, relax, rest_state
from myoface.tissue.hessian import energy_gradient_free, symmetric_matvec
from myoface.tissue.solver import (
    NEWTON_TOL_MM,
    PRECOND_SHIFT,
    diagonal_blocks,
    newton_data,
    pcg,
    sgs_precond,
)

#: the L-BFGS reference is run to this step tolerance (mm); its own error is then ~1e-6 mm,
#: negligible beside the Newton tolerance it is compared with
REFERENCE_TOL_MM = 1e-7


@pytest.fixture(scope="module")
def fm():
    from myoface.model import build_face_model

    return build_face_model()


def _reference(tm, targets, state=None):
    r = relax(tm, state, targets, method="lbfgs", tol_mm=REFERENCE_TOL_MM, max_iter=5000)
    assert r.converged
    return r.state.x


def _perturbed(tm, scale_mm, seed=0):
    rng = np.random.default_rng(seed)
    x = tm.rest_positions.copy()
    x[tm.free_index] += rng.normal(0, scale_mm, (len(tm.free_index), 3))
    return x


def _free_energy_gradient(tm, x):
    pat = newton_data(tm).pattern
    g = np.empty((pat.n_free, 3))
    en = energy_gradient_free(x, pat.springs, pat.prisms, g)
    return en, g.reshape(-1)


def test_energy_gradient_matches_the_reference_kernels(fm):
    """The Newton solver's kernel against the force module's energy and forces: over the
    springs and prisms that touch a free node, so its energy is E less a constant (the same at
    every x with the same kinematic nodes), and its gradient is minus the forces on the free
    nodes."""
    tm = fm.tissue
    # the kinematic nodes moved too (the same way in x and x2), so that the parts between them
    # hold energy
    kin_move = np.random.default_rng(10).normal(0, 0.3, (len(tm.kinematic_index), 3))
    x = _perturbed(tm, 0.5)
    x[tm.kinematic_index] += kin_move
    en = potential_energy(tm, x)
    f = internal_forces(tm, x)
    en_free, g_free = _free_energy_gradient(tm, x)
    # the kernel's gradient is in the pattern's order of the free nodes
    free = newton_data(tm).pattern.free_nodes
    np.testing.assert_array_equal(np.sort(free), tm.free_index)
    np.testing.assert_allclose(g_free, -f[free].reshape(-1), rtol=0, atol=1e-9 * np.abs(f).max())
    x2 = _perturbed(tm, 0.5, seed=7)
    x2[tm.kinematic_index] += kin_move
    en2 = potential_energy(tm, x2)
    en2_free, _ = _free_energy_gradient(tm, x2)
    assert en_free - en2_free == pytest.approx(en - en2, rel=1e-9)
    assert en_free < en  # the constant left out is the energy of the kinematic-only parts


def test_hessian_is_the_jacobian_of_the_gradient(fm):
    """The exact Hessian (unclipped geometric term, full volume term) against central
    differences of the force module's forces, along random directions, at a state far from
    rest (compressed and stretched springs); its product (symmetric storage) against the
    assembled matrix's."""
    tm = fm.tissue
    pat = newton_data(tm).pattern
    x = _perturbed(tm, 0.5, seed=1)
    dvals, lvals = np.empty(9 * pat.n_free), np.empty(9 * pat.nl)
    pat.assemble(x, dvals, lvals)
    h = pat.matrix(dvals, lvals)
    assert abs(h - h.T).max() == 0.0
    free = pat.free_nodes  # the Hessian's order of the free nodes
    eps = 1e-6  # mm: central differences have error O(eps^2) relative to the O(1) terms
    rng = np.random.default_rng(2)
    for _ in range(3):
        v = rng.normal(size=3 * len(free))
        hv = np.empty_like(v)
        symmetric_matvec(pat.lptr, pat.lcol, dvals, lvals, v, hv)
        np.testing.assert_allclose(hv, h @ v, rtol=0, atol=1e-12 * np.abs(hv).max())
        xp, xm = x.copy(), x.copy()
        xp[free] += eps * v.reshape(-1, 3)
        xm[free] -= eps * v.reshape(-1, 3)
        fd = (internal_forces(tm, xm)[free] - internal_forces(tm, xp)[free]).reshape(-1)
        fd /= 2 * eps
        # the energy is piecewise smooth (biphasic springs): a spring within eps of its
        # threshold would make the difference quotient meaningless; at a random state none is
        assert np.abs(hv - fd).max() < 1e-6 * np.abs(fd).max()


def test_rest_factor_solves_the_rest_stiffness(fm):
    tm = fm.tissue
    data = newton_data(tm)
    pat = data.pattern
    dvals, lvals = np.empty(9 * pat.n_free), np.empty(9 * pat.nl)
    pat.assemble(tm.rest_positions, dvals, lvals)
    k = pat.matrix(dvals, lvals)
    # the factor is of K plus a tiny shift (see PRECOND_SHIFT)
    k = (k + PRECOND_SHIFT * k.diagonal().mean() * sp.eye(k.shape[0])).tocsc()
    b = np.random.default_rng(3).normal(size=k.shape[0])
    z = data.precond.solve(b)
    ref = spsolve(k, b)
    # two direct solves of a matrix of condition ~1e5: they agree to ~1e-11 relative
    np.testing.assert_allclose(z, ref, rtol=0, atol=1e-9 * np.abs(ref).max())
    assert sp.issparse(data.coupling) and data.coupling.shape == (
        k.shape[0],
        3 * tm.kinematic.sum(),
    )
    # K_fk: the change of the gradient over the free nodes with the kinematic nodes, at rest
    kin, free, eps = tm.kinematic_index, pat.free_nodes, 1e-6
    v = np.random.default_rng(9).normal(size=(len(kin), 3))
    xp, xm = tm.rest_positions.copy(), tm.rest_positions.copy()
    xp[kin] += eps * v
    xm[kin] -= eps * v
    fd = (internal_forces(tm, xm)[free] - internal_forces(tm, xp)[free]).reshape(-1) / (2 * eps)
    kv = data.coupling @ v.reshape(-1)
    np.testing.assert_allclose(kv, fd, rtol=0, atol=1e-6 * np.abs(fd).max())


@settings(max_examples=3, deadline=None, derandomize=True)
@given(st.data())
def test_newton_equals_the_lbfgs_reference(fm, draw):
    ids = fm.ids
    n_active = draw.draw(st.integers(1, len(ids)), label="active muscles")
    seed = draw.draw(st.integers(0, 2**31 - 1), label="seed")
    rng = np.random.default_rng(seed)
    c = np.zeros(len(ids))
    c[rng.choice(len(ids), n_active, replace=False)] = rng.uniform(0, 1, n_active)
    tm = fm.tissue
    tg = fm.targets(c)
    r = relax(tm, None, tg)
    assert r.converged and r.method == "newton"
    ref = _reference(tm, tg)
    # converged means the last Newton step - the estimate of the distance to the equilibrium,
    # taken - moved no node by NEWTON_TOL_MM: the result is within that of the equilibrium
    if np.abs(r.state.x - ref).max() >= NEWTON_TOL_MM:
        # the energy is not convex (compressed springs, the volume penalty): for some
        # contractions there is more than one equilibrium (e.g. 25 muscles, seed 141 with the
        # working tree's muscle set of 2026-11-30: two minima 0.81 mm apart, 480 nJ apart),
        # and the two solvers may find different ones. Then the Newton result must be one (the
        # reference started there stays within the tolerance) and no higher than the reference's
        there = relax(
            tm, r.state, tg, method="lbfgs", tol_mm=REFERENCE_TOL_MM, max_iter=5000
        ).state.x
        assert np.abs(r.state.x - there).max() < NEWTON_TOL_MM
        assert potential_energy(tm, there) <= potential_energy(tm, ref)
    np.testing.assert_array_equal(r.state.x[tm.kinematic_index], tg)
    # the solver reports the force at its last iterate, the one it returns
    f = np.abs(internal_forces(tm, r.state.x)[tm.free_index]).max()
    assert r.max_force == pytest.approx(f, rel=1e-9, abs=1e-9 * np.abs(tg).max())


@settings(max_examples=3, deadline=None, derandomize=True)
@given(st.data())
def test_newton_from_a_random_equilibrium_equals_the_lbfgs_reference(fm, draw):
    """Warm starts: from the equilibrium of random contractions to a random change of them (a
    frame of an animation or a jump), the same equilibrium as the reference from that start."""
    ids = fm.ids
    seed = draw.draw(st.integers(0, 2**31 - 1), label="seed")
    step = draw.draw(st.sampled_from([0.02, 0.1, 0.5]), label="largest change")
    rng = np.random.default_rng(seed)
    c0 = rng.uniform(0, 1, len(ids)) * (rng.uniform(size=len(ids)) < 0.3)
    c1 = np.clip(c0 + rng.uniform(-step, step, len(ids)), 0, 1)
    tm = fm.tissue
    start = relax(tm, None, fm.targets(c0)).state
    tg = fm.targets(c1)
    r = relax(tm, start, tg)
    assert r.converged
    assert np.abs(r.state.x - _reference(tm, tg, start)).max() < NEWTON_TOL_MM


def test_gauss_seidel_preconditioner_is_the_symmetric_sweep(fm):
    """z = (D + L^T)^-1 D (D + L)^-1 r with the Hessian's blocks, against dense triangular
    solves; symmetric positive definite; the rest stiffness's diagonal block where the
    Hessian's is not positive definite."""
    tm = fm.tissue
    data = newton_data(tm)
    pat = data.pattern
    nf = pat.n_free
    dvals, lvals = np.empty(9 * nf), np.empty(9 * pat.nl)
    pat.assemble(_perturbed(tm, 0.5, seed=4), dvals, lvals)
    dvals[9 * 5 : 9 * 6] *= -1.0  # node 5's block made negative definite
    dused, dinv = np.empty(9 * nf), np.empty(9 * nf)
    diagonal_blocks(dvals, data.rest_diag, dused, dinv, np.empty(9 * nf))
    np.testing.assert_array_equal(dused[9 * 5 : 9 * 6], data.rest_diag[9 * 5 : 9 * 6])
    np.testing.assert_array_equal(dused[: 9 * 5], dvals[: 9 * 5])
    d = sp.block_diag(dused.reshape(-1, 3, 3)).toarray()
    np.testing.assert_allclose(
        sp.block_diag(dinv.reshape(-1, 3, 3)).toarray() @ d, np.eye(3 * nf), atol=1e-9
    )
    lo = sp.bsr_matrix(
        (lvals.reshape(-1, 3, 3), pat.lcol, pat.lptr), shape=(3 * nf, 3 * nf)
    ).toarray()
    rng = np.random.default_rng(5)
    r, v = rng.normal(size=3 * nf), rng.normal(size=3 * nf)

    def apply(b):
        z, w = np.empty(3 * nf), np.empty(3 * nf)
        sgs_precond(pat.lptr, pat.lcol, dused, lvals, dinv, b, z, w)
        return z

    # block triangular (full 3x3 diagonal blocks): general dense solves
    ref = np.linalg.solve(d + lo.T, d @ np.linalg.solve(d + lo, r))
    z = apply(r)
    np.testing.assert_allclose(z, ref, rtol=0, atol=1e-10 * np.abs(ref).max())
    assert v @ z == pytest.approx(r @ apply(v), rel=1e-10)
    assert r @ z > 0


def test_warm_start_from_a_nearby_equilibrium_takes_few_iterations(fm):
    from myoface.control import au_contractions

    tm = fm.tissue
    tg0 = fm.targets(au_contractions({12: 0.5, 6: 0.25}, fm.ids))
    tg1 = fm.targets(au_contractions({12: 0.505, 6: 0.2525}, fm.ids))
    start = relax(tm, None, tg0, tol_mm=1e-4).state
    cold = relax(tm, None, tg1)
    warm = relax(tm, start, tg1)
    assert warm.converged and cold.converged
    # a 0.5 % step of the smile moves the free nodes by ~0.06 mm, six times the tolerance: the
    # linear response to the move of the targets plus a Newton step or two (the biphasic springs
    # near their threshold slow it) reach it, and the test of the tolerance takes one more step;
    # the cold start needs more than that to find the nonlinear regime
    assert warm.iterations <= 4 and warm.iterations < cold.iterations
    assert np.abs(warm.state.x - _reference(tm, tg1, start)).max() < NEWTON_TOL_MM


def test_two_threads_sharing_a_model_get_the_single_thread_results(fm):
    from myoface.control import expression_contractions

    # a fresh copy of the model, so the two threads also race to build its cached factor
    tm = fm.tissue.with_kinematic(fm.tissue.kinematic_index)
    targets = [
        fm.targets(expression_contractions("surprise", 1.0, fm.ids)),
        fm.targets(expression_contractions("happiness", 1.0, fm.ids)),
    ]
    out = [None, None]
    barrier = threading.Barrier(2)

    def work(k):
        barrier.wait()
        for _ in range(3):
            out[k] = relax(tm, None, targets[k]).state.x

    threads = [threading.Thread(target=work, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for k in range(2):
        single = relax(fm.tissue, None, targets[k]).state.x
        np.testing.assert_array_equal(out[k], single)


def test_non_finite_targets_or_start_raise(fm):
    tm = fm.tissue
    tg = tm.rest_positions[tm.kinematic_index].copy()
    for bad in (np.nan, np.inf):
        t = tg.copy()
        t[3, 1] = bad
        with pytest.raises(MyofaceValueError, match="finite"):
            relax(tm, None, t)
    s = rest_state(tm)
    s.x[tm.free_index[0], 0] = np.nan
    with pytest.raises(MyofaceValueError, match="finite"):
        relax(tm, s, tg)
    with pytest.raises(MyofaceValueError, match="tol_mm"):
        relax(tm, None, tg, tol_mm=0.0)


def test_implicit_is_an_alias_of_newton(fm):
    tm = fm.tissue
    tg = fm.targets(np.full(len(fm.ids), 0.3))
    a = relax(tm, None, tg, method="implicit")
    b = relax(tm, None, tg, method="newton")
    assert a.method == b.method == "newton"
    np.testing.assert_array_equal(a.state.x, b.state.x)


def test_pcg_in_eisenstats_form_is_the_preconditioned_cg(fm):
    """The solver's CG (no product with H, Eisenstat's form) against the textbook preconditioned
    CG with the Gauss-Seidel sweep and the Hessian's product: the same iterates, iteration
    count and solution, on a Newton system."""
    tm = fm.tissue
    data = newton_data(tm)
    pat = data.pattern
    nf = pat.n_free
    # a Newton system near an equilibrium: a smile's, with the targets of a stronger one
    x = relax(tm, None, fm.targets(np.full(len(fm.ids), 0.3))).state.x
    x[tm.kinematic_index] = fm.targets(np.full(len(fm.ids), 0.35))
    dvals, lvals = np.empty(9 * nf), np.empty(9 * pat.nl)
    pat.assemble(x, dvals, lvals)
    dused, dinv = np.empty(9 * nf), np.empty(9 * nf)
    diagonal_blocks(dvals, data.rest_diag, dused, dinv, np.empty(9 * nf))
    _, b = _free_energy_gradient(tm, x)
    b = -b
    eta = 0.05
    out = np.empty(3 * nf)
    k, curved = pcg(
        pat.lptr,
        pat.lcol,
        dused,
        lvals,
        dinv,
        2 * dused - dvals,
        b,
        eta,
        200,
        out,
        np.empty((7, 3 * nf)),
    )

    def precond(r):
        z, w = np.empty(3 * nf), np.empty(3 * nf)
        sgs_precond(pat.lptr, pat.lcol, dused, lvals, dinv, r, z, w)
        return z

    def hess(v):
        o = np.empty(3 * nf)
        symmetric_matvec(pat.lptr, pat.lcol, dvals, lvals, v, o)
        return o

    ref, r = np.zeros(3 * nf), b.copy()
    z = precond(r)
    p, rz = z.copy(), r @ z
    stop = eta * eta * rz
    it = 0
    while it < 200:
        it += 1
        q = hess(p)
        assert p @ q > 0  # no negative curvature on this system
        a = rz / (p @ q)
        ref += a * p
        r -= a * q
        z = precond(r)
        if r @ z <= stop:
            break
        rz, p = r @ z, z + (r @ z) / rz * p
    assert (k, curved) == (it, 0)
    np.testing.assert_allclose(out, ref, rtol=0, atol=1e-9 * np.abs(ref).max())


def test_extrapolated_start_repeats_the_last_move_along_the_new_one(fm):
    """The start state's last move is repeated for the part of the new kinematic move along
    its own, and only that part is left for the linear response; an unrelated move (orthogonal
    to the last) changes nothing; a reversed move returns the free nodes to where they were."""
    from myoface.tissue.solver import extrapolated_start

    tm = fm.tissue
    kin, free = tm.kinematic_index, tm.free_index
    rng = np.random.default_rng(6)
    previous = tm.rest_positions.copy()
    start = previous.copy()
    start[kin] += rng.normal(0, 0.3, (len(kin), 3))
    start[free] += rng.normal(0, 0.3, (len(free), 3))
    last = start - previous
    for a in (1.0, 0.5, -1.0):
        x = start.copy()
        x[kin] = start[kin] + a * last[kin]
        rest_of_move = extrapolated_start(tm, x, start[kin], previous)
        np.testing.assert_allclose(x[free], start[free] + a * last[free], rtol=0, atol=1e-12)
        np.testing.assert_allclose(rest_of_move, 0.0, rtol=0, atol=1e-12)
    # a new move orthogonal to the last one (over the kinematic nodes): no extrapolation
    other = rng.normal(0, 0.3, (len(kin), 3))
    other -= np.vdot(other, last[kin]) / np.vdot(last[kin], last[kin]) * last[kin]
    x = start.copy()
    x[kin] = start[kin] + other
    rest_of_move = extrapolated_start(tm, x, start[kin], previous)
    np.testing.assert_allclose(x[free], start[free], rtol=0, atol=1e-12)
    np.testing.assert_allclose(rest_of_move, other, rtol=0, atol=1e-12)


def test_relaxed_states_carry_where_they_came_from(fm):
    """A relax's state records the positions it started from (the next relax extrapolates that
    move); a state made by RK2 steps records none; a smile relaxed frame by frame from those
    states lands on the reference's equilibria."""
    from myoface.control import au_contractions

    s0 = fm.rest_state()
    r1 = fm.relax(au_contractions({12: 0.2, 6: 0.1}, fm.ids), s0)
    np.testing.assert_array_equal(r1.state.previous_x, s0.x)
    assert not r1.state.previous_x.flags.writeable
    assert fm.step(r1.state, r1.state.contractions).previous_x is None
    tm = fm.tissue
    state = r1.state
    for k in (1, 2, 3):
        c = au_contractions({12: 0.2 + 0.04 * k, 6: 0.1 + 0.02 * k}, fm.ids)
        start = state
        r = fm.relax(c, start)
        assert r.converged
        ref = _reference(tm, fm.targets(c), start.tissue_state())
        assert np.abs(r.state.x - ref).max() < NEWTON_TOL_MM
        state = r.state


def test_energy_gradient_hessian_in_one_pass_equals_the_separate_kernels(fm):
    """The Newton loop's fused pass (energy, gradient, the springs' and the prisms' Hessians)
    against the energy-gradient kernel and the separate assemblies, at a state far from rest."""
    from myoface.tissue.hessian import (
        add_prism_hessian,
        add_spring_hessian,
        energy_gradient_hessian,
    )

    tm = fm.tissue
    pat = newton_data(tm).pattern
    nf = pat.n_free
    x = _perturbed(tm, 0.5, seed=8)
    en, g = _free_energy_gradient(tm, x)
    dp, lp = np.zeros(9 * nf), np.zeros(9 * pat.nl)
    add_prism_hessian(x, pat.prisms, dp, lp)
    ds, ls = np.zeros(9 * nf), np.zeros(9 * pat.nl)
    add_spring_hessian(x, pat.springs, ds, ls)
    d2, l2 = np.empty(9 * nf), np.empty(9 * pat.nl)
    dp2, lp2 = np.empty(9 * nf), np.empty(9 * pat.nl)
    g2 = np.empty((nf, 3))
    en2 = energy_gradient_hessian(x, pat.springs, pat.prisms, g2, True, d2, l2, True, dp2, lp2)
    # the same sums (fastmath may contract them differently: rounding only)
    assert en2 == pytest.approx(en, rel=1e-12)
    for got, ref in ((g2.reshape(-1), g), (dp2, dp), (lp2, lp), (d2, ds + dp), (l2, ls + lp)):
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-10 * np.abs(ref).max())
    # and that is the pattern's assembly
    dref, lref = np.empty(9 * nf), np.empty(9 * pat.nl)
    pat.assemble(x, dref, lref)
    np.testing.assert_allclose(d2, dref, rtol=0, atol=1e-10 * np.abs(dref).max())
    np.testing.assert_allclose(l2, lref, rtol=0, atol=1e-10 * np.abs(lref).max())
    # without a new prisms' part: the springs' plus the one given
    d3, l3 = np.empty(9 * nf), np.empty(9 * pat.nl)
    g3 = np.empty((nf, 3))
    en3 = energy_gradient_hessian(x, pat.springs, pat.prisms, g3, True, d3, l3, False, dp2, lp2)
    np.testing.assert_array_equal(d3, d2)
    np.testing.assert_array_equal(l3, l2)
    # (and then the prisms' energy and gradient come from their vectorised pass: the same sums)
    assert en3 == pytest.approx(en, rel=1e-12)
    np.testing.assert_allclose(g3.reshape(-1), g, rtol=0, atol=1e-10 * np.abs(g).max())


def test_a_warm_start_past_newtons_basin_falls_back_to_rest():
    """A state the 3-D fit met on a real video (a face coming back into the frame, its
    contractions jumping): the start extrapolated from its last move led Newton's line search
    to stall with 2e95 uN left and nodes at 1e19 mm, reported as converged. Now it is not
    taken for an equilibrium, and the relax falls back to the start from rest. (With the face and
    tissue of 2026-12-02 Newton converges from this state; the next test forces the fallback.)"""
    import warnings

    from tests.conftest import REPO

    import myoface as mf
    from myoface._io import parse_toml
    from myoface.face import default_mirror_map, load_default_face
    from myoface.model import FaceState
    from myoface.muscles.io import muscles_from_dict
    from myoface.tissue import solver

    data = REPO / "tests" / "data"
    d = np.load(data / "warm_start_past_the_basin.npz")
    # the muscle set the state was recorded with (the bundled file as of 2026-12-02, 35 muscles),
    # so the state stays a state of this model however the default set changes
    face = load_default_face()
    pinned = data / "warm_start_past_the_basin.muscles.toml"
    doc = parse_toml(pinned.read_text(), str(pinned))
    fm = mf.build_face_model(face, muscles_from_dict(doc, face, mirror=default_mirror_map()))
    c = d["contractions"]
    assert len(c) == len(fm.ids)
    st = FaceState(d["x"], np.zeros_like(d["x"]), d["state_contractions"], 0.0, d["previous_x"])
    t = fm.tissue
    x = st.x.copy()
    x[t.kinematic_index] = fm.targets(fm.validate(c))
    x_new, ok, *_, fmax = solver.relax_newton(
        t, x, st.x[t.kinematic_index], 0.01, 50, previous_x=st.previous_x
    )
    assert not (ok and np.abs(x_new).max() > 1e3)  # never a blown-up "equilibrium"
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # and the relax converges (from rest)
        res = fm.relax(c, st)
    ref = fm.relax(c)
    assert res.converged and np.isfinite(res.state.x).all()
    np.testing.assert_allclose(res.state.x, ref.state.x, atol=0.02)


def test_a_warm_start_far_outside_newtons_basin_falls_back_to_rest():
    """The recorded state above no longer leads today's Newton astray (the face and tissue have
    changed since it was recorded), so the fallback is also exercised on a start that must fail:
    every node 1e8 mm off. Newton does not report it converged, and relax falls back to the
    start from rest, giving exactly the response from rest."""
    import warnings

    import myoface as mf
    from myoface.model import FaceState
    from myoface.tissue import solver

    fm = mf.build_face_model()
    c = np.zeros(len(fm.ids))
    c[fm.ids.index("zygomaticus_major_l")] = 0.8
    ref = fm.relax(c)
    x = ref.state.x + np.random.default_rng(0).normal(0.0, 1e8, ref.state.x.shape)
    st = FaceState(x, np.zeros_like(x), np.zeros_like(c), 0.0, x.copy())
    t = fm.tissue
    x0 = x.copy()
    x0[t.kinematic_index] = fm.targets(fm.validate(c))
    _, ok, *_ = solver.relax_newton(t, x0, x[t.kinematic_index], 0.01, 50, previous_x=x)
    assert not ok  # the scenario is the one named: Newton alone does not get there
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        res = fm.relax(c, st)
    assert res.converged
    np.testing.assert_allclose(res.state.x, ref.state.x, atol=1e-9)
