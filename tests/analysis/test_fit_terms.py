"""The 3-D fit's energy: each term's normal equations are its cost's derivatives, the solver
minimises the sum of whatever terms it is given, and the compiled pieces (the box-constrained
step, the vertex normals) agree with their references."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.linalg import cho_factor, solve_triangular
from scipy.optimize import lsq_linear

from myoface.analysis._fitkernels import box_qp, vertex_normals
from myoface.analysis.camera import HeadPose, rotmat
from myoface.analysis.modelfit import FrameFit, ModelFit
from myoface.analysis.solver import bounded_gauss_newton
from myoface.analysis.terms import (
    Estimate,
    LandmarkTerm,
    MagnitudePrior,
    OpticalFlowTerm,
    SparsityPrior,
    SymmetryPrior,
    TemporalPrior,
    mirror_pairs,
    patch_footprint,
)
from tests.analysis.test_fit import CAMERA, landmarks


@pytest.fixture(scope="module")
def frame():
    """A ModelFit, a frame of posed landmarks with noise and MediaPipe-like depth, an estimate
    away from the truth (pose off by a few degrees, contractions off) and a previous frame."""
    from myoface.model import build_face_model

    fm = build_face_model()
    fit = ModelFit(fm, CAMERA)
    rng = np.random.default_rng(3)
    c_true = rng.uniform(0, 0.6, fit.n_muscles) * (rng.uniform(size=fit.n_muscles) < 0.5)
    truth = HeadPose.from_euler(12.0, -6.0, 4.0, (5.0, -3.0, -520.0))
    p = landmarks(fit.shape(c_true), truth) + rng.normal(0, 0.7, (len(fit.neutral), 3))
    pose = HeadPose.from_euler(9.0, -4.0, 6.0, (2.0, 0.0, -500.0))
    c = np.clip(c_true + rng.normal(0, 0.1, fit.n_muscles), 0.05, 0.95)
    prev = FrameFit(c_true, truth, 0.5, 1, True)
    return fit, p, pose, c, prev


def _estimate(fit, pose, c, free):
    jac = np.ascontiguousarray(fit.response)
    return Estimate(pose, c, fit.shape(c), jac, np.asarray(free, dtype=np.int64))


def _moved(fit, est, x):
    """The estimate after the step ``x`` (omega, dt, dc[free])."""
    pose = HeadPose(rotmat(x[:3]) @ est.pose.rotation, est.pose.translation_mm + x[3:6])
    c = est.contractions.copy()
    c[est.free] += x[6:]
    return Estimate(pose, c, fit.shape(c), est.jac, est.free)


def _footprint(fit, pose, half=5):
    """(F, base) of 11-px patches where ``pose`` puts ``fit``'s neutral (no gap)."""
    base = fit.neutral + fit.identity_mm
    pc = pose.apply(base)
    return patch_footprint(CAMERA.project(pc), -pc[:, 2], fit.model.face.triangles, half), base


