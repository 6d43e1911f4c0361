"""Expressions read from the contractions (``myoface.analysis.expressions``): the EMFACS rule
over the AU table, its CSV columns, its plot, and one clip analysed end to end."""

import csv
import warnings

import numpy as np
import pytest

from myoface.analysis.expressions import (
    EXPRESSION_COLUMNS,
    EXPRESSIONS,
    LABEL_COLUMN,
    LABEL_MIN,
    NEUTRAL,
    expression_labels,
    expression_scores,
    expression_scores_from_aus,
    plot_expressions,
    prototypes,
    read_expressions,
    rule_aus,
    specificity,
)
from myoface.control import expression_aus, expression_contractions
from myoface.control.facs import au_contractions
from tests.conftest import needs_mediapipe


@pytest.fixture(scope="module")
def ids():
    from myoface.muscles.io import load_default_muscles

    return list(load_default_muscles().ids)


def _aus(**kw) -> np.ndarray:
    """AU intensities in [0, 1] over :func:`rule_aus` from ``AU12=0.9``-style keywords."""
    aus = rule_aus()
    x = np.zeros(len(aus))
    for k, v in kw.items():
        x[aus.index(int(k[2:]))] = v
    return x


# ------------------------------------------------------------------------------ the rule


@pytest.mark.parametrize("name", EXPRESSIONS)
@pytest.mark.parametrize("intensity", [0.5, 0.75, 1.0])
def test_each_expressions_facs_command_gives_its_label(ids, name, intensity):
    """The expression's own FACS command (data/expressions.toml) through the AU table: the
    rule labels it that expression, and it is the strongest of the six by a margin."""
    s = expression_scores(expression_contractions(name, intensity, ids), ids)
    assert expression_labels(s) == [name]
    j = EXPRESSIONS.index(name)
    others = np.delete(s[: len(EXPRESSIONS)], j)
    assert s[j] >= LABEL_MIN and s[j] > others.max() + 0.1, s
    assert s[-1] == pytest.approx(1.0 - s[j])


def test_neutral_at_rest(ids):
    s = expression_scores(np.zeros(len(ids)), ids)
    np.testing.assert_array_equal(s, [0, 0, 0, 0, 0, 0, 1])
    assert expression_labels(s) == [NEUTRAL]


def test_a_trace_of_one_au_is_neutral(ids):
    """A single AU below a trace (FACS's A) opens no prototype's gate."""
    s = expression_scores(au_contractions({12: 0.09}, ids), ids)
    assert s[: len(EXPRESSIONS)].max() == 0 and expression_labels(s) == [NEUTRAL]


def test_a_mixture_of_two_expressions(ids):
    """Happiness at apex with surprise at half: both present (each discounted by the other's
    AUs, which it leaves unexplained), happiness the stronger and the label; swapped,
    surprise."""
    keep = (1 - expression_contractions("happiness", 1.0, ids)) * (
        1 - expression_contractions("surprise", 0.5, ids)
    )
    s = expression_scores(1 - keep, ids)
    h, su = s[EXPRESSIONS.index("happiness")], s[EXPRESSIONS.index("surprise")]
    assert h > su > 0 and expression_labels(s) == ["happiness"]
    keep = (1 - expression_contractions("happiness", 0.4, ids)) * (
        1 - expression_contractions("surprise", 1.0, ids)
    )
    s = expression_scores(1 - keep, ids)
    h, su = s[EXPRESSIONS.index("happiness")], s[EXPRESSIONS.index("surprise")]
    assert su > h > 0 and expression_labels(s) == ["surprise"]


