"""Snakes on synthetic images with known answers (T&W 1993, eq. (7)-(13))."""

import numpy as np
import pytest

from myoface.analysis.potentials import image_potential, image_potential_numpy, to_intensity
from myoface.analysis.snakes import (
    SnakeParams,
    Snakes,
    SnakeSystem,
    make_contours,
    relax_contours,
    resample_polyline,
    system_matrix_dense,
    track_contours,
)
from myoface.bench.snakes import ellipse_distance, ellipse_task
from myoface.errors import MyofaceValueError


def ellipse_image(size=96, center=(48.0, 44.0), radii=(24.0, 16.0), dark=40, bright=200):
    ys, xs = np.mgrid[0:size, 0:size]
    r = np.sqrt(((xs - center[0]) / radii[0]) ** 2 + ((ys - center[1]) / radii[1]) ** 2)
    inside = np.clip((1.0 - r) * min(radii) + 0.5, 0, 1)  # a 1-px anti-aliased edge
    return (bright * (1 - inside) + dark * inside).astype(np.uint8)


def ellipse_points(center, radii, n, grow=0.0):
    t = np.linspace(0, 2 * np.pi, n, endpoint=False)
    return np.column_stack(
        [center[0] + (radii[0] + grow) * np.cos(t), center[1] + (radii[1] + grow) * np.sin(t)]
    )


@pytest.mark.parametrize("dtype", [np.uint8, np.float32, np.float64])
def test_contour_converges_onto_a_dark_ellipse(dtype):
    img = ellipse_image()
    if dtype is not np.uint8:
        img = (img / 255.0).astype(dtype)  # floats in 0-1 are read as 0-255 grey levels
    c = make_contours([ellipse_points((48, 44), (24, 16), 126, grow=3.0)], closed=True)
    res = relax_contours(image_potential(img, sigma=2.0), c, SnakeParams(max_iter=3000))
    assert res.converged
    err = ellipse_distance(res.nodes, (48, 44), (24, 16))
    assert err.max() < 1.0, err.max()
    assert res.escaped[0] == 0


def test_tracks_a_translating_ravine():
    """A vertical step edge (the ravine of P = -|grad I|) moving 2 px per frame; an open snake
    started 1 px off it follows it."""
    size, frames, xs = 64, [], []
    cols = np.arange(size)
    for k in range(8):
        x0 = 20.0 + 2.0 * k
        dark = np.clip(x0 - cols + 0.5, 0, 1)  # dark left of x0, 1-px anti-aliased
        img = np.tile(210.0 - 150.0 * dark, (size, 1))
        frames.append(img.astype(np.uint8))
        xs.append(x0)
    line = np.column_stack([np.full(40, 21.0), np.linspace(12, 51, 40)])
    out = list(track_contours(frames, make_contours([line]), SnakeParams(p=0.005)))
    assert len(out) == 8
    for fr, x0 in zip(out, xs, strict=True):
        assert np.abs(fr.result.nodes[:, 0] - x0).max() < 0.5, (fr.index, x0)
        assert fr.result.escaped[0] == 0
    # tension shortens an open contour from its ends (its rest lengths relax, eq. 8), but it
    # still spans most of the edge after 8 frames
    last = out[-1].result.nodes
    assert np.linalg.norm(np.diff(last, axis=0), axis=1).sum() > 0.7 * 39.0


def test_breaks_separate_contours():
    """Two contours in one system: moving one (a user force) does not move the other."""
    a = resample_polyline(np.array([[10.0, 10], [30, 10]]))
    b = resample_polyline(np.array([[10.0, 30], [30, 30]]))
    c = make_contours([a, b])
    flat = np.zeros((48, 48))
    f = np.zeros((len(c.nodes), 2))
    f[: len(a), 1] = 0.05  # push the first contour down
    res = relax_contours(flat, c, SnakeParams(max_iter=20), user_forces=f)
    pa, pb = res.split()
    assert pa[:, 1].min() > 10.5
    np.testing.assert_allclose(pb, b, atol=1e-12)
    k = system_matrix_dense(c, SnakeParams())
    assert np.all(k[: len(a), len(a) :] == 0)  # no coupling in the matrix either