def _terms(fit, p, prev, huber):
    s = fit.settings
    w0 = fit.base_weights
    rng = np.random.default_rng(11)
    tracked = rng.uniform(size=len(p)) < 0.6
    moved = p[:, :2] + rng.normal(0, 0.5, (len(p), 2))
    return {
        "landmarks": LandmarkTerm(p, CAMERA, w0, s.landmark_sigma_mm, s.depth_sigma_mm, huber),
        # the landmarks' x, y left to the flow where it tracked, their depth kept
        "landmarks_beside_flow": LandmarkTerm(
            p, CAMERA, w0, s.landmark_sigma_mm, s.depth_sigma_mm, huber, xy_weights=~tracked
        ),
        # the detector reading the skin's motion from the neutral at a gain of 0.6
        "landmarks_at_gain": LandmarkTerm(
            p,
            CAMERA,
            w0,
            s.landmark_sigma_mm,
            s.depth_sigma_mm,
            huber,
            gain=(0.6, fit.neutral + fit.identity_mm),
        ),  # fmt: skip
        "flow": OpticalFlowTerm(moved, tracked, CAMERA, w0, s.landmark_sigma_mm, huber),
        # each point against the model's motion averaged over its patch
        "flow_footprint": OpticalFlowTerm(
            moved,
            tracked,
            CAMERA,
            w0,
            s.landmark_sigma_mm,
            huber,
            footprint=_footprint(fit, prev.pose),
        ),  # fmt: skip
        "temporal": TemporalPrior(
            prev, 1 / 30, s.rotation_rate_deg_per_s, s.translation_rate_mm_per_s, s.rate_per_s
        ),
        "magnitude": MagnitudePrior(s.magnitude_sigma),
        "sparsity": SparsityPrior(s.sparsity),
        "sparsity_concave": SparsityPrior(s.sparsity, knee=0.2),
        # each muscle its own weight (FitSettings.sparsity_reach)
        "sparsity_scaled": SparsityPrior(s.sparsity, scale=_scale(fit)),
        "sparsity_concave_scaled": SparsityPrior(s.sparsity, knee=0.2, scale=_scale(fit)),
        # the two sides alike: quadratic, and Cauchy's (FitSettings.symmetry_scale)
        "symmetry": SymmetryPrior(mirror_pairs(fit.model.ids), 0.1),
        "symmetry_robust": SymmetryPrior(mirror_pairs(fit.model.ids), 0.1, scale=0.2),
    }


def _scale(fit) -> np.ndarray:
    return np.linspace(0.25, 3.0, fit.n_muscles)


@pytest.mark.parametrize(
    "name",
    [
        "landmarks",
        "landmarks_beside_flow",
        "landmarks_at_gain",
        "flow",
        "flow_footprint",
        "temporal",
        "magnitude",
        "sparsity",
        "sparsity_concave",
        "sparsity_scaled",
        "sparsity_concave_scaled",
        "symmetry",
        "symmetry_robust",
    ],  # fmt: skip
)
@pytest.mark.parametrize("use_depth", [True, False])
@pytest.mark.parametrize("n_free", [0, 7, None])
def test_a_terms_normal_equations_give_its_costs_gradient(frame, name, use_depth, n_free):
    """For every term, ``b = -J^T r`` is minus half the gradient of its cost in the step's
    unknowns (central differences along random directions), and ``H`` is symmetric positive
    semi-definite: the term's contract with the solver. The landmarks without Huber's
    reweighting (whose weights are held at the step's start, as iteratively reweighted least
    squares does)."""
    fit, p, pose, c, prev = frame
    if not use_depth:
        p = np.column_stack([p[:, :2], np.full(len(p), np.nan)])
    free = np.arange(fit.n_muscles if n_free is None else n_free)
    est = _estimate(fit, pose, c, free)
    term = _terms(fit, p, prev, huber=np.inf)[name]
    term.prepare(est)
    h, b = term.normal_equations(est)
    n = est.n_unknowns
    assert h.shape == (n, n) and b.shape == (n,)
    np.testing.assert_allclose(h, h.T, atol=1e-9 * (1 + np.abs(h).max()))
    assert np.linalg.eigvalsh(h).min() >= -1e-8 * (1 + np.abs(h).max())
    rng = np.random.default_rng(7)
    for _ in range(3):
        d = rng.normal(size=n)
        d[:3] *= 1e-3  # radians
        eps = 1e-5
        slope = (term.cost(_moved(fit, est, eps * d)) - term.cost(_moved(fit, est, -eps * d))) / (
            2 * eps
        )
        assert slope == pytest.approx(-2 * b @ d, rel=1e-5, abs=1e-6 * (1 + abs(b @ d)))