def test_the_rule_by_hand():
    """The documented arithmetic on given AU intensities. AU6 0.6 and AU12 0.9: relative to
    the strongest (AU12), 0.67 and 1; happiness's 6+12 matches 0.83 and 12>=C 1, the best 1;
    AU20 (fear's alone: specificity 1) unexplained."""
    s = expression_scores_from_aus(_aus(AU06=0.6, AU12=0.9))
    assert s[0] == pytest.approx(1.0) and s[-1] == pytest.approx(0.0)
    s = expression_scores_from_aus(_aus(AU06=0.6, AU12=0.9, AU20=0.5))
    assert s[0] == pytest.approx((0.36 + 0.81) / (0.36 + 0.81 + 0.25))
    # the same pattern read at a third of its strength (its strongest AU above a trace)
    # scores the same: the rule compares the AUs with each other
    for x in (_aus(AU01=0.8, AU04=0.5, AU15=0.7), _aus(AU06=0.6, AU12=0.9, AU20=0.5)):
        np.testing.assert_allclose(expression_scores_from_aus(x / 3), expression_scores_from_aus(x))
    # ... but the strongest AU gates the whole frame, open from half a trace (0.1) to a trace:
    # at 0.15 half open (happiness 1 x 0.5), below 0.1 shut (nothing is an expression)
    s = expression_scores_from_aus(_aus(AU06=0.1, AU12=0.15))
    assert s[0] == pytest.approx(0.5) and expression_labels(s) == ["happiness"]
    s = expression_scores_from_aus(_aus(AU06=0.06, AU12=0.09))
    assert s[: len(EXPRESSIONS)].max() == 0 and expression_labels(s) == [NEUTRAL]
    # the gate: AU4 at 0.15 of the strongest (AU1) is half open (0.1 -> 0.2)
    s = expression_scores_from_aus(_aus(AU01=0.8, AU04=0.12, AU15=0.6))
    assert s[EXPRESSIONS.index("sadness")] == pytest.approx(0.5 * (1 + 0.15 + 0.75) / 3)
    # AU12 at half the strongest AU is below C: 12>=C is shut, 6+12 (AU6 at 0.25 of it) opens
    s = expression_scores_from_aus(_aus(AU06=0.2, AU12=0.4, AU14=0.8))
    assert s[0] == pytest.approx((0.25 + 0.5) / 2 * (0.04 + 0.16) / (0.04 + 0.16 + 0.64))
    # AU10 (disgust's and anger's: specificity 1/2) speaks against happiness at half weight
    s = expression_scores_from_aus(_aus(AU12=1.0, AU10=1.0))
    assert s[0] == pytest.approx(1.0 / (1.0 + 0.5))
    assert s[EXPRESSIONS.index("disgust")] == pytest.approx(1.0 / (1.0 + 1.0))
    assert expression_labels(s) == ["happiness"]


def test_sadness_and_fear_share_au1_and_au4():
    """1+4+15 is sadness; 1+2+4+5+20 fear; 1+4 alone is neither (no prototype of either)."""
    assert expression_labels(expression_scores_from_aus(_aus(AU01=0.8, AU04=0.6, AU15=0.7))) == [
        "sadness"
    ]
    fear = _aus(AU01=0.8, AU02=0.6, AU04=0.5, AU05=0.6, AU20=0.7)
    assert expression_labels(expression_scores_from_aus(fear)) == ["fear"]
    s = expression_scores_from_aus(_aus(AU01=0.8, AU04=0.6))
    assert s[EXPRESSIONS.index("sadness")] == 0 and s[EXPRESSIONS.index("fear")] == 0
    assert expression_labels(s) == [NEUTRAL]


def test_the_fear_brow_alone_is_fear():
    """1+2+4 (brows raised and drawn together) is fear; with AU15 besides and AU2 faint
    (0.25: its gate open) it is sadness, whose AU15 fear leaves unexplained."""
    x = _aus(AU01=0.6, AU02=0.5, AU04=0.5)
    assert expression_labels(expression_scores_from_aus(x)) == ["fear"]
    x = _aus(AU01=0.8, AU02=0.25, AU04=0.6, AU15=0.7)
    s = expression_scores_from_aus(x)
    assert expression_labels(s) == ["sadness"] and s[EXPRESSIONS.index("fear")] > 0


def test_surprise_with_fears_aus_is_fear():
    """Surprise's AUs are a subset of fear's: with fear's brow lowerer and lip stretcher
    besides, fear is the stronger (surprise leaves them unexplained)."""
    x = _aus(AU01=0.8, AU02=0.8, AU05=0.6, AU26=0.6)
    assert expression_labels(expression_scores_from_aus(x)) == ["surprise"]
    x = _aus(AU01=0.8, AU02=0.8, AU04=0.5, AU05=0.6, AU20=0.7, AU26=0.6)
    s = expression_scores_from_aus(x)
    assert expression_labels(s) == ["fear"] and s[2] > 0  # surprise still partly there


def test_a_glare_without_the_upper_lid_raised_is_anger(ids):
    """Anger's table variant without AU5, 4+7+23: AU7 (lid tightener) is not measured, and
    the AU table makes it of the orbital sphincter (0.5, AU6's muscle) and the lid's part
    (0.3), so its prototypes read it as AU6. The brows lowered, the lids tightened and the
    lips tightened, made through the AU table and read back, are anger; without the lip
    tightener, 4+7 is no prototype (neutral); and a measured AU7 at 0 is not replaced by
    AU6 (4+6+23 then opens no anger prototype)."""
    c = au_contractions({4: 0.8, 7: 0.8, 23: 0.7}, ids)
    assert expression_labels(expression_scores(c, ids)) == ["anger"]
    c = au_contractions({4: 0.8, 7: 0.8}, ids)
    assert expression_labels(expression_scores(c, ids)) == [NEUTRAL]
    x = _aus(AU04=0.8, AU06=0.4, AU23=0.6)
    x[rule_aus().index(7)] = np.nan  # (as the analysis gives it)
    assert expression_labels(expression_scores_from_aus(x)) == ["anger"]
    x[rule_aus().index(7)] = 0.0
    assert expression_scores_from_aus(x)[EXPRESSIONS.index("anger")] == 0
    # happiness's 6+12 keeps its label with AU6 standing in for AU7
    assert expression_labels(expression_scores_from_aus(_aus(AU06=0.6, AU12=0.9))) == ["happiness"]