def test_rest_lengths_follow_eq8():
    """A stretched open contour on a flat potential: each iteration the rest lengths move by
    nu e / (gamma/dt) towards the current lengths (eq. 8 with gamma = 1)."""
    pts = np.column_stack([np.arange(6.0) * 2.0 + 5, np.full(6, 10.0)])  # spacing 2
    params = SnakeParams(a=1.0, b=0.0, nu=0.2, gamma_over_dt=0.5, max_iter=1)
    s = Snakes(make_contours([pts]), params)
    s.rest[:] = 1.0  # natural length 1, so every spring is stretched by e = 1
    s.relax(np.zeros((24, 32)))
    np.testing.assert_allclose(s.rest, 1.0 + 0.2 * 1.0 / 0.5)


def test_banded_solve_equals_dense_oracle():
    rng = np.random.default_rng(0)
    conts = [
        ellipse_points((30, 30), (10, 7), 25),
        resample_polyline(np.array([[5.0, 50], [40, 55], [60, 45]])),
        ellipse_points((60, 20), (6, 6), 12),
    ]
    c = make_contours(conts, closed=[True, False, True])
    params = SnakeParams(b=rng.uniform(0.1, 1.0, len(c.nodes)))
    sysm = SnakeSystem(c, params)
    assert sysm.bw <= 4
    rhs = rng.normal(size=(len(c.nodes), 2))
    np.testing.assert_allclose(
        sysm.solve(rhs), np.linalg.solve(system_matrix_dense(c, params), rhs), atol=1e-10
    )


def test_closed_and_open_boundaries():
    """Rigidity alone (flat potential, no tension): an open straight line and a closed circle
    are equilibria; the open ends are free (no row of K reaches past them)."""
    line = resample_polyline(np.array([[5.0, 20], [35, 20]]))
    circ = ellipse_points((20, 40), (8, 8), 50)
    c = make_contours([line, circ], closed=[False, True])
    k = system_matrix_dense(c, SnakeParams(gamma_over_dt=0.0 + 1e-9))
    x = c.nodes
    np.testing.assert_allclose((k @ x)[: len(line)], 1e-9 * x[: len(line)], atol=1e-9)
    kc = k[len(line) :, len(line) :]
    # the cyclic matrix couples the first and last nodes of the closed contour
    assert kc[0, -1] != 0 and kc[0, -2] != 0
    kl = k[: len(line), : len(line)]
    assert kl[0, -1] == 0


def test_potentials():
    img = ellipse_image()
    p = image_potential(img, sigma=2.0)
    np.testing.assert_allclose(p, image_potential_numpy(img, sigma=2.0), atol=1e-9)
    assert p.max() <= 0 and p.min() < -10  # ravines at the edge
    pp = image_potential(img, method="paper")
    assert pp.shape == img.shape and pp.min() < -10
    rgb = np.repeat(img[:, :, None], 3, axis=2)
    np.testing.assert_allclose(to_intensity(rgb), img.astype(float), atol=1e-9)


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: make_contours([np.zeros((5, 3))]), r"\(K, 2\)"),
        (lambda: make_contours([np.full((5, 2), np.nan)]), "NaN"),
        (lambda: make_contours([np.zeros((2, 2))]), "at least 3"),
        (
            lambda: relax_contours(np.zeros((20, 20)), make_contours([np.full((4, 2), 30.0)])),
            "outside",
        ),
        (lambda: image_potential(np.zeros((0, 0))), "empty"),
        (lambda: image_potential(np.zeros((10, 10, 7))), "shape"),
        (lambda: image_potential(np.full((10, 10), np.nan)), "NaN"),
        (
            lambda: list(track_contours([np.zeros((0, 5))], make_contours([np.ones((4, 2))]))),
            "frame 0 is empty",
        ),
        (lambda: SnakeParams(gamma_over_dt=0), "gamma_over_dt"),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(MyofaceValueError, match=match):
        call()


