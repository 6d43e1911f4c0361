"""Action units, expressions, visemes and timelines -> contractions."""

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from myoface.control import (
    au_contractions,
    au_table,
    envelope,
    expression_aus,
    expression_contractions,
    list_expressions,
    list_visemes,
    load_timeline,
    missing_muscles,
    single_event_timeline,
    viseme_contractions,
)
from myoface.control.timeline import Timeline
from myoface.errors import MyofaceError, MyofaceFormatError, MyofaceValueError
from myoface.muscles import load_default_muscles
from tests.conftest import REPO

IDS = load_default_muscles().ids
REQUIRED_AUS = [1, 2, 4, 5, 6, 9, 10, 12, 14, 15, 16, 17, 20, 23, 24, 25, 26, 27]


def mirror(c):
    out = c.copy()
    for i, k in enumerate(IDS):
        if k.endswith("_l"):
            j = IDS.index(k[:-2] + "_r")
            out[i], out[j] = c[j], c[i]
    return out


def test_table_covers_required_aus_and_known_muscles():
    table = au_table()
    assert set(REQUIRED_AUS) <= set(table)
    for au in table.values():
        for base in au.muscles:
            assert base in IDS or f"{base}_l" in IDS, (au.number, base)
    # (a crossed AU, AD30, is scored with a side only)
    assert not missing_muscles({f"L{n}" if au.crossed else n: 1.0 for n, au in table.items()}, IDS)


def test_jaw_sideways_is_scored_by_where_the_jaw_goes():
    """AD30: L30 takes the jaw to the subject's left (+x), by the right lateral pterygoid; it
    needs a side (both would cancel)."""
    left = au_contractions({"L30": 1.0}, IDS)
    assert left[IDS.index("lateral_pterygoid_r")] > 0 and left.sum() == pytest.approx(
        left[IDS.index("lateral_pterygoid_r")]
    )
    right = au_contractions({"30R": 0.5}, IDS)
    assert right[IDS.index("lateral_pterygoid_l")] == pytest.approx(0.5 * left.max())
    with pytest.raises(MyofaceValueError, match="needs a side"):
        au_contractions({30: 1.0}, IDS)


@settings(max_examples=60, deadline=None)
@given(
    st.dictionaries(st.sampled_from(REQUIRED_AUS), st.floats(0, 1), min_size=1, max_size=6),
    st.sampled_from(REQUIRED_AUS),
    st.floats(0, 1),
)
def test_au_mapping_is_bounded_and_monotonic(aus, extra, more):
    c = au_contractions(aus, IDS)
    assert np.all((c >= 0) & (c <= 1))
    bumped = dict(aus)
    bumped[extra] = max(bumped.get(extra, 0.0), more)
    c2 = au_contractions(bumped, IDS)
    assert np.all(c2 >= c - 1e-12)


def test_single_au_at_full_is_its_weight():
    c = au_contractions({12: 1.0}, IDS)
    assert c[IDS.index("zygomaticus_major_l")] == 1.0 == c[IDS.index("zygomaticus_major_r")]
    assert c.sum() == 2.0


def test_unilateral_variants_touch_one_side():
    for key in ("L12", "12L", "AU12L", "l12"):
        c = au_contractions({key: 0.7}, IDS)
        assert c[IDS.index("zygomaticus_major_l")] == pytest.approx(0.7)
        assert c[IDS.index("zygomaticus_major_r")] == 0
    c = au_contractions({"R1": 1.0}, IDS)
    assert all(IDS[i].endswith("_r") for i in np.flatnonzero(c))


def test_symmetric_aus_and_expressions_are_symmetric():
    for n in REQUIRED_AUS:
        c = au_contractions({n: 0.8}, IDS)
        np.testing.assert_array_equal(c, mirror(c))
    for e in list_expressions():
        c = expression_contractions(e, 0.9, IDS)
        np.testing.assert_array_equal(c, mirror(c))
        assert c.max() > 0.3


def test_expressions_follow_their_prototypes():
    assert set(list_expressions()) == {
        "anger",
        "disgust",
        "fear",
        "happiness",
        "sadness",
        "surprise",
    }
    assert {6, 12} <= set(expression_aus("happiness"))
    assert {1, 2, 5, 26} == set(expression_aus("surprise"))
    c = expression_contractions("surprise", 1.0, IDS)
    assert c[IDS.index("jaw")] > 0.2 and c[IDS.index("frontalis_inner_l")] > 0.5
    half = expression_contractions("surprise", 0.5, IDS)
    assert np.all(half <= c + 1e-12) and half.sum() < c.sum()


def test_visemes():
    assert {"rest", "PBM", "A", "O", "U", "FV"} <= set(list_visemes())
    a = viseme_contractions("A", 1.0, IDS)
    assert a[IDS.index("jaw")] == a.max() > 0.5  # "a": the widest opening
    assert a[IDS.index("jaw")] > viseme_contractions("E", 1.0, IDS)[IDS.index("jaw")]
    assert not viseme_contractions("rest", 1.0, IDS).any()
    u = viseme_contractions("U", 1.0, IDS)
    assert u[IDS.index("orbicularis_oris")] == u.max() > 0.5  # "u": the lips rounded


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda: au_contractions({3: 1.0}, IDS), "unknown action unit AU3"),
        (lambda: au_contractions({"12": 3}, IDS), r"must be in \[0, 1\]; got 3"),
        (lambda: au_contractions({"smile": 1}, IDS), "not an action unit"),
        (lambda: au_contractions({"L26": 1}, IDS), "no left/right variant"),
        (lambda: expression_contractions("joy", 1, IDS), "unknown expression 'joy'"),
        (lambda: viseme_contractions("ZZ", 1, IDS), "unknown viseme"),
        (lambda: au_contractions({12: 1}, ["jaw"]), "does not have"),
    ],
)
def test_bad_input(call, match):
    with pytest.raises(MyofaceValueError, match=match):
        call()