def test_an_au_not_measured_skips_its_prototypes(ids):
    """The snakes' CSV (the paper's 12 muscles and the jaw) measures AU1, 2, 9, 12, 25 and 26
    only: sadness, fear and anger (every prototype needs an AU it lacks) are NaN, never a
    label; happiness, surprise and disgust are scored on the prototypes it can read."""
    from myoface.analysis.sections import PAPER_MUSCLES

    paper = list(PAPER_MUSCLES)
    pick = [ids.index(m) for m in paper]
    s = expression_scores(au_contractions({1: 0.9, 4: 0.6, 15: 0.8}, ids)[pick], paper)
    for e in ("sadness", "fear", "anger"):
        assert np.isnan(s[EXPRESSIONS.index(e)]), e
    assert expression_labels(s) == [NEUTRAL]  # (1 alone: no prototype)
    s = expression_scores(expression_contractions("surprise", 1.0, ids)[pick], paper)
    assert expression_labels(s) == ["surprise"]  # 1+2+26


def test_not_measured_frames_are_empty(ids):
    s = expression_scores(np.full((2, len(ids)), np.nan), ids)
    assert np.isnan(s).all() and expression_labels(s) == ["", ""]


def test_prototypes_read_only_aus_the_analysis_reads():
    aus = set(rule_aus())
    for e in EXPRESSIONS:
        assert prototypes()[e], e
        for p in prototypes()[e]:
            assert set(p.aus) <= aus, (e, p.text)
    # the data's apex AUs of each expression are among its own (the table's) AUs
    from myoface.analysis.expressions import ANY_EXPRESSION_AUS, EXPRESSION_AUS

    for e in EXPRESSIONS:
        assert set(expression_aus(e)) <= {*EXPRESSION_AUS[e], *ANY_EXPRESSION_AUS}, e
    sp = specificity((12, 10, 4, 14))
    np.testing.assert_allclose(sp, [1.0, 0.5, 1 / 3, 1.0])


# ---------------------------------------------------------------------- CSV and plot


def _frames(ids):
    from myoface.analysis.camera import HeadPose
    from myoface.analysis.trackers.landmark_fit import FitMeasurement

    pose = HeadPose.from_euler(5, 0, 0, (0, 0, -500))
    played = ["neutral", "happiness", None, "sadness", "anger"]
    out = []
    for k, name in enumerate(played):
        if name is None:
            c = np.full(len(ids), np.nan)
            out.append(FitMeasurement(k, k / 30, "no_face", c, None, float("nan")))
            continue
        c = np.zeros(len(ids)) if name == NEUTRAL else expression_contractions(name, 0.8, ids)
        out.append(FitMeasurement(k, k / 30, "ok", c, pose, 0.3))
    return out, played


@pytest.mark.parametrize("streamed", [False, True])
def test_csv_columns_round_trip(tmp_path, ids, streamed):
    """The expression columns after the head columns; read back as written, equal to the
    rule on the row's contractions; empty on the frame not measured; and the readers of
    the contractions (resynthesis, the viewer) ignore them without a warning."""
    from myoface.analysis.contractions_csv import (
        ContractionsCsvWriter,
        read_contractions_csv,
        write_contractions_csv,
    )

    frames, played = _frames(ids)
    path = tmp_path / "contractions.csv"
    if streamed:
        with ContractionsCsvWriter(path, ids, 0.3) as w:
            for f in frames:
                w.write(f)
    else:
        write_contractions_csv(path, ids, frames, 0.3)
    head = next(csv.reader(path.read_text().splitlines()))
    assert head[-8:] == [*EXPRESSION_COLUMNS, LABEL_COLUMN]
    scores, labels = read_expressions(path)
    assert labels == [p or "" for p in played]
    want = expression_scores(np.array([f.contractions for f in frames]), ids)
    np.testing.assert_allclose(scores, want, atol=5e-4)  # 3 decimals
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        times, table, quality = read_contractions_csv(path, ids)
    assert quality == ["ok", "ok", "no_face", "ok", "ok"]
    np.testing.assert_allclose(table[1], frames[1].contractions, atol=1e-5)
    # computed from the contractions for a CSV without the columns (an older analysis)
    old = tmp_path / "old.csv"
    rows = list(csv.reader(path.read_text().splitlines()))
    old.write_text("\n".join(",".join(r[:-8]) for r in rows) + "\n")
    s2, l2 = read_expressions(old, table, ids)
    assert l2 == labels
    np.testing.assert_allclose(s2, want, atol=2e-4)