def test_escaped_contour_is_reported():
    img = ellipse_image()
    c = make_contours([ellipse_points((48, 44), (24, 16), 126, grow=1.0)], closed=True)
    s = Snakes(c, SnakeParams(max_iter=500))
    s.relax(image_potential(img))
    res = s.relax(image_potential(np.full_like(img, 128)))  # the feature is gone
    assert res.escaped[0] == len(c.nodes)


def test_beats_skimage_on_the_benchmark_task():
    """6 frames of the benchmark task (9 ellipses drifting 1.4 px per frame), tracked by ours
    and by scikit-image's active_contour (the peer in BENCHMARKS.md, with its parameters) from
    the same start: ours ends within 1 px of every true edge (a node on the edge to within the
    1-px anti-aliased ramp), and closer than the peer on every contour."""
    from myoface.bench.snakes import track_myoface, track_skimage

    frames, centres, init = ellipse_task(6)

    def worst(contours):
        return np.array(
            [ellipse_distance(c, ctr).max() for c, ctr in zip(contours, centres[-1], strict=True)]
        )

    ours, theirs = worst(track_myoface(frames, init)), worst(track_skimage(frames, init))
    assert ours.max() < 1.0, ours
    assert (ours < theirs).all(), (ours, theirs)
    assert ours.max() < 0.5 * theirs.max(), (ours, theirs)


def test_each_contour_moves_in_its_own_potential_layer():
    """Two contours on the same image, each in its own potential: one is pulled onto a dark
    line by the "line" potential, the other onto an ellipse's edge by eq. (13)."""
    img = ellipse_image(size=96)
    img[70:73, 10:86] = 40  # a 3-px dark line, rows 70-72
    pot = np.stack(
        [image_potential(img, sigma=1.5), image_potential(img, sigma=1.5, method="line")]
    )
    line0 = np.column_stack([np.linspace(20, 76, 29), np.full(29, 68.5)])
    c = make_contours(
        [ellipse_points((48, 44), (24, 16), 126, grow=2.0), line0], closed=[True, False]
    )
    s = Snakes(c, SnakeParams(p=0.01), layers=[0, 1])
    ell, line = s.relax(pot).split()
    assert ellipse_distance(ell, (48, 44), (24, 16)).max() < 1.0
    # the line's centre row is 71; the middle nodes settle on it
    assert np.abs(line[5:-5, 1] - 71.0).max() < 0.5
    with pytest.raises(MyofaceValueError, match="layer"):
        s.relax(pot[0])
    with pytest.raises(MyofaceValueError, match="layers"):
        Snakes(c, layers=[0])


def test_line_potential_has_its_ravine_on_a_thin_dark_lines_centre():
    img = np.full((40, 60), 200, np.uint8)
    img[:, 29:32] = 60  # columns 29-31
    row = image_potential(img, sigma=1.5, method="line")[20]
    assert int(np.argmin(row)) == 30
    assert row[30] < -50 and abs(row[3]) < 5  # deep on the line, about 0 on the flat
    # eq. (13) has a ridge there instead, with its ravines on the line's sides
    edge = image_potential(img, sigma=1.5)[20]
    assert edge[30] > edge[28] and edge[30] > edge[32]