def test_the_landmark_term_at_a_gain_reads_the_motion_scaled_from_the_neutral(frame):
    """At gain g the term's cost at an estimate is the plain term's at the skin whose motion
    from the neutral is g times the estimate's (the head's pose as it is), and its rows in
    the contractions are g times the plain term's there: a detector that reads g of the
    skin's motion agrees with the model moving in full."""
    fit, p, pose, c, _ = frame
    s = fit.settings
    base = fit.neutral + fit.identity_mm
    est = _estimate(fit, pose, c, np.arange(fit.n_muscles))
    seen = Estimate(pose, c, base + 0.6 * (est.shape - base), 0.6 * est.jac, est.free)
    args = (p, CAMERA, fit.base_weights, s.landmark_sigma_mm, s.depth_sigma_mm, np.inf)
    at_gain, plain = LandmarkTerm(*args, gain=(0.6, base)), LandmarkTerm(*args)
    for t in (at_gain, plain):
        t.prepare(est)
    assert at_gain.cost(est) == pytest.approx(plain.cost(seen), rel=1e-12)
    assert not at_gain.cost(est) == pytest.approx(plain.cost(est), rel=1e-3)
    for a, b in zip(at_gain.normal_equations(est), plain.normal_equations(seen), strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-10, atol=1e-12)
    # (gain 1: the plain term itself)
    assert LandmarkTerm(*args, gain=(1.0, base)).gain is None


def test_the_landmark_terms_huber_weights_hold_outliers(frame):
    """With Huber's threshold, a point far off (beyond it) adds to the cost linearly, not
    quadratically: moving one landmark 10x farther raises the cost about 10x, not 100x."""
    fit, p, pose, c, prev = frame
    est = _estimate(fit, pose, c, np.arange(fit.n_muscles))
    s = fit.settings

    def cost_with(offset):
        q = p.copy()
        q[0, 0] += offset
        t = LandmarkTerm(q, CAMERA, fit.base_weights, s.landmark_sigma_mm, s.depth_sigma_mm, 1.5)
        t.prepare(est)
        return t.cost(est)

    base = cost_with(0.0)
    d1, d10 = cost_with(40.0) - base, cost_with(400.0) - base
    assert 8 < d10 / d1 < 12


def test_the_flow_term_takes_the_landmarks_place_where_it_tracked(frame):
    """The landmarks with their x, y left to the flow where it tracked, plus the flow's term,
    cost what the landmarks cost at the points where the flow put them (the depth rows stay
    MediaPipe's): the flow is a term of its own, and adds nothing where it did not track."""
    fit, p, pose, c, prev = frame
    est = _estimate(fit, pose, c, np.arange(fit.n_muscles))
    s = fit.settings
    rng = np.random.default_rng(4)
    tracked = rng.uniform(size=len(p)) < 0.5
    xy = p[:, :2] + rng.normal(0, 0.8, (len(p), 2))
    seen = p.copy()
    seen[tracked, :2] = xy[tracked]
    args = (CAMERA, fit.base_weights, s.landmark_sigma_mm, s.depth_sigma_mm, np.inf)
    whole = LandmarkTerm(seen, *args)
    parts = [
        LandmarkTerm(p, *args, xy_weights=~tracked),
        OpticalFlowTerm(xy, tracked, CAMERA, fit.base_weights, s.landmark_sigma_mm, np.inf),
    ]
    for t in (whole, *parts):
        t.prepare(est)
    assert sum(t.cost(est) for t in parts) == pytest.approx(whole.cost(est), rel=1e-12)
    h = sum(t.normal_equations(est)[0] for t in parts)
    np.testing.assert_allclose(h, whole.normal_equations(est)[0], rtol=1e-9, atol=1e-9)
    none = OpticalFlowTerm(xy, np.zeros(len(p), bool), *args[:3], np.inf)
    none.prepare(est)
    assert none.cost(est) == 0.0