def test_resynth_reads_a_csv_with_the_expression_columns(tmp_path, ids):
    from myoface.analysis.contractions_csv import write_contractions_csv
    from myoface.analysis.resynthesis import read_performance
    from myoface.model import load_face_model

    frames, _ = _frames(ids)
    path = tmp_path / "contractions.csv"
    write_contractions_csv(path, ids, frames, 0.3)
    perf = read_performance(path, load_face_model(None), pose=True)
    np.testing.assert_allclose(perf.contractions[1], frames[1].contractions, atol=1e-5)


def test_bad_label_is_a_clear_error(tmp_path, ids):
    from myoface.analysis.contractions_csv import write_contractions_csv
    from myoface.errors import MyofaceFormatError

    frames, _ = _frames(ids)
    path = tmp_path / "contractions.csv"
    write_contractions_csv(path, ids, frames, 0.3)
    text = path.read_text().replace(",happiness\n", ",joy\n")
    path.write_text(text)
    with pytest.raises(MyofaceFormatError, match="row 3: expression must be one of"):
        read_expressions(path)


def test_plot_written(tmp_path):
    """expressions.png: the strengths and a band of the labels' colours (happiness' amber
    where it is labelled); grey where not measured."""
    import imageio.v3 as iio

    from myoface.analysis.expressions import COLORS

    t = np.arange(30) / 30
    x = np.zeros((30, len(rule_aus())))
    x[10:20, rule_aus().index(12)] = 0.9
    s = expression_scores_from_aus(x)
    s[25] = np.nan
    labels = expression_labels(s)
    quality = ["ok"] * 25 + ["no_face"] + ["ok"] * 4
    path = tmp_path / "expressions.png"
    plot_expressions(path, t, s, labels, quality)
    img = iio.imread(path)[..., :3].astype(int)
    assert img.shape[:2] == (360, 800)
    amber = np.array([int(COLORS["happiness"][i : i + 2], 16) for i in (1, 3, 5)])
    assert (np.abs(img - amber).sum(axis=2) < 10).sum() > 1000  # the band and the curve
    assert labels[:10] == [NEUTRAL] * 10 and labels[12] == "happiness" and labels[25] == ""


# --------------------------------------------------------------------------- end to end


@needs_mediapipe
def test_analyze_labels_a_rendered_smile(tmp_path):
    """A rendered clip of the default face, at rest then smiling (happiness at 1.0), analysed
    as ``myoface analyze --tracker landmarks``: neutral at rest, happiness at the apex, and
    the plot beside contractions.png (4 s; 19 s on a loaded 2-core machine)."""
    from myoface.analysis.outputs import analyze_to_folder
    from myoface.analysis.video import open_video
    from myoface.bench.headmotion import camera_renderer
    from myoface.model import load_face_model
    from myoface.render import VideoWriter

    fm = load_face_model(None)
    ren = camera_renderer(fm.face, size=(320, 240), fov_deg=25.0)
    rot, tr = np.eye(3), np.array([0.0, 0.0, -500.0])
    smile = expression_contractions("happiness", 1.0, fm.ids)
    state, frames = fm.rest_state(), []
    truth = [np.zeros(fm.n_muscles)] * 6 + [smile] * 6
    for c in truth:
        state = fm.relax(c, state).state
        frames.append(ren.render(fm.skin_vertices(state), pose=(rot, tr)))
    video = tmp_path / "smile.mp4"
    with VideoWriter(video, fps=30) as w:
        for f in frames:
            w.write(f)
    out = tmp_path / "ana"
    analyze_to_folder(open_video(video), out, model=fm, tracker="landmarks")
    assert (out / "expressions.png").is_file() and (out / "contractions.png").is_file()
    _, labels = read_expressions(out / "contractions.csv")
    assert labels[:5] == [NEUTRAL] * 5, labels
    assert labels[8:] == ["happiness"] * 4, labels


# ------------------------------------------------------------------- the benchmark's parts


def test_episode_programme(ids):
    """Rest (zeros) first and between episodes, the apex held at the expression's
    contractions, onset and offset strictly between."""
    from myoface.bench.expression import episode_programme

    eps = (("happiness", 1.0), ("fear", 0.5))
    phases = (4, 2, 3, 2, 1)
    truth, played, phase = episode_programme(ids, eps, phases)
    assert len(truth) == 4 + 2 * (2 + 3 + 2 + 1) == len(played) == len(phase)
    assert phase[:6] == ["rest"] * 4 + ["onset"] * 2 and played[4] == "happiness"
    for k, (p, name) in enumerate(zip(phase, played, strict=True)):
        if p == "rest":
            assert not truth[k].any() and name == NEUTRAL
        elif p == "apex":
            want = expression_contractions(name, 1.0 if name == "happiness" else 0.5, ids)
            np.testing.assert_array_equal(truth[k], want)
        else:
            apex = expression_contractions(name, 1.0 if name == "happiness" else 0.5, ids)
            big = apex > 0
            assert np.all(truth[k][big] < apex[big]) and np.all(truth[k][big] > 0)