@pytest.mark.parametrize("methods", [("gaussian",), ("gaussian", "line"), ("paper", "line+edge")])
def test_a_windowed_field_equals_the_whole_images_potentials(methods):
    """A window of a frame filtered alone (grown by the blur's reach) gives the potentials,
    and their gradients, of the whole frame inside it; at the frame's border too."""
    from myoface.analysis.potentials import PotentialField, potential_field

    rng = np.random.default_rng(0)
    img = (ellipse_image(size=96) + rng.normal(0, 5, (96, 96))).clip(0, 255).astype(np.uint8)
    whole = PotentialField.from_potential(
        np.stack([image_potential(img, sigma=1.5, method=m) for m in methods])
    )
    for window in [(30, 20, 70, 60), (-5, 50, 40, 120)]:  # inside; over two borders
        f = potential_field(img, 1.5, methods, window)
        x0, y0, x1, y1 = f.box
        assert (x0, y0) == (max(window[0], 0), max(window[1], 0))
        assert (x1, y1) == (min(window[2], 95), min(window[3], 95)) and f.image_size == (96, 96)
        sl = (slice(None), slice(y0, y1 + 1), slice(x0, x1 + 1))
        for a, b in ((f.potential, whole.potential), (f.gx, whole.gx), (f.gy, whole.gy)):
            inner = (slice(None), slice(1, -1), slice(1, -1))  # one-sided at the window's sides
            np.testing.assert_allclose(a[inner], b[sl][inner], atol=1e-9)
        assert f.full_layer(0).shape == (96, 96)
    with pytest.raises(MyofaceValueError, match="outside"):
        potential_field(img, 1.5, ("gaussian",), (200, 200, 300, 300))
    # a layer computed only in a smaller window: the whole image's values there, 0 elsewhere
    line = image_potential(img, sigma=1.5, method="line")
    f = potential_field(img, 1.5, ("gaussian", "line"), (10, 10, 90, 90), [None, (40, 30, 70, 60)])
    assert f.layer_boxes == (None, (40, 30, 70, 60))
    np.testing.assert_allclose(f.potential[1][21:50, 31:60], line[31:60, 41:70], atol=1e-9)
    assert (f.potential[1][:19] == 0).all() and (f.gx[1][:, :29] == 0).all()
    inside = np.array([[50.0, 40.0], [60.0, 50.0]])
    assert f.covers(inside, 2, layer=1) and not f.covers(inside + 15, 2, layer=1)


def test_a_contour_leaving_the_image_is_held_on_its_border_and_lost():
    """The tracker's relaxation does not refuse nodes outside the image (a face may leave the
    frame): they are held on its border and reported lost; the one-shot relaxation of contours
    a user gave still refuses them."""
    img = ellipse_image()
    c = make_contours([ellipse_points((48, 44), (24, 16), 126, grow=1.0)], closed=True)
    s = Snakes(c, SnakeParams(max_iter=50))
    s.contours.nodes[:] += (60.0, 0.0)  # most of the contour is past the right border
    res = s.relax(image_potential(img))
    x = res.nodes
    assert (x[:, 0] <= 95).all() and (x[:, 0] >= 0).all()
    out = x[:, 0] > 94.5  # on the border (to the interpolation's 1e-4 px)
    assert out.sum() > 60 and res.lost[out].all() and res.escaped[0] >= out.sum()
    with pytest.raises(MyofaceValueError, match="outside"):
        relax_contours(image_potential(img), make_contours([x + (60.0, 0.0)], closed=True))
    # a contour put back by the tracker gets rest lengths from its new nodes
    s.reset_contour(0, ellipse_points((48, 44), (24, 16), 126))
    assert np.allclose(
        s.rest,
        np.linalg.norm(np.diff(s.contours.nodes, axis=0, append=s.contours.nodes[:1]), axis=1),
    )
    assert s.relax(image_potential(img)).escaped[0] == 0


