"""Cylindrical range/colour maps: ray casting against analytic surfaces, files, holes."""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from myoface.errors import MyofaceFormatError, MyofaceValueError
from myoface.face import FaceMesh
from myoface.face.cylindrical import CylindricalMaps, load_maps, maps_from_mesh

R_SPHERE = 90.0


@pytest.fixture(scope="module")
def sphere():
    s = trimesh.creation.icosphere(subdivisions=5, radius=R_SPHERE)
    v = np.asarray(s.vertices)
    theta = np.arctan2(v[:, 0], v[:, 2])
    uv = np.column_stack([(theta + np.pi) / (2 * np.pi), (v[:, 1] + R_SPHERE) / (2 * R_SPHERE)])
    # a texture whose red channel encodes the angle and green the height
    h, w = 64, 256
    tex = np.zeros((h, w, 3), np.uint8)
    tex[..., 0] = np.linspace(0, 255, w)[None, :].round().astype(np.uint8)
    tex[..., 1] = np.linspace(255, 0, h)[:, None].round().astype(np.uint8)
    return FaceMesh(v, np.asarray(s.faces), uv, tex, name="sphere")


def test_sphere_radius_matches_the_analytic_surface(sphere):
    m = maps_from_mesh(sphere, (128, 256), axis_x_mm=0.0, axis_z_mm=0.0, margin_mm=0.0)
    row, col = np.mgrid[0:128, 0:256]
    _, y = m.from_cells(row, col)
    truth = np.sqrt(R_SPHERE**2 - y**2)
    assert np.isfinite(m.radius_mm[np.abs(y) < 0.95 * R_SPHERE]).all(), "no ray may slip through"
    # a flat triangle of edge a inscribed in the sphere lies at most a^2 / (6 R) inside it (at
    # its centre, equilateral case); below |y| = 0.8 R the ray meets the surface within 53
    # degrees of the normal, so the radius may be short by that sag / cos(53 deg)
    a = np.linalg.norm(
        sphere.vertices[sphere.edges[:, 0]] - sphere.vertices[sphere.edges[:, 1]], axis=1
    )
    tol = a.max() ** 2 / (6 * R_SPHERE) / np.cos(np.radians(53))
    inside = np.abs(y) < 0.8 * R_SPHERE
    err = (truth - m.radius_mm)[inside]
    assert err.max() < tol and err.min() > -1e-6  # never outside the sphere


def test_off_axis_rays_give_the_outermost_hit(sphere):
    # an axis 30 mm off the centre: every ray from inside a sphere meets it exactly once outward
    m = maps_from_mesh(sphere, (64, 128), axis_x_mm=30.0, axis_z_mm=0.0, margin_mm=0.0)
    pts = m.points()
    band = np.abs(pts[:, 1]) < 0.6 * R_SPHERE
    assert np.isfinite(pts[band]).all()
    r = np.linalg.norm(pts[band], axis=1)
    assert np.abs(r - R_SPHERE).max() < 0.05


def test_colour_is_registered_to_the_texture(sphere):
    m = maps_from_mesh(sphere, (64, 256), axis_x_mm=0.0, axis_z_mm=0.0, margin_mm=0.0)
    row, col = np.mgrid[0:64, 0:256]
    theta, y = m.from_cells(row, col)
    keep = (np.abs(y) < 80) & (np.abs(theta) < 3.0)  # away from the texture's own seam
    expect_r = (theta + np.pi) / (2 * np.pi) * 255
    expect_g = (y + R_SPHERE) / (2 * R_SPHERE) * 255
    assert np.abs(m.rgb[..., 0].astype(float) - expect_r)[keep].max() < 4
    assert np.abs(m.rgb[..., 1].astype(float) - expect_g)[keep].max() < 6


@pytest.mark.parametrize("suffix", [".npz", ""])
def test_files_round_trip(sphere, tmp_path, suffix):
    m = maps_from_mesh(sphere, (32, 64), axis_x_mm=1.0, axis_z_mm=-2.0)
    m.landmarks_mm = np.arange(68 * 3, dtype=float).reshape(68, 3)
    path = m.save(tmp_path / f"maps{suffix}")
    back = load_maps(path)
    assert back.shape == m.shape
    assert np.array_equal(back.holes, m.holes)
    tol = 0.0 if suffix else 0.005  # the PNG layout stores 0.01 mm steps
    assert np.nanmax(np.abs(back.radius_mm - m.radius_mm)) <= tol + 1e-6
    assert np.array_equal(back.rgb, m.rgb)
    assert (back.axis_x_mm, back.axis_z_mm) == (1.0, -2.0)
    assert np.array_equal(back.landmarks_mm, m.landmarks_mm)


def test_bad_maps_are_refused(tmp_path):
    r = np.full((8, 16), 50.0)
    with pytest.raises(MyofaceValueError, match="colour map must have the range map's size"):
        CylindricalMaps(r, np.zeros((8, 15, 3), np.uint8))
    with pytest.raises(MyofaceValueError, match=">= 0"):
        CylindricalMaps(-r, np.zeros((8, 16, 3), np.uint8))
    bad = tmp_path / "x.npz"
    np.savez(bad, radius_mm=r)
    with pytest.raises(MyofaceFormatError, match="not a maps file"):
        load_maps(bad)
    (tmp_path / "folder").mkdir()
    with pytest.raises(MyofaceFormatError, match="no range.png"):
        load_maps(tmp_path / "folder")


def test_small_holes_are_filled_and_large_ones_kept():
    h, w = 40, 80
    r = np.full((h, w), 100.0) + np.linspace(0, 10, h)[:, None]  # radius grows downwards
    r[10:12, 20:22] = np.nan  # 4 cells
    r[20:35, 40:70] = np.nan  # 450 cells
    m = CylindricalMaps(r, np.zeros((h, w, 3), np.uint8), y_top_mm=40.0, y_bottom_mm=0.0)
    f = m.filled(max_hole_cells=64)
    assert np.isfinite(f.radius_mm[10:12, 20:22]).all()
    # the harmonic fill of a linear field is that field
    assert np.allclose(
        f.radius_mm[10:12, 20:22], 100 + np.linspace(0, 10, h)[10:12, None], atol=0.05
    )
    assert np.isnan(f.radius_mm[20:35, 40:70]).all()


def test_sampling_next_to_a_hole_uses_the_valid_cells():
    r = np.full((10, 20), 80.0)
    r[:, 10:] = np.nan
    m = CylindricalMaps(r, np.zeros((10, 20, 3), np.uint8), y_top_mm=10.0, y_bottom_mm=0.0)
    theta, y = m.from_cells(np.array([4.5, 4.5]), np.array([9.5, 14.0]))
    got = m.sample_radius(theta, y)
    assert got[0] == pytest.approx(80.0)
    assert np.isnan(got[1])