def test_score_labels():
    from myoface.bench.expression import score_labels

    played = ["neutral", "happiness", "happiness", "fear", "fear", "neutral"]
    phase = ["rest", "apex", "apex", "apex", "onset", "rest"]
    labels = ["neutral", "happiness", "neutral", "", "fear", "disgust"]
    r = score_labels(labels, played, phase, [0, 1, 1, 0.5, 0.5, 0])
    assert r["apex_accuracy"] == pytest.approx(1 / 3) and r["rest_accuracy"] == 0.5
    assert r["apex_frames"] == 3 and r["rest_frames"] == 2
    assert r["confusion"] == {
        "happiness": {"happiness": 1, "neutral": 1},
        "fear": {"not measured": 1},
        "neutral": {"neutral": 1, "disgust": 1},
    }
    assert r["apex_accuracy_per_episode"] == {"happiness 1": 0.5, "fear 0.5": 0.0}


def test_pool_scores_counts_each_frame_once():
    """The headline over several clips: apex frames and rest frames pooled, not the clips'
    shares averaged (a short clip does not weigh as much as a long one)."""
    from myoface.bench.expression import CLIPS, pool_scores

    runs = {
        "a": {"apex_accuracy": 1.0, "rest_accuracy": 0.5, "apex_frames": 30, "rest_frames": 10},
        "b": {"apex_accuracy": 0.0, "rest_accuracy": 1.0, "apex_frames": 10, "rest_frames": 30},
    }
    r = pool_scores(runs)
    assert r["apex_accuracy"] == pytest.approx(0.75) and r["rest_accuracy"] == pytest.approx(0.875)
    assert r["apex_frames"] == 40 and r["rest_frames"] == 40
    assert r["per_clip (apex / rest)"] == {"a": "1.000 / 0.500", "b": "0.000 / 1.000"}
    # the benchmark's clips: the first is the clip of before, each differs in its episodes,
    # its head's loop or its camera's noise
    assert next(iter(CLIPS)) == "bench"
    assert len({(e, loop, seed) for e, loop, seed in CLIPS.values()}) == len(CLIPS)
    assert len({seed for *_, seed in CLIPS.values()}) == len(CLIPS)


def test_model_landmarks_project_the_skin(ids):
    """The benchmark's perfect detector: the posed vertices through the fit's camera (a
    frontal head 500 mm away lands its nose tip near the image's centre)."""
    from myoface.analysis.camera import HeadPose
    from myoface.bench.expression import model_landmarks
    from myoface.bench.headmotion import SIZE
    from myoface.face import load_default_face

    face = load_default_face()
    pose = HeadPose.from_euler(0, 0, 0, (0, 0, -500))
    (pts,) = model_landmarks([pose], [face.vertices])
    assert pts.shape == (face.n_vertices, 2) and np.isfinite(pts).all()
    nose = pts[np.argmax(face.vertices[:, 2])]  # the vertex nearest the camera
    assert abs(nose[0] - SIZE[0] / 2) < 20 and abs(nose[1] - SIZE[1] / 2) < 60


def test_pattern_agreement_is_blind_to_a_gain(ids):
    """The benchmark's diagnosis: the fit's readings at a third of the truth keep every
    expression's pattern (cosine 1, every apex frame nearest its own pattern); readings that
    swap two expressions' patterns have it for neither."""
    from myoface.bench.expression import pattern_agreement

    names = ("happiness", "sadness", "surprise")
    truth = np.array([expression_contractions(n, 0.9, ids) for n in names])
    played, phase, level = list(names), ["apex"] * 3, [0.9] * 3
    r = pattern_agreement(truth * 0.3, truth, ids, played, phase, level)
    assert r["nearest_true_pattern"] == 1.0
    assert min(r["cosine"].values()) > 0.99, r
    swapped = truth[[1, 0, 2]] * 0.3
    r = pattern_agreement(swapped, truth, ids, played, phase, level)
    assert r["nearest_true_pattern_per_expression"] == {
        "happiness": 0.0,
        "sadness": 0.0,
        "surprise": 1.0,
    }
    assert r["cosine"]["happiness 0.9"] < 0.5


def test_readings_by_class(ids):
    """The truth's AUs of the played expression against the readings, the AUs read that were
    not played, and the readings at rest."""
    from myoface.bench.expression import readings_by_class

    smile = expression_contractions("happiness", 1.0, ids)
    brow = au_contractions({4: 0.5}, ids)
    truth = np.array([np.zeros(len(ids)), smile])
    est = np.array([brow, 1 - (1 - 0.5 * smile) * (1 - brow)])  # half the smile, and AU4
    r = readings_by_class(est, truth, ids, ["neutral", "happiness"], ["rest", "apex"])
    t12, e12 = (float(v) for v in r["happiness"]["played"]["AU12"].split(" -> "))
    assert t12 > 0.5 and e12 == pytest.approx(t12 / 2, abs=0.05)
    assert set(r["happiness"]["read, not played"]) == {"AU4"}
    assert r["rest"]["AU4"].startswith("0.50") and r["rest"]["AU12"].startswith("0.00")


