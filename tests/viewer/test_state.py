"""The viewer's control logic and physics worker, without a browser."""

import time

import numpy as np
import pytest

from myoface.control import au_contractions, expression_contractions
from myoface.errors import MyofaceError, MyofaceValueError
from myoface.model import build_face_model
from myoface.viewer.state import PhysicsWorker, ViewerState, region_of
from tests.conftest import REPO


@pytest.fixture(scope="module")
def fm():
    return build_face_model()


def test_linked_and_free_sliders(fm):
    st = ViewerState(fm)
    st.set_muscle("zygomaticus_major_l", 0.6)
    c = st.contractions()
    assert c[fm.ids.index("zygomaticus_major_r")] == pytest.approx(0.6)
    st.linked = False
    st.set_muscle("zygomaticus_major_l", 0.2)
    c = st.contractions()
    assert c[fm.ids.index("zygomaticus_major_l")] == pytest.approx(0.2)
    assert c[fm.ids.index("zygomaticus_major_r")] == pytest.approx(0.6)


def test_requests_mix_like_the_control_level(fm):
    st = ViewerState(fm)
    st.set_au(12, 0.5)
    st.set_expression("surprise", 0.8)
    want = 1 - (1 - au_contractions({12: 0.5}, fm.ids)) * (
        1 - expression_contractions("surprise", 0.8, fm.ids)
    )
    np.testing.assert_allclose(st.contractions(), want)
    st.reset()
    assert not st.contractions().any()


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda st: st.set_muscle("zygomaticus_major_l", 3), r"in \[0, 1\]"),
        (lambda st: st.set_muscle("smile", 0.5), "unknown muscle"),
        (lambda st: st.set_au(3, 0.5), "unknown action unit"),
        (lambda st: st.set_expression("joy", 0.5), "unknown expression"),
        (lambda st: st.set_muscle("jaw", "abc"), "must be a number"),
    ],
)
def test_bad_values_are_refused_and_state_kept(fm, call, match):
    st = ViewerState(fm)
    st.set_muscle("jaw", 0.3)
    before = st.contractions()
    with pytest.raises(MyofaceValueError, match=match):
        call(st)
    np.testing.assert_array_equal(st.contractions(), before)


def test_playback_of_timeline_and_csv(fm, tmp_path):
    st = ViewerState(fm)
    dur = st.load_playback(REPO / "examples" / "talk.toml")
    assert dur == pytest.approx(3.0, abs=0.05)
    assert st.frame_at(1.0)[fm.ids.index("zygomaticus_major_l")] > 0.2  # the smile is on
    csv = tmp_path / "c.csv"
    csv.write_text("time_s,quality,jaw\n0,ok,0.1\n0.5,escaped:chin,\n1.0,ok,0.6\n")
    assert st.load_playback(csv) == pytest.approx(1.0)
    assert st.frame_at(0.6)[fm.ids.index("jaw")] == pytest.approx(0.1)  # held over the gap
    assert st.frame_at(1.0)[fm.ids.index("jaw")] == pytest.approx(0.6)
    bad = tmp_path / "bad.csv"
    bad.write_text("frame,jaw\n0,0.1\n")
    with pytest.raises(MyofaceError, match="time_s"):
        st.load_playback(bad)


def test_worker_coalesces_and_survives_errors(fm):
    published, errors = [], []
    w = PhysicsWorker(fm, published.append, errors.append)
    w.start()
    try:
        for v in np.linspace(0, 1, 20):  # a burst of slider events
            w.request(fm.validate({"jaw": v}))
        assert w.settled.wait(20)
        assert 1 <= len(published) < 20  # intermediate requests were skipped
        assert w.current.contractions[fm.ids.index("jaw")] == 1.0  # and the last one won
        drawn = np.array(w.current.x)  # the tissue, with the skin as drawn (eyelids, lips)
        drawn[: fm.face.n_vertices] = fm.skin_vertices(w.current)
        np.testing.assert_array_equal(published[-1], drawn)
        w.request(np.full(len(fm.ids), 7.0))  # invalid: reported, not fatal
        time.sleep(0.5)
        assert errors and "in [0, 1]" in errors[-1]
        w.request(fm.validate({}))
        assert w.settled.wait(20) and w.is_alive()
    finally:
        w.stop()


def test_regions_cover_the_default_muscles(fm):
    assert all(region_of(m) != "other" for m in fm.ids if m != "jaw")


def test_view_command_without_viser(monkeypatch, capsys):
    import builtins

    real = builtins.__import__

    def no_viser(name, *a, **k):
        if name == "viser":
            raise ImportError("no viser")
        return real(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_viser)
    from myoface.cli import main

    assert main(["view", "--port", "0"]) == 1
    assert 'pip install "myoface[viewer]"' in capsys.readouterr().err