def test_non_strict_reports_missing_muscles():
    c = au_contractions({12: 1.0, 26: 0.4}, ["jaw"], strict=False)
    assert c.tolist() == [pytest.approx(0.2)]
    assert missing_muscles({12: 1.0}, ["jaw"]) == {"zygomaticus_major_l", "zygomaticus_major_r"}


def test_envelope_values():
    t = np.array([-0.1, 0.0, 0.25, 0.5, 1.0, 2.0, 2.25, 2.5, 3.0])
    e = envelope(t, start=0.0, onset=0.5, apex=1.5, offset=0.5)
    np.testing.assert_allclose(e, [0, 0, 0.5, 1, 1, 1, 0.5, 0, 0], atol=1e-12)


def test_timeline_mixing_and_envelopes(tmp_path):
    tl = Timeline.from_dict(
        {
            "events": [
                {
                    "kind": "au",
                    "name": "12",
                    "start": 0.0,
                    "duration": 1.0,
                    "intensity": 0.6,
                    "onset": 0.2,
                    "offset": 0.2,
                },
                {
                    "kind": "muscle",
                    "name": "zygomaticus_major_l",
                    "start": 0.5,
                    "duration": 1.0,
                    "intensity": 0.5,
                    "onset": 0.0,
                    "offset": 0.0,
                },
            ]
        }
    )
    assert tl.duration == 1.5
    c = tl.contractions([0.1, 0.6, 1.2, 2.0], IDS)
    zl, zr = IDS.index("zygomaticus_major_l"), IDS.index("zygomaticus_major_r")
    assert c[0, zr] == pytest.approx(0.3)  # half-way up the onset
    assert c[1, zr] == pytest.approx(0.6)
    assert c[1, zl] == pytest.approx(1 - 0.4 * 0.5)  # probabilistic OR of 0.6 and 0.5
    assert c[2, zl] == pytest.approx(0.5) and c[2, zr] == 0
    assert not c[3].any()


def test_timeline_files_roundtrip(tmp_path):
    tl = load_timeline(REPO / "examples" / "talk.toml")
    for suffix in (".toml", ".json"):
        p = tmp_path / f"t{suffix}"
        tl.save(p)
        back = load_timeline(p)
        t = np.linspace(0, tl.duration, 40)
        np.testing.assert_allclose(back.contractions(t, IDS), tl.contractions(t, IDS))


@pytest.mark.parametrize(
    ("doc", "match"),
    [
        (
            {"events": [{"kind": "expression", "name": "joy", "start": 0, "duration": 1}]},
            "unknown expression",
        ),
        ({"events": [{"kind": "au", "name": "12", "start": -1, "duration": 1}]}, "start must be"),
        (
            {"events": [{"kind": "au", "name": "12", "start": 0, "duration": 0}]},
            "duration must be > 0",
        ),
        (
            {"events": [{"kind": "au", "name": "12", "start": 0, "duration": 1, "intensity": 3}]},
            r"in \[0, 1\]",
        ),
        (
            {"events": [{"kind": "au", "name": "12", "start": 0, "duration": 1, "strat": 1}]},
            "unknown keys",
        ),
        (
            {"events": [{"kind": "au", "name": "12", "start": float("nan"), "duration": 1}]},
            "finite",
        ),
        (
            {
                "events": [
                    {
                        "kind": "au",
                        "name": "12",
                        "start": 0,
                        "duration": 1,
                        "onset": 0.8,
                        "offset": 0.8,
                    }
                ]
            },
            "exceed the duration",
        ),
        (
            {
                "events": [
                    {"kind": "viseme", "name": "A", "start": 0, "duration": 1},
                    {"kind": "viseme", "name": "O", "start": 0.2, "duration": 1},
                ]
            },
            "overlap at their apex",
        ),
        ({"events": []}, "no events"),
        ({"events": [{"kind": "smile", "name": "x", "start": 0, "duration": 1}]}, "kind must be"),
    ],
)
def test_timeline_errors(doc, match):
    with pytest.raises(MyofaceFormatError, match=match):
        Timeline.from_dict(doc, "t.toml")


def test_timeline_file_errors(tmp_path):
    with pytest.raises(MyofaceError, match="no such timeline"):
        load_timeline(tmp_path / "none.toml")
    p = tmp_path / "bad.json"
    p.write_text("{not json")
    with pytest.raises(MyofaceFormatError, match="cannot parse"):
        load_timeline(p)
    p.write_text(
        json.dumps(
            {"events": [{"kind": "muscle", "name": "smile_muscle", "start": 0, "duration": 1}]}
        )
    )
    tl = load_timeline(p)
    with pytest.raises(MyofaceValueError, match="event #1: unknown muscle"):
        tl.contractions([0.5], IDS)


def test_visemes_may_overlap_in_their_ramps():
    tl = Timeline.from_dict(
        {
            "events": [
                {"kind": "viseme", "name": "A", "start": 0, "duration": 0.6},
                {"kind": "viseme", "name": "O", "start": 0.4, "duration": 0.6},
            ]
        }
    )
    c = tl.contractions([0.45], IDS)
    assert c[0, IDS.index("orbicularis_oris")] > 0 and c[0, IDS.index("jaw")] > 0


def test_single_event_timeline_has_tail():
    tl = single_event_timeline("expression", "surprise", 0.8, 1.5, tail=0.5)
    assert tl.duration == 2.0
    c = tl.contractions([0.75, 1.9], IDS)
    assert c[0].max() > 0.5 and not c[1].any()