def test_a_patch_footprint_averages_a_field_over_the_patch():
    """:func:`patch_footprint` on a regular grid of triangles: rows sum to 1; a field linear
    in the image (a patch's mean is its centre's) is left as it is; a field that peaks at a
    vertex (a tent) is averaged to the tent's mean over the patch (computed here in closed
    form); a patch reaching off the mesh keeps its vertex; pixels inside the gap's polygon
    do not count."""
    n, step, half = 9, 10.0, 3
    g = np.stack(np.meshgrid(np.arange(n), np.arange(n)), -1).reshape(-1, 2) * step
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = (
        idx[:-1, :-1].ravel(),
        idx[:-1, 1:].ravel(),
        idx[1:, :-1].ravel(),
        idx[1:, 1:].ravel(),
    )
    tri = np.concatenate([np.column_stack([a, b, d]), np.column_stack([a, d, c])])
    f = patch_footprint(g, np.ones(len(g)), tri, half)
    np.testing.assert_allclose(np.asarray(f.sum(1)).ravel(), 1.0, atol=1e-12)
    inner = (g.min(1) >= step) & (g.max(1) <= (n - 2) * step)
    lin = g @ np.array([0.3, -0.7]) + 2.0
    np.testing.assert_allclose((f @ lin)[inner], lin[inner], atol=1e-9)
    # a tent at the centre vertex: on this mesh (diagonals a-d) the field is linear per
    # triangle, its mean over the square patch the mean of max(0, 1 - ...) at the pixels
    centre = int(idx[n // 2, n // 2])
    tent = np.zeros(len(g))
    tent[centre] = 1.0
    o = np.arange(-half, half + 1) / step
    x, y = np.meshgrid(o, o)
    # the barycentric hat of a vertex on this triangulation
    hat = np.where(x * y >= 0, 1 - np.maximum(np.abs(x), np.abs(y)), 1 - np.abs(x) - np.abs(y))
    assert (f @ tent)[centre] == pytest.approx(np.clip(hat, 0, None).mean(), rel=1e-9)
    assert (f @ tent)[centre] < 0.9  # (short of the peak)
    # off the mesh: the corner vertex keeps itself
    assert f[0, 0] == 1.0 and f[0].nnz == 1
    # a gap around the centre's right neighbour: its pixels left out, the patch still used
    right = int(idx[n // 2, n // 2 + 1])
    box = g[right] + np.array([[-2.5, -2.5], [2.5, -2.5], [2.5, 2.5], [-2.5, 2.5]])
    fg = patch_footprint(g, np.ones(len(g)), tri, half, gap=box)
    np.testing.assert_allclose((fg @ lin)[centre], lin[centre], atol=1e-9)  # (untouched)
    assert fg[right].nnz > 1 and fg[right, right] != f[right, right]
    np.testing.assert_allclose(fg.sum(1), 1.0, atol=1e-12)


def test_the_flow_term_with_footprints_reads_a_patchs_motion_at_gain_one(frame):
    """A patch tracker reads the mean motion of its patch (short of the motion at its
    vertex where the motion peaks). Given points that moved exactly so (the model's motion
    at known contractions averaged over each point's patch), the fit whose flow term knows
    the patches finds the contractions; read at the vertices, the same points give a fit
    whose skin moves less (the shortfall :class:`OpticalFlowTerm` describes)."""
    fit, p, pose, c, prev = frame
    s = fit.settings
    m = fit.n_muscles
    truth = prev.pose
    c_true = np.zeros(m)
    for mid, v in (("zygomaticus_major_l", 0.6), ("zygomaticus_major_r", 0.6),
                   ("frontalis_inner_l", 0.5), ("frontalis_inner_r", 0.5)):  # fmt: skip
        c_true[fit.ids.index(mid)] = v
    fmat, base = _footprint(fit, truth, half=5)
    seen = base + fmat @ (fit.shape(c_true) - base)
    xy = CAMERA.project(truth.apply(seen))
    tracked = np.ones(len(xy), dtype=bool)
    free = np.arange(m)
    jac = np.ascontiguousarray(fit.response)
    out = {}
    for name, fp in (("patch", (fmat, base)), ("vertex", None)):
        flow = OpticalFlowTerm(xy, tracked, CAMERA, fit.base_weights, s.landmark_sigma_mm,
                               s.huber, footprint=fp)  # fmt: skip
        pose_f, c_f, _, _ = bounded_gauss_newton([flow], fit.shape, jac, truth, np.zeros(m),
                                                 free, 40)  # fmt: skip
        d_true = fit.shape(c_true) - base
        d_fit = fit.shape(c_f) - base
        moving = np.linalg.norm(d_true, axis=1) > 1.0
        out[name] = float((d_fit[moving] * d_true[moving]).sum() / (d_true[moving] ** 2).sum())
    assert out["patch"] == pytest.approx(1.0, abs=0.03)
    assert out["vertex"] < out["patch"] - 0.05


def test_the_solver_sums_any_terms_it_is_given(frame):
    """Adding an observation is adding a term: a term of our own (one contraction held at 0.3
    by a stiff quadratic) added to the landmark fit moves that contraction there, leaves the
    rest of the fit working, and the result is the minimum the solver reports converged."""
    fit, p, pose, c, prev = frame
    m = fit.ids.index("zygomaticus_major_l")

    class HoldAt:
        def prepare(self, est):
            pass

        def normal_equations(self, est):
            n = est.n_unknowns
            h, b = np.zeros((n, n)), np.zeros(n)
            j = int(np.flatnonzero(est.free == m)[0]) + 6
            h[j, j] = 1e6
            b[j] = -1e6 * (est.contractions[m] - 0.3)
            return h, b

        def cost(self, est):
            return 1e6 * (est.contractions[m] - 0.3) ** 2

    free = np.arange(fit.n_muscles)
    jac = np.ascontiguousarray(fit.response)
    lm = _terms(fit, p, prev, huber=1.5)["landmarks"]
    plain = bounded_gauss_newton([lm], fit.shape, jac, pose, c, free, 30)
    held = bounded_gauss_newton([HoldAt(), lm], fit.shape, jac, pose, c, free, 30)
    assert held[1][m] == pytest.approx(0.3, abs=1e-3)
    assert abs(plain[1][m] - 0.3) > 0.01  # (the landmarks alone put it elsewhere)
    # the head is found either way (the truth: 12, -6, 4 degrees)
    np.testing.assert_allclose(held[0].angles_deg, [12.0, -6.0, 4.0], atol=1.5)
    assert held[3] and (held[1] >= 0).all() and (held[1] <= 1).all()


def test_vertex_normals_equal_the_meshs():
    """The compiled vertex normals the fit's visibility weights use are the mesh module's (to
    rounding: the same sums in another order), a vertex in no triangle included."""
    from myoface.face.mesh import vertex_normals as reference
    from myoface.model import build_face_model

    face = build_face_model().face
    rng = np.random.default_rng(5)
    v = face.vertices + rng.normal(0, 2.0, face.vertices.shape)
    v = np.vstack([v, [[0.0, 0.0, 0.0]]])  # a vertex in no triangle: (0, 0, 1)
    got = vertex_normals(v, face.triangles)
    np.testing.assert_allclose(got, reference(v, face.triangles), rtol=0, atol=1e-12)
    np.testing.assert_array_equal(got[-1], [0.0, 0.0, 1.0])


def _bounded_normal(hess, rhs, lo, hi):
    """The reference step: ``argmin x^T hess x / 2 - rhs . x`` with ``lo <= x <= hi`` as a
    bounded least-squares problem on the Cholesky factor (scipy's BVLS)."""
    r, _ = cho_factor(hess, lower=False)
    r = np.triu(r)
    y = solve_triangular(r, rhs, trans="T")
    return lsq_linear(r, y, bounds=(lo, hi), method="bvls").x


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n_muscles=st.integers(0, 34),
    conditioning=st.sampled_from([0.0, 0.99, 0.9999]),
)
def test_box_qp_finds_the_bounded_minimum(seed, n_muscles, conditioning):
    """The active-set step minimises the same bounded quadratic as scipy's BVLS (to rounding
    of the objective), stays in the box, and satisfies the optimality conditions: zero
    gradient on the free unknowns, and on a bound a gradient pointing out of the box. The
    fit's problems: 6 unbounded pose unknowns, contractions within [-c, 1 - c], nearly
    collinear columns (confounded muscles)."""
    rng = np.random.default_rng(seed)
    n = 6 + n_muscles
    a = rng.normal(size=(2 * n + 4, n))
    if n_muscles >= 2:
        a[:, 6] = conditioning * a[:, 7] + (1 - conditioning) * a[:, 6]
    h = a.T @ a + 1e-8 * np.eye(n)
    rhs = rng.normal(size=n) * rng.uniform(0.1, 100)
    c = rng.uniform(0, 1, n_muscles) * (rng.uniform(size=n_muscles) < 0.6)
    lo = np.concatenate([np.full(6, -np.inf), -c])
    hi = np.concatenate([np.full(6, np.inf), 1 - c])
    x = box_qp(h, rhs, lo, hi)
    assert (x >= lo).all() and (x <= hi).all()
    f = lambda y: 0.5 * y @ h @ y - rhs @ y  # noqa: E731
    ref = _bounded_normal(h, rhs, lo, hi)
    scale = 1e-9 * (1 + abs(f(ref)))
    assert f(x) <= f(ref) + scale
    g = h @ x - rhs
    tol = 1e-7 * (1 + np.abs(rhs).max())
    inside = (x > lo) & (x < hi)
    assert np.abs(g[inside]).max(initial=0) < tol
    assert (g[x == lo] >= -tol).all() and (g[x == hi] <= tol).all()


@pytest.mark.parametrize(
    "bad", [{"photo_landmark_gain": 0.0}, {"photo_landmark_gain": -0.5},
            {"photo_landmark_gain": 3.0}, {"photo_rate_per_s": 0.0}, {"rate_per_s": -1.0},
            {"sparsity_knee": 0.0}, {"sparsity_knee": 2.0}],
)  # fmt: skip
def test_the_fits_gain_and_rates_are_checked(bad):
    """A detector's gain outside (0, 1.5] or a rate that is not positive is refused with the
    field's name (None, the default, estimates the gain from the video)."""
    from myoface.analysis.weights import FitSettings
    from myoface.errors import MyofaceValueError

    with pytest.raises(MyofaceValueError, match=next(iter(bad))):
        FitSettings(**bad)
    assert FitSettings().photo_landmark_gain is None
    assert FitSettings(photo_landmark_gain=0.6).photo_landmark_gain == 0.6


def test_the_sparsity_prior_weighs_each_muscle_by_its_reach(frame):
    """With :attr:`FitSettings.sparsity_reach` the L1 prior's weight of each free muscle is
    the median's times its reach (its skin motion per unit contraction) over the fitted
    muscles' median reach, to that power: the zygomaticus major (its response's norm over
    the vertices 59 mm) pays more than the mentalis (5 mm); at 0 every muscle pays the same."""
    from dataclasses import replace

    fit, _, pose, c, _ = frame
    free = np.arange(fit.n_muscles)
    est = _estimate(fit, pose, c, free)
    plain = SparsityPrior(4.0).normal_equations(est)[1][6:]
    assert np.all(plain == plain[0])
    assert fit._sparsity_scale() is None
    saved = fit.settings
    try:
        fit.settings = replace(saved, sparsity_reach=1.0)
        scale = fit._sparsity_scale()
    finally:
        fit.settings = saved
    reach = np.sqrt((fit.model_response**2).sum(axis=(0, 1)))
    np.testing.assert_allclose(scale, reach / np.median(reach[fit._fitted]))
    ids = list(fit.model.ids)
    zyg, ment = ids.index("zygomaticus_major_l"), ids.index("mentalis_l")
    assert scale[zyg] > 2.0 and scale[ment] < 0.5, (scale[zyg], scale[ment])
    b = SparsityPrior(4.0, scale=scale).normal_equations(est)[1][6:]
    np.testing.assert_allclose(b, plain * scale)