def test_equilibrium_ignores_sliding_along_the_contour():
    """A contour on a straight edge, dragged along it by a user force: its nodes keep sliding
    (0.02 px per iteration, 0.2 px per equilibrium window, above tol_px), but it is at rest
    across the edge, which is what the equilibrium test measures."""
    img = np.full((40, 80), 200, np.uint8)
    img[20:, :] = 40  # a horizontal edge at row 19.5
    pts = np.column_stack([np.linspace(10, 40, 31), np.full(31, 19.5)])
    s = Snakes(make_contours([pts]), SnakeParams(max_iter=300))
    drag = np.tile([0.01, 0.0], (len(pts), 1))
    res = s.relax(image_potential(img, sigma=1.5), drag)
    assert res.converged and res.iterations < 300
    assert res.nodes[:, 0].mean() > pts[:, 0].mean() + 0.1  # it did slide
    assert np.abs(res.nodes[:, 1] - 19.5).max() < 0.2


def lips_image(size=96, center=(48.0, 44.0), radii=(24.0, 12.0), lip_px=2.5):
    """A made-up mouth: skin (170), an elliptical ring of lip (100) ``lip_px`` wide, and the
    mouth's dark inside (15) within it, each edge anti-aliased over 1 px."""
    ys, xs = np.mgrid[0:size, 0:size]
    u = np.sqrt(((xs - center[0]) / radii[0]) ** 2 + ((ys - center[1]) / radii[1]) ** 2)
    outer = np.clip((1.0 - u) * min(radii) + 0.5, 0, 1)  # 1 inside the lips' outline
    inner = np.clip((1.0 - u) * min(radii) - lip_px + 0.5, 0, 1)  # 1 inside the opening
    return (170.0 * (1 - outer) + 100.0 * (outer - inner) + 15.0 * inner).astype(np.uint8)


def test_a_floored_layer_makes_no_edge_of_what_is_darker_than_the_floor():
    """``layer_floors``: the layer is the potential of the image raised to the floor, so that
    a thin lip around a dark mouth has one edge, its outline with the skin; in the plain
    potential the opening's stronger edge, 2.5 px inside, draws the lips' contour in."""
    from myoface.analysis.potentials import potential_field

    img = lips_image()
    f = potential_field(img, 1.5, ("gaussian", "gaussian"), layer_floors=[None, 80.0])
    raised = np.maximum(img, 80).astype(np.uint8)
    np.testing.assert_allclose(f.potential[1], image_potential(raised, 1.5), atol=1e-9)
    np.testing.assert_allclose(f.potential[0], image_potential(img, 1.5), atol=1e-9)
    start = ellipse_points((48, 44), (24, 12), 120, grow=3.0)
    inside = {}
    for layer in (0, 1):
        c = make_contours([start], closed=True)
        nodes = Snakes(c, SnakeParams(p=0.01), layers=[layer]).relax(f).split()[0]
        # px inside the outline (negative outside)
        u = np.hypot((nodes[:, 0] - 48) / 24, (nodes[:, 1] - 44) / 12)
        inside[layer] = np.sign(1 - u) * ellipse_distance(nodes, (48, 44), (24, 12))
    assert np.abs(inside[1]).max() < 0.6, inside[1]
    assert inside[0].mean() > 0.6 and inside[0].mean() > 3 * np.abs(inside[1]).mean(), inside
    with pytest.raises(MyofaceValueError, match="layer_floors"):
        potential_field(img, 1.5, ("gaussian",), layer_floors=[1.0, 2.0])
    with pytest.raises(MyofaceValueError, match="floor"):
        potential_field(img, 1.5, ("gaussian",), layer_floors=[300.0])


def test_the_lips_tone_is_read_inside_their_outline():
    """:func:`~myoface.analysis.trackers.snakes.lips_tone`: the grey levels of the band inside the
    outline, whichever way the contour runs; the skin outside and the mouth's inside (beyond
    the band) do not count."""
    from myoface.analysis.trackers.snakes import lips_tone

    img = lips_image(lip_px=4.0)
    outline = ellipse_points((48, 44), (24, 12), 120)
    for q in (outline, outline[::-1]):
        tone = lips_tone(img, q, band_px=(1.5, 2.5), percentile=50)
        assert abs(tone - 100) < 8, tone