# ---------------------------------------------------------------- the rest reference (video)


def _turning_rest(n=40, yaw_max=30.0):
    """AU readings of a face at rest whose head turns from frontal to ``yaw_max`` over ``n``
    frames, read by a fit that gives it anger's AUs in proportion to the turn (AU4 0.4, AU5
    0.3, AU23 0.5 at 30 deg: the kind of pose-driven reading the benchmark measures), and
    the head's angles (n, 3)."""
    yaw = np.linspace(0.0, yaw_max, n)
    x = np.array([_aus(AU04=0.4 * t, AU05=0.3 * t, AU23=0.5 * t) for t in yaw / 30.0])
    ang = np.column_stack([yaw, np.zeros(n), np.zeros(n)])
    return x, ang


def test_the_rest_reference_takes_off_readings_that_follow_the_pose():
    """Known answer: readings that are a linear function of the pose at rest. Read alone, the
    turned frames are anger; read in order by one ExpressionReader, every frame is neutral
    (each step of the turn adds less than half a trace above the reference learnt from the
    frames before); and a smile played on top at the turned pose (AU6 0.3, AU12 0.5) is
    happiness, which the frames alone do not say (anger's AUs are stronger)."""
    from myoface.analysis.expressions import ExpressionReader

    x, ang = _turning_rest()
    alone = expression_labels(expression_scores_from_aus(x))
    assert alone[-1] == "anger" and alone[0] == NEUTRAL
    r = ExpressionReader([], aus=rule_aus())
    labels = [r.read_aus(row, a)[1] for row, a in zip(x, ang, strict=True)]
    assert labels == [NEUTRAL] * len(x)
    assert r.n_neutral == len(x)
    ref = r.reference(ang[-1])
    np.testing.assert_allclose(ref, x[-1], atol=0.02)  # it has learnt the rest at 30 deg
    smile = x[-1] + _aus(AU06=0.3, AU12=0.5)
    assert expression_labels(expression_scores_from_aus(smile)) == ["anger"]
    s, lab = r.read_aus(smile, ang[-1])
    assert lab == "happiness" and s[0] > 0.9, s


def test_the_rest_reference_takes_off_readings_that_grow_with_the_turn_either_way():
    """Known answer: at rest the head turns to one side and then the other, and the fit reads
    AU6 and AU23 in proportion to how far it is turned, whichever way (0.35 and 0.45 at 30
    deg). A reference linear in the angles cannot follow that (a straight line through a
    V): the next sweep, read in order by one ExpressionReader, is neutral on every frame,
    and its reference at 30 deg either way is what it saw there."""
    from myoface.analysis.expressions import ExpressionReader

    yaw = np.concatenate(
        [np.linspace(0, 30, 16), np.linspace(30, -30, 31), np.linspace(-30, 0, 16)]
    )
    x = np.array([_aus(AU06=0.35 * t, AU23=0.45 * t) for t in np.abs(yaw) / 30.0])
    ang = np.column_stack([yaw, np.zeros_like(yaw), np.zeros_like(yaw)])
    r = ExpressionReader([], aus=rule_aus())
    for row, a in zip(x, ang, strict=True):  # (the first sweep: the reference learns)
        r.read_aus(row, a)
    labels = [r.read_aus(row, a)[1] for row, a in zip(x, ang, strict=True)]
    assert labels == [NEUTRAL] * len(x), labels
    for side in (30.0, -30.0):
        np.testing.assert_allclose(r.reference([side, 0.0, 0.0]), x[15], atol=0.03)
    np.testing.assert_allclose(r.reference([0.0, 0.0, 0.0]), 0.0, atol=0.03)


def test_the_rest_reference_does_not_extrapolate_above_what_it_saw():
    """A pose beyond any seen at rest: the reference stays within the largest reading of each
    AU on the neutral frames (it does not guess the readings of a turn it never saw)."""
    from myoface.analysis.expressions import ExpressionReader

    x, ang = _turning_rest(yaw_max=10.0)
    r = ExpressionReader([], aus=rule_aus())
    for row, a in zip(x, ang, strict=True):
        r.read_aus(row, a)
    far = r.reference([60.0, 0.0, 0.0])
    np.testing.assert_allclose(far, x.max(axis=0), atol=1e-9)
    assert (far <= x.max(axis=0) + 1e-12).all() and (far >= 0).all()


