"""The lips' colour layer of the snakes (``Analyzer(mouth_colour=True)``) on made-up open
mouths with known outlines: one region of lips, teeth and dark inside, edges rising outwards,
a coarse copy."""

import numpy as np
import pytest

from myoface.analysis.potentials import (
    MouthTones,
    image_potential,
    mouth_image,
    potential_field,
    pseudo_hue,
    saturation,
)
from myoface.analysis.snakes import SnakeParams, Snakes, make_contours
from myoface.bench.snakes import ellipse_distance
from myoface.errors import MyofaceValueError
from tests.analysis.test_snakes import ellipse_image, ellipse_points

SKIN = (190, 135, 120)  # pseudo-hue 0.585, saturation 0.37
LIP = (165, 95, 95)  # 0.635, 0.42
TEETH = (225, 220, 205)  # 0.506, 0.09
CAVITY = (45, 20, 22)


def open_mouth(size=96, center=(48.0, 44.0), radii=(24.0, 12.0), lip_px=3.0, teeth_px=4.0):
    """An RGB open smile: skin, an elliptical ring of lip ``lip_px`` wide, a band of teeth
    ``teeth_px`` wide inside it and the dark inside within, each edge anti-aliased over 1 px;
    and the (u) map, 1 on the lips' outline."""
    ys, xs = np.mgrid[0:size, 0:size]
    u = np.sqrt(((xs - center[0]) / radii[0]) ** 2 + ((ys - center[1]) / radii[1]) ** 2)
    depth = (1.0 - u) * min(radii)  # px inside the outline, along the minor axis' scale
    outer = np.clip(depth + 0.5, 0, 1)
    inner = np.clip(depth - lip_px + 0.5, 0, 1)
    deep = np.clip(depth - lip_px - teeth_px + 0.5, 0, 1)
    rgb = (
        np.array(SKIN) * (1 - outer)[..., None]
        + np.array(LIP) * (outer - inner)[..., None]
        + np.array(TEETH) * (inner - deep)[..., None]
        + np.array(CAVITY) * deep[..., None]
    )
    return rgb.round().astype(np.uint8), u


TONES = MouthTones(skin_hue=0.585, lip_hue=0.635, floor=60.0, teeth_saturation=0.28)


def test_the_colour_tells_lips_from_skin_and_teeth():
    img, _ = open_mouth()
    h, s = pseudo_hue(img), saturation(img)
    assert h[44, 10] == pytest.approx(190 / 325) and h[44, 48 - 24 + 1] > 0.62
    assert s[44, 10] == pytest.approx(70 / 190) and s[44 + 12 - 5, 48] < 0.1  # a tooth
    assert (
        pseudo_hue(np.zeros((3, 3, 3)))[1, 1] == 0.5 and saturation(np.zeros((3, 3, 3))).max() == 0
    )


def test_the_mouth_image_is_one_region_inside_the_lips_outline():
    """Lips, teeth and the dark inside all at the mouth's level, the skin at its own, so the
    only edge left is the lips' outline; a grey image is floored as the plain mouth layer."""
    img, u = open_mouth()
    m = mouth_image(img, TONES)
    # (the pseudo-hue is blurred by a pixel: within 2 px of the outline the skin's shows, and
    # where the lips meet the teeth their anti-aliased mix is a little less red than the lips)
    inside, outside = m[u < 1 - 2.5 / 12], m[u > 1 + 2.5 / 12]
    assert np.abs(inside - 150).max() < 15 and abs(np.median(inside) - 150) < 0.5
    assert np.abs(outside - 200).max() < 1
    grey = img.mean(axis=2)
    np.testing.assert_allclose(mouth_image(grey, TONES), np.maximum(grey, 60.0))


