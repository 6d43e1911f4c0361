"""The action units' range of motion against the published human values."""

import copy
import tomllib
from importlib import resources

import numpy as np
import pytest

from myoface.control.au_range import (
    AXES,
    AURange,
    AURangeResult,
    au_range_within,
    au_ranges,
    incisal_edges,
    measure_au_range,
    measure_au_ranges,
    parse_au_ranges,
)
from myoface.control.facs import au_table
from myoface.errors import MyofaceValueError


def _doc():
    return tomllib.loads((resources.files("myoface") / "data" / "au_range.toml").read_text())


@pytest.fixture(scope="module")
def measured():
    from myoface.model import build_face_model

    return {r.ref.au: r for r in measure_au_ranges(build_face_model())}


def test_table_parses_and_every_entry_has_a_source_or_says_why_not():
    refs = au_ranges()
    aus = {r.au for r in refs}
    # the AUs the issue names
    assert {1, 2, 4, 6, 9, 10, 12, 15, 17, 20, 25, 26, 27} <= aus and aus & {23, 24}
    for r in refs:
        assert r.au in au_table()
        if r.published:
            lo, hi = r.range_mm
            assert 0 < lo < hi and r.source.strip()
        else:
            assert "no published" in r.note
        assert r.direction and all(d in AXES for d in r.direction)


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda d: d["au"][0].pop("source"), "without a source"),
        (lambda d: d["au"][0].pop("range_mm"), "no range and no note"),
        (lambda d: d["au"][0].update(points=["nowhere"]), "unknown point"),
        (lambda d: d["au"][0].update(direction=["sideways"]), "direction"),
        (lambda d: d["au"][0].update(au=99), "not in the AU table"),
        (lambda d: d["au"][0].update(range_mm=[9.0, 3.0]), "bad range_mm"),
        (lambda d: d["au"][0].update(quantity="interincisal"), "takes no points"),
        (lambda d: d["au"][0].update(points=[]), "no points"),
    ],
)
def test_bad_table_entries_are_refused(edit, message):
    doc = copy.deepcopy(_doc())
    doc["au"][0].pop("note", None)
    edit(doc)
    with pytest.raises(MyofaceValueError, match=message):
        parse_au_ranges(doc)


def test_measurement_mirrors_the_right_side_and_measures_openings():
    refs = {r.au: r for r in au_ranges()}
    rest = np.zeros((468, 3))
    rest[:, 0] = np.where(np.arange(468) % 2, 20.0, -20.0)
    r12 = refs[12]
    moved = rest.copy()
    for v in r12.vertices:  # both corners 3 mm outwards, 4 mm up
        side = np.sign(rest[v, 0]) if abs(rest[v, 0]) > 1 else 1.0
        moved[v] += [3.0 * side, 4.0, 0.0]
    value, mean = measure_au_range(r12, rest, moved)
    assert value == pytest.approx(5.0) and mean == pytest.approx([3.0, 4.0, 0.0])
    # an opening between two points: the increase of their distance
    opening = AURange(26, ("a", "b"), (0, 2), "opening", ("down",), None, "", "")
    rest[0], rest[2] = [0.0, 0.0, 50.0], [0.0, -5.0, 50.0]
    moved = rest.copy()
    moved[2] += [0.0, -30.0, -10.0]
    value, mean = measure_au_range(opening, rest, moved)
    assert value == pytest.approx(np.hypot(35.0, 10.0) - 5.0)
    assert mean == pytest.approx([0.0, -30.0, -10.0])


def test_interincisal_opening_is_the_distance_between_the_incisal_edges():
    """AU27 is measured as the clinic measures a maximal opening: a ruler between the upper and
    lower incisors' edges, the lower ones carried by the jaw's rigid motion."""
    from myoface.face import load_default_face
    from myoface.face.teeth import fit_dentition

    r27 = {r.au: r for r in au_ranges()}[27]
    assert r27.quantity == "interincisal" and r27.vertices == ()
    d = fit_dentition(load_default_face())
    rest = incisal_edges(d)
    assert rest[0, 1] > rest[1, 1]  # the upper edge above the lower
    # a pure translation of the mandible 40 mm down and 3 mm forward
    moved = incisal_edges(d, (np.eye(3), np.array([0.0, -40.0, 3.0])))
    np.testing.assert_allclose(moved[0], rest[0])
    np.testing.assert_allclose(moved[1], rest[1] + [0.0, -40.0, 3.0])
    skin = np.zeros((468, 3))
    value, mean = measure_au_range(r27, skin, skin, np.stack([rest, moved]))
    assert value == pytest.approx(np.linalg.norm(moved[0] - moved[1]))
    assert mean == pytest.approx([0.0, -40.0, 3.0])
    with pytest.raises(MyofaceValueError, match="needs the incisors"):
        measure_au_range(r27, skin, skin)


def test_the_jaw_opens_the_incisors_within_the_human_range(measured):
    """AU26 a relaxed opening, AU27 the maximal one: the incisors part more in AU27, and AU26
    stays below the smallest maximal opening [K12] of data/au_range.toml."""
    r26, r27 = measured[26], measured[27]
    lo, _ = r27.ref.range_mm
    assert r26.value_mm < lo < r27.value_mm
    assert r27.within


def test_within_counts_only_aus_with_a_published_range():
    refs = {r.au: r for r in au_ranges()}
    inside = AURangeResult(refs[12], 9.0, np.array([4.0, 7.0, -3.0]), True)
    outside = AURangeResult(refs[1], 2.0, np.array([0.0, 2.0, 0.0]), True)
    unpublished = AURangeResult(refs[6], 50.0, np.array([0.0, 50.0, 0.0]), True)
    assert au_range_within([inside, outside, unpublished]) == 0.5
    assert unpublished.within is None and inside.direction_ok and outside.dominant == "up"
    with pytest.raises(MyofaceValueError):
        au_range_within([unpublished])


@pytest.mark.parametrize("au", [r.au for r in au_ranges()])
def test_each_au_moves_its_points_in_the_reference_direction(measured, au):
    r = measured[au]
    assert r.converged
    assert r.direction_ok, f"AU{au}: {r.direction_text()} (reference {r.ref.direction})"