def test_a_held_expression_stays_its_label():
    """The reference learns only from frames labelled neutral: a smile held for 20 s (600
    frames) after 1 s at rest is happiness to its last frame (a baseline from a trailing
    window of every frame would have taken it for the rest)."""
    from myoface.analysis.expressions import ExpressionReader

    rest = _aus(AU17=0.05)
    smile = _aus(AU06=0.3, AU12=0.5, AU17=0.05)
    r = ExpressionReader([], aus=rule_aus())
    labels = [r.read_aus(rest if k < 30 else smile, [5.0, 0.0, 0.0])[1] for k in range(630)]
    assert labels[:30] == [NEUTRAL] * 30 and labels[30:] == ["happiness"] * 600
    assert r.n_neutral == 30


def test_without_a_pose_the_reference_is_the_level_at_rest():
    """The snakes' rows have no pose: the reference is each AU's level on the neutral frames
    (a face whose fit reads AU10 at 0.08 at rest: a raised upper lip is disgust from half a
    trace above it). Frames not measured (NaN) are skipped and learnt from not at all."""
    from myoface.analysis.expressions import ExpressionReader

    r = ExpressionReader([], aus=rule_aus())
    for k in range(10):
        _, lab = r.read_aus(_aus(AU10=0.08 + 0.005 * (k % 2)))
        assert lab == NEUTRAL
    s, lab = r.read_aus(np.full(len(rule_aus()), np.nan))
    assert lab == "" and np.isnan(s).all() and r.n_neutral == 10
    np.testing.assert_allclose(r.reference()[rule_aus().index(10)], 0.0825, atol=1e-6)
    s, lab = r.read_aus(_aus(AU10=0.25))  # 0.1675 above its rest: the level gate 0.675 open
    assert lab == "disgust" and s[EXPRESSIONS.index("disgust")] == pytest.approx(0.675), s
    s, lab = r.read_aus(_aus(AU10=0.14))  # 0.06 above: below half a trace, neutral
    assert lab == NEUTRAL, s


def test_expression_sequence_is_the_csvs(tmp_path, ids):
    """expression_sequence (what the benchmark scores) gives what the CSV writer writes, row
    by row, with the rows' head poses; a CSV without the expression columns has them
    computed the same way (with its pose columns) by read_expressions."""
    from myoface.analysis.camera import HeadPose
    from myoface.analysis.contractions_csv import ContractionsCsvWriter, read_contractions_csv
    from myoface.analysis.expressions import expression_sequence
    from myoface.analysis.trackers.landmark_fit import FitMeasurement

    rng = np.random.default_rng(3)
    table, frames, angles = [], [], []
    for k in range(24):
        c = np.clip(rng.normal(0.0, 0.04, len(ids)), 0, 1)
        if 12 <= k < 18:
            c = np.maximum(c, expression_contractions("surprise", 0.6, ids))
        a = (20 * np.sin(k / 5), 5 * np.cos(k / 7), 3.0)
        frames.append(
            FitMeasurement(k, k / 30, "ok", c, HeadPose.from_euler(*a, (0, 0, -500)), 0.3)
        )
        table.append(c)
        angles.append(HeadPose.from_euler(*a, (0, 0, -500)).angles_deg)
    path = tmp_path / "contractions.csv"
    with ContractionsCsvWriter(path, ids, 0.3) as w:
        for f in frames:
            w.write(f)
    scores, labels = read_expressions(path)
    s2, l2 = expression_sequence(np.array(table), ids, np.array(angles))
    assert labels == l2 and "surprise" in labels and NEUTRAL in labels
    np.testing.assert_allclose(scores, s2, atol=5e-4)
    rows = list(csv.reader(path.read_text().splitlines()))
    old = tmp_path / "old.csv"
    old.write_text("\n".join(",".join(r[:-8]) for r in rows) + "\n")
    _, tab, _ = read_contractions_csv(old, ids)
    s3, l3 = read_expressions(old, tab, ids)
    assert l3 == labels
    np.testing.assert_allclose(s3, s2, atol=2e-3)


def test_rest_readings_vs_pose_on_a_known_answer(ids):
    """The benchmark's diagnosis on readings made to follow the pose: AU17 linear in the yaw
    (correlation +1, R^2 1), AU23 in the turn |yaw| (correlation with |yaw| 1; a linear
    function of the signed angles explains nearly none of it, with |yaw| all of it)."""
    from myoface.bench.expression import rest_readings_vs_pose

    yaw = np.linspace(-30, 30, 41)
    c = np.array(
        [au_contractions({17: 0.3 + 0.2 * y / 30, 23: 0.4 * abs(y) / 30}, ids) for y in yaw]
    )
    ang = np.column_stack([yaw, 5 * np.sin(yaw / 7), np.zeros_like(yaw)])
    out = rest_readings_vs_pose(c, ids, ["rest"] * len(yaw), ang)
    assert out["AU17"]["corr yaw/pitch/roll"].startswith("+1.00"), out
    assert out["AU17"]["r2 linear in pose"] > 0.99 and abs(out["AU17"]["mean"] - 0.3) < 0.02
    assert out["AU23"]["corr |yaw|"] > 0.99
    assert out["AU23"]["r2 linear in pose"] < 0.2 < 0.99 < out["AU23"]["r2 with |yaw|"]