def test_teeth_enclosed_by_the_lips_are_mouth_even_when_not_pale():
    """Teeth less pale than the saturation test takes (yellow, in shadow) are mouth when the
    lips enclose them, also through a gap of a pixel or two in the lips' ring."""
    img, u = open_mouth()
    yellow = np.array([200, 170, 110], np.uint8)  # pseudo-hue 0.54, saturation 0.45
    teeth = (u < 1 - 3.0 / 12) & (u > 1 - 7.0 / 12)
    img[teeth] = yellow
    img[44 - 12 : 44 - 8, 47:49] = yellow  # a 2-px gap through the upper lip
    m = mouth_image(img, TONES)
    assert np.abs(m[teeth] - 150).max() < 15 and abs(np.median(m[teeth]) - 150) < 0.5
    assert np.abs(m[u > 1 + 2.5 / 12] - 200).max() < 1


def test_the_outward_layer_keeps_the_edges_rising_outwards():
    """``layer_outward``: the outline of a dark ellipse on bright ground keeps its ravine (as
    deep as the plain potential's, within the projection on the ellipse's normal), a bright
    ellipse on dark ground makes none."""
    dark = ellipse_image()
    bright = (240 - dark.astype(int)).astype(np.uint8)
    ell = (48.0, 44.0, 24.0, 16.0)
    for img, deep in ((dark, True), (bright, False)):
        f = potential_field(img, 1.5, ("gaussian", "gaussian"), layer_outward=[None, ell])
        plain, out = f.potential[0], f.potential[1]
        np.testing.assert_allclose(plain, image_potential(img, 1.5), atol=1e-9)
        if deep:
            assert out.min() < 0.9 * plain.min() < 0
        else:
            assert out.min() > 0.05 * plain.min()
        assert (out <= 0).all() and (out >= plain - 1e-9).all()
    with pytest.raises(MyofaceValueError, match="layer_outward"):
        potential_field(dark, 1.5, ("line",), layer_outward=[ell])
    with pytest.raises(MyofaceValueError, match="layer_outward"):
        potential_field(dark, 1.5, ("gaussian",), layer_outward=[ell, ell])


def test_a_coarse_layer_is_the_wider_potential_deepened():
    """``layer_sigmas``: a layer's own width; its potential multiplied by the ratio of the
    widths (a blurred step's slope falls as the blur widens)."""
    img = ellipse_image()
    f = potential_field(img, 1.5, ("gaussian", "gaussian"), layer_sigmas=[None, 4.5])
    np.testing.assert_allclose(f.potential[1], 3.0 * image_potential(img, 4.5), atol=1e-9)
    np.testing.assert_allclose(f.potential[0], image_potential(img, 1.5), atol=1e-9)
    with pytest.raises(MyofaceValueError, match="sigma"):
        potential_field(img, 1.5, ("gaussian",), layer_sigmas=[-1.0])
    with pytest.raises(MyofaceValueError, match="layer_sigmas"):
        potential_field(img, 1.5, ("gaussian",), layer_sigmas=[None, None])


def _settle(fld, layers, start):
    c = make_contours([start], closed=True)
    sn = Snakes(c, SnakeParams(p=0.01))
    for layer in layers:
        sn.node_layer[:] = layer
        nodes = sn.relax(fld).split()[0]
    u = np.hypot((nodes[:, 0] - 48) / 24, (nodes[:, 1] - 44) / 12)
    return np.sign(1 - u) * ellipse_distance(nodes, (48, 44), (24, 12))  # px inside


def test_a_lips_contour_on_the_teeth_finds_the_outline():
    """A lips contour left on the teeth (as a smile opens, 4 px inside the outline) stays on
    the teeth's edges in the plain potential; in the colour layer, relaxed first in its coarse
    copy, it settles on the lips' outline."""
    img, _ = open_mouth()
    ell = (48.0, 44.0, 20.0, 8.0)
    f = potential_field(
        img,
        1.5,
        ("gaussian", "gaussian", "gaussian"),
        layer_floors=[None, TONES, TONES],
        layer_sigmas=[None, None, 4.5],
        layer_outward=[None, ell, ell],
    )
    start = ellipse_points((48, 44), (20, 8), 120)
    plain = _settle(f, [0], start)
    colour = _settle(f, [2, 1], start)
    assert plain.mean() > 2.5, plain
    assert np.abs(colour).max() < 1.0, colour
