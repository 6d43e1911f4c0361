"""The lips at rest (issue 34): the inner lips' gap, measured on every kind of face, and closed on
the default face, Waters' face and a face from a photo."""

from __future__ import annotations

import numpy as np
import pytest

from myoface.errors import MyofaceValueError
from myoface.face import FaceMesh, default_mirror_map, load_default_face, read_waters_geoface
from myoface.face.lips import (
    CLOSED_MAX_MM,
    distance_to_polyline,
    inner_lip_margins,
    lip_gap,
    rest_lip_gap,
)
from tests.conftest import needs_mediapipe, shared_path


def _without_landmarks(face: FaceMesh) -> FaceMesh:
    return FaceMesh(face.vertices, face.triangles, face.uv, None, {}, name=face.name)


def test_gap_of_two_straight_margins_is_their_distance():
    """A known answer: two straight margins 3 mm apart meeting at the corners."""
    x = np.linspace(-20.0, 20.0, 9)
    up = np.column_stack([x, np.where(np.abs(x) < 20, 0.0, -1.5), np.zeros(9)])
    lo = np.column_stack([x, np.where(np.abs(x) < 20, -3.0, -1.5), np.zeros(9)])
    v = np.vstack([up, lo[1:-1]])
    upper = np.arange(9)
    lower = np.r_[0, 9 + np.arange(7), 8]
    g = lip_gap(v, upper, lower, "test")
    # the inner vertices next to the corners see the corner segments (closer than 3 mm)
    inner = np.abs(g.x_mm) < 15
    np.testing.assert_allclose(g.gaps_mm[inner], 3.0)
    assert g.max_mm == pytest.approx(3.0) and not g.closed and g.source == "test"
    assert len(g.gaps_mm) == 14  # 7 of each margin: the corners are not measured


def test_distance_to_polyline_projects_onto_segments():
    line = np.array([[0.0, 0.0, 0.0], [10.0, 0.0, 0.0], [10.0, 10.0, 0.0]])
    p = np.array([[5.0, 2.0, 0.0], [12.0, 5.0, 0.0], [-3.0, 4.0, 0.0], [5.0, 5.0, 1.0]])
    np.testing.assert_allclose(distance_to_polyline(p, line), [2.0, 2.0, 5.0, np.sqrt(26.0)])


def test_margins_need_three_vertices():
    with pytest.raises(MyofaceValueError, match="at least 3 vertices"):
        lip_gap(np.zeros((4, 3)), [0, 1], [0, 2, 1])


def test_default_face_rests_with_its_lips_together():
    """The bundled face: inner lips at most 1 mm apart along the whole mouth (5.5-5.8 mm at the
    midline before issue 34; 2.8-5.8 mm along the mouth)."""
    g = rest_lip_gap(load_default_face())
    assert g.source == "landmarks"
    assert g.max_mm <= CLOSED_MAX_MM and g.closed
    # every inner-margin vertex but the corners is measured, on both lips
    assert len(g.gaps_mm) == 18


def test_default_face_after_closing_is_still_symmetric_and_unfolded():
    """The closing keeps the face exactly left/right symmetric (the muscles are mirrored on it)
    and no triangle faces into the head."""
    face = load_default_face()
    m = default_mirror_map()
    np.testing.assert_allclose(face.vertices[m] * [-1, 1, 1], face.vertices, atol=1e-4)
    v, t = face.vertices, face.triangles
    n = np.cross(v[t[:, 1]] - v[t[:, 0]], v[t[:, 2]] - v[t[:, 0]])
    front = v[t].mean(axis=1)[:, 2] > 30.0  # the lips and the face round them look forward
    assert (n[front, 2] > 0).mean() > 0.95


def test_mouth_loop_finds_the_same_margins_as_the_landmarks():
    """A face without landmark groups: its mouth is found as a boundary loop and cut at the
    corners into the same margins the landmarks name."""
    face = load_default_face()
    up, lo, src = inner_lip_margins(_without_landmarks(face))
    assert src == "mouth loop"
    lm = face.landmarks
    np.testing.assert_array_equal(up, lm["lip_upper_inner"])
    np.testing.assert_array_equal(lo, lm["lip_lower_inner"])
    a = rest_lip_gap(face)
    b = rest_lip_gap(_without_landmarks(face))
    np.testing.assert_allclose(np.sort(a.gaps_mm), np.sort(b.gaps_mm))


def _grid(n: int = 8, hole: tuple[int, int] | None = None) -> FaceMesh:
    """A flat n x n grid of 10 mm cells (x right, y up, facing +z), optionally with the cells of
    row ``hole[0]``, columns ``hole[1]`` to ``n - 1 - hole[1]`` left out (a slit)."""
    g = np.arange(n + 1)
    x, y = np.meshgrid(g * 10.0, g * 10.0)
    v = np.column_stack([x.ravel() - 5.0 * n, y.ravel() - 5.0 * n, np.zeros(x.size)])
    tris = []
    for r in range(n):
        for c in range(n):
            if hole is not None and r == hole[0] and hole[1] <= c < n - hole[1]:
                continue
            a, b, d = r * (n + 1) + c, r * (n + 1) + c + 1, (r + 1) * (n + 1) + c
            tris += [[a, b, d], [b, d + 1, d]]
    return FaceMesh(v, np.array(tris), None, None, {})


def test_a_face_without_a_mouth_has_no_gap():
    assert rest_lip_gap(_grid()) is None


def test_a_slit_below_the_middle_is_a_mouth():
    """A rectangular slit one cell (10 mm) high on the midline: found, 10 mm apart."""
    g = rest_lip_gap(_grid(hole=(2, 2)))
    assert g.source == "mouth loop"
    assert g.gaps_mm.min() == pytest.approx(10.0) and not g.closed


def test_parted_lips_are_measured_apart():
    """The default face's lower lip lowered 4 mm: the gap at the midline is about 4 mm."""
    face = load_default_face()
    lm = face.landmarks
    v = face.vertices.copy()
    v[lm["lip_lower_inner"][1:-1], 1] -= 4.0
    g = rest_lip_gap(face.with_vertices(v))
    assert not g.closed
    mid = np.abs(g.x_mm) < 1.0
    assert g.gaps_mm[mid] == pytest.approx(4.0, abs=0.3)


@pytest.mark.shared_data
def test_waters_face_rests_with_its_lips_together():
    face = read_waters_geoface(shared_path("waters-geoface"))
    g = rest_lip_gap(face)
    assert g.source == "mouth loop"
    assert g.max_mm <= CLOSED_MAX_MM
    # the mouth is Waters' 14-vertex slit at the midline, below the nose
    up, lo, _ = inner_lip_margins(face)
    assert len(up) + len(lo) - 2 == 14
    assert abs(face.vertices[np.r_[up, lo], 0].mean()) < 1.0


@needs_mediapipe
@pytest.mark.shared_data
def test_face_from_the_sample_videos_first_frame_rests_with_its_lips_together():
    from myoface.analysis.video import open_video
    from myoface.face.personal import face_from_photo

    frame = next(iter(open_video(shared_path("video", "single_face.mp4"))))
    face, _ = face_from_photo(frame)
    g = rest_lip_gap(face)
    assert g.source == "landmarks"
    assert g.max_mm <= CLOSED_MAX_MM


def test_info_reports_the_rest_gap(capsys):
    from myoface.cli import main

    assert main(["info"]) == 0
    out = capsys.readouterr().out
    line = next(s for s in out.splitlines() if s.startswith("lips"))
    g = rest_lip_gap(load_default_face())
    assert f"max {g.max_mm:.2f} mm" in line and "closed" in line