def test_rest_readings_vs_pose_tells_the_points_from_the_fits_pose(ids):
    """With the true angles, the diagnosis says whether a reading follows the pose (the
    points' view-dependent offsets) or the fit's error in it (the fit trading pose for
    muscles): AU12 made to follow the true pitch, AU10 the fit's pitch error (an error that
    does not follow the pitch)."""
    from myoface.bench.expression import rest_readings_vs_pose

    k = np.arange(60)
    pitch = 15 * np.sin(k / 6.0)
    err = 2 * np.sin(k / 2.3 + 0.7)
    c = np.array(
        [au_contractions({12: 0.3 - 0.2 * p / 15, 10: 0.2 + 0.1 * e / 2}, ids)
         for p, e in zip(pitch, err, strict=True)]
    )  # fmt: skip
    true = np.column_stack([np.zeros_like(pitch), pitch, np.zeros_like(pitch)])
    est = true + np.column_stack([np.zeros_like(err), err, np.zeros_like(err)])
    out = rest_readings_vs_pose(c, ids, ["rest"] * len(k), est, true)
    r12 = [float(v) for v in out["AU12"]["corr yaw/pitch/roll error"].split()]
    r10 = [float(v) for v in out["AU10"]["corr yaw/pitch/roll error"].split()]
    assert abs(r12[1]) < 0.3 < 0.95 < r10[1], out
    assert (
        "corr yaw/pitch/roll error"
        not in rest_readings_vs_pose(c, ids, ["rest"] * len(k), est)["AU12"]
    )


def _ceiling_clip(ids, read=None):
    """A clip for readings_ceiling: rest frames between apex episodes of the six expressions
    (two each, at 0.5 and 1.0), the head turning; the estimate is the truth at 0.25 of its
    strength (or each episode's contractions as ``read`` maps them) plus chin raiser and lip
    tightener readings that follow the turn |yaw| and the pitch squared (as the fit's do), and
    a little noise."""
    rng = np.random.default_rng(3)
    truth, est, played, phase = [], [], [], []
    spurious = []
    for lv in (0.5, 1.0):
        for name in EXPRESSIONS:
            for ph, n in (("rest", 12), ("apex", 6)):
                c = expression_contractions(name, lv, ids) if ph == "apex" else np.zeros(len(ids))
                for _ in range(n):
                    truth.append(c)
                    est.append(0.25 * (read(name, lv) if read and ph == "apex" else c))
                    played.append(name if ph == "apex" else "neutral")
                    phase.append(ph)
    k = np.arange(len(truth))
    ang = np.column_stack([30 * np.sin(k / 9.0), 15 * np.sin(k / 13.0 + 1), 5 * np.sin(k / 7.0)])
    for y, p in ang[:, :2]:
        spurious.append(au_contractions({17: abs(y) / 30, 23: 0.8 * (p / 15) ** 2}, ids))
    est = np.array(est) + np.array(spurious) + rng.normal(0, 0.003, (len(k), len(ids)))
    return est, np.array(truth), played, phase, ang


def test_readings_ceiling_on_a_known_answer(ids):
    """The benchmark's ceiling (what any rule on the fit's contractions could do): readings at
    a gain of 0.25 with pose-driven chin raiser and lip tightener taken off by its oracle rest
    reference tell every apex frame from rest and are each nearest their own pattern (with a
    reference linear in the angles, as the reader's, the episodes' residuals keep the turn's
    chin raiser and are alike at 0.47 only);
    readings that swap happiness's and sadness's patterns consistently fail the true patterns
    for those two and keep the fit's own consistency; readings that swap them in one episode
    only fail that too."""
    from myoface.bench.expression import readings_ceiling

    r = readings_ceiling(*_ceiling_clip(ids))
    assert r["presence"] == 1.0 and r["identity_true_patterns"] == 1.0, r
    assert r["identity_own_readings"] == 1.0

    swap = {"happiness": "sadness", "sadness": "happiness"}

    def consistently(name, lv):
        return expression_contractions(swap.get(name, name), lv, ids)

    r = readings_ceiling(*_ceiling_clip(ids, consistently))
    per = r["identity_true_patterns_per_expression"]
    assert per["happiness"] == per["sadness"] == 0.0 and per["anger"] == 1.0, r
    assert r["identity_own_readings"] == 1.0

    def once(name, lv):
        return expression_contractions(swap.get(name, name) if lv == 1.0 else name, lv, ids)

    r = readings_ceiling(*_ceiling_clip(ids, once))
    assert r["identity_true_patterns_per_expression"]["happiness"] == 0.5
    # each of the four episodes of the two is compared with the other episode of its
    # expression, read as the other's pattern: all four fail, the other eight are right
    assert r["identity_own_readings"] == pytest.approx(8 / 12, abs=1e-3), r
