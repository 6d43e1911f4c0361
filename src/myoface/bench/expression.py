"""Expressions recognised from the muscles, end to end: synthetic videos of the six basic
expressions on a person's face with its head moving, and the sample video's smile.

**Synthetic.** A face from a real photograph (:func:`myoface.bench.headmotion.personal_face`:
``face_from_photo`` on the sample video's first frame; the default face when the video or
MediaPipe is not there) plays each of the six expressions (their FACS commands,
``data/expressions.toml``) at intensity 0.5 and at 1.0 (a quick run: three of them at 0.75,
short episodes), each an episode of rest, onset, apex (held), offset, while the head moves
along the loop's 3-D trajectory
(:func:`~myoface.bench.headmotion.head_trajectory`: yaw +-30, pitch and roll +-15 deg). The
frames are rendered and degraded as a webcam would (:func:`~myoface.bench.headmotion.degraded_sequence`:
texture at half resolution, a room, moving light, noise, blur, H.264), read by MediaPipe's face
mesh and fitted in 3-D (:func:`~myoface.bench.headmotion.run_headmotion`, the calibration
frame chosen automatically), and the fitted contractions labelled by the rule
(:mod:`myoface.analysis.expressions`) as contractions.csv labels them: the frames in order,
each read above the person's rest reference at the fit's head pose
(:func:`~myoface.analysis.expressions.expression_sequence`). Scored: the share of the apex frames labelled with the
expression played, and of the rest frames (between episodes; not the onsets and offsets)
labelled neutral; the value is the lower of the two (the issue asks >= 0.9 of each), over
the frames of six clips pooled (:data:`CLIPS`, :func:`pool_scores`; a quick run: the first):
the benchmark's first clip and five more, the same face in other orders and intensities,
the head's loop started elsewhere (two of them turned 30 degrees at the start), other camera
noise (before 2026-12-06 the value was the first clip's alone, an optimistic draw; until
06:57 UTC that day, the first three's). The detail has both, per expression and intensity, the confusion (played -> labels counted), the
rule on the true contractions (what the rule says when the fit is perfect), the rule on each
frame alone (no rest reference), whether the AUs the fit reads at rest follow the head's pose
(:func:`rest_readings_vs_pose`), what the fit makes
of each AU (:func:`au_readings`: its gain, and its reading where the AU is absent), per class
of frame (:func:`readings_by_class`: each played expression's AUs, true against read, the AUs
read that were not played, and the readings at rest), whether the fit keeps each
expression's pattern of AUs whatever its gain (:func:`pattern_agreement`), how far any rule
on the fit's contractions could go, given an oracle rest reference and the true patterns
(:func:`readings_ceiling`: presence, identity; docs/expressions.md), and, in a
full run, all of it again with the head still (what the head's motion costs), with the
head still on the clean renders (what the camera costs), and with the fit given the model's
own projected vertices instead of MediaPipe's points, head moving and still (what the
detector costs; :func:`model_landmarks`).

**The better trackers and the AU-space prior** (:data:`VARIANTS`; docs/expression_trackers.md):
the same clip, head moving, fitted with the model-anchored tracker (``--flow``), with the
photometric term (``--photometric``), and each of those and the default with the fit's
AU-space prior (:mod:`myoface.analysis.au_prior`, ``FitSettings(au_prior_sigma=0.1)``); in a
full run also the flow on the clean renders (what the camera costs it) and the sample video
with ``--flow``. The benchmark's value stays the default analysis'.

**The sample video** (``single_face.mp4``, 72 frames at 30 fps: a man at rest who smiles):
analysed as ``myoface analyze --tracker landmarks`` does (:func:`~myoface.analysis.outputs.analyze_to_folder`),
its labels read from the CSV. Rest and smile were judged by eye on the frames (2026-12-02:
every 6th frame, then every frame of the onset, 12-27, and of the end, 64-71): frames 0-16
are at rest (lips closed, lip corners still); from 17 the lip corners rise, the teeth show
from 20, and from 22 to 68 the smile is held (broad, teeth apart, one blink at 26); at 69 it
fades, at 70 the lips close and at 71 the face is nearly back at rest. Scored: rest = frames
0-15 labelled neutral, smile = frames 22-68 labelled happiness (the onset 16-21 and the
offset 69-71 are not scored; the detail has their labels). A quick run analyses the first
40 frames.

The rule was written from the FACS Investigator's Guide's table (see
:mod:`myoface.analysis.expressions`), not fitted to these clips.
"""

from __future__ import annotations

from collections import Counter

import numpy as np

from myoface.bench import Measurement, benchmark

#: the episodes of the full run: (expression, intensity), each expression at both ends of
#: the issue's range, the order mixed so that each meets the head in other poses
EPISODES = (
    ("happiness", 1.0),
    ("sadness", 0.5),
    ("surprise", 1.0),
    ("fear", 0.5),
    ("anger", 1.0),
    ("disgust", 0.5),
    ("happiness", 0.5),
    ("sadness", 1.0),
    ("surprise", 0.5),
    ("fear", 1.0),
    ("anger", 0.5),
    ("disgust", 1.0),
)
#: the held-out clips' episodes (the person's face, other orders and intensities; written
#: 2026-12-05 for ``tools/expression_runs.py``, never tuned on): ``HELDP`` at 0.6-0.9,
#: ``P2`` at both ends of the range in a third order
HELDP = (
    ("anger", 0.7), ("surprise", 0.6), ("disgust", 0.9), ("sadness", 0.8), ("happiness", 0.6),
    ("fear", 0.7), ("surprise", 0.9), ("sadness", 0.6), ("anger", 0.9), ("fear", 0.8),
    ("disgust", 0.6), ("happiness", 0.9),
)  # fmt: skip
P2 = (
    ("fear", 1.0), ("disgust", 0.5), ("sadness", 1.0), ("happiness", 0.5), ("anger", 0.5),
    ("surprise", 1.0), ("fear", 0.5), ("sadness", 0.5), ("disgust", 1.0), ("anger", 1.0),
    ("happiness", 1.0), ("surprise", 0.5),
)  # fmt: skip
#: the clips the headline pools (a full run; a quick run has the first alone): name ->
#: (episodes, where the head's loop starts (a fraction of the way round), the camera's noise
#: seed). ``bench`` is the clip of before 2026-12-06 (the detail's variants are on it); the
#: other two meet each expression with the head in other poses and under other noise. One
#: clip's numbers moved with its draw by more than settings changed them (2026-12-05, the
#: default analysis: 0.71 / 0.76 on ``bench`` where four held-out clips gave 0.68-0.80 /
#: 0.69-0.93), and a decision read on it alone went the wrong way for the others.
#: Since 2026-12-06 06:57 UTC also ``h3``, ``h4``, ``h5`` (until then held out of the
#: benchmark by ``tools/expression_calibration.py``): the same episodes in other orders, the
#: head's loop started elsewhere, camera seeds 3-5; ``h4`` and ``h5`` start with the head
#: turned 30 degrees, where the calibration frame then is (the first three start nearly
#: frontal), and read worse (docs/expressions.md, "What holds the readings"). Why six: a
#: clip's accuracies move by up to 5 points when the appearance's registered pose is turned
#: by half a degree either way (measured on ``bench``: apex 70.8-76.0 %, rest 74.1-80.2 %,
#: no direction better), so a clip's number is read to about +-5 points, and the clips that
#: start turned are the ones the analysis reads worst.
CLIPS = {
    "bench": (EPISODES, 0.0, 0),
    "heldp": (HELDP, 0.0, 1),
    "p2": (P2, 1 / 3, 2),
    "h3": (tuple(reversed(P2)), 2 / 3, 3),
    "h4": (tuple(reversed(HELDP)), 1 / 6, 4),
    "h5": (EPISODES[6:] + EPISODES[:6], 0.5, 5),
}
#: a quick run (a smoke run of the pipeline, about 30 frames): three expressions, at the
#: middle of the range
QUICK_EPISODES = (("happiness", 0.75), ("surprise", 0.75), ("sadness", 0.75))
#: frames of each phase (30 fps): (first rest, onset, apex, offset, rest after)
PHASES = (20, 6, 8, 6, 8)
QUICK_PHASES = (6, 2, 3, 2, 2)
#: the sample video's rest and smile frames (judged by eye; see the module's docstring)
SAMPLE_REST = range(0, 16)
SAMPLE_SMILE = range(22, 69)
SAMPLE_QUICK_FRAMES = 40


def episode_programme(ids, episodes, phases=PHASES):
    """The truth of a sequence: contractions (T, M) over ``ids``, and per frame the played
    expression and its phase (``"rest"``, ``"onset"``, ``"apex"``, ``"offset"``). Each episode:
    onset and offset half raised cosines, the apex held; rest (zero) between them."""
    from myoface.control import expression_contractions

    first, n_on, n_apex, n_off, n_rest = phases
    rows, played, phase = [], [], []

    def add(c, name, ph):
        rows.append(c)
        played.append(name)
        phase.append(ph)

    zero = np.zeros(len(ids))
    for _ in range(first):
        add(zero, "neutral", "rest")
    for name, intensity in episodes:
        apex = expression_contractions(name, intensity, ids)
        for k in range(n_on):
            add(apex * 0.5 * (1 - np.cos(np.pi * (k + 1) / (n_on + 1))), name, "onset")
        for _ in range(n_apex):
            add(apex, name, "apex")
        for k in range(n_off):
            add(apex * 0.5 * (1 + np.cos(np.pi * (k + 1) / (n_off + 1))), name, "offset")
        for _ in range(n_rest):
            add(zero, "neutral", "rest")
    return np.array(rows), played, phase


def score_labels(labels, played, phase, intensity=None) -> dict:
    """Apex accuracy (the played expression), rest accuracy (neutral), the confusion
    (``{played: {label: count}}``, apex frames; ``"neutral"`` for the rest frames) and, with
    ``intensity`` (per frame), the apex accuracy per expression and intensity."""
    apex = [k for k, p in enumerate(phase) if p == "apex"]
    rest = [k for k, p in enumerate(phase) if p == "rest"]
    confusion: dict = {}
    for k in apex + rest:
        lab = labels[k] or "not measured"
        confusion.setdefault(played[k], Counter())[lab] += 1
    out = {
        "apex_accuracy": float(np.mean([labels[k] == played[k] for k in apex])),
        "rest_accuracy": float(np.mean([labels[k] == "neutral" for k in rest])),
        "apex_frames": len(apex),
        "rest_frames": len(rest),
        "confusion": {p: dict(c.most_common()) for p, c in confusion.items()},
    }
    if intensity is not None:
        per: dict = {}
        for k in apex:
            per.setdefault(f"{played[k]} {intensity[k]:g}", []).append(labels[k] == played[k])
        out["apex_accuracy_per_episode"] = {k: float(np.mean(v)) for k, v in per.items()}
    return out


_cache: dict = {}


def au_readings(estimate, truth, ids) -> dict:
    """What the fit makes of each AU (the rule's inputs, :func:`~myoface.analysis.expressions.au_fractions`):
    its gain (least-squares slope through 0 of the estimated on the true intensity, over the
    frames where the truth has it at a trace or more) and its mean reading on frames where
    the truth has none of it; ``{"AU12": {"gain": .., "frames": .., "when_absent": ..}}``."""
    from myoface.analysis.expressions import TRACE, au_fractions, rule_aus

    xe, xt = au_fractions(estimate, ids), au_fractions(truth, ids)
    out = {}
    for j, a in enumerate(rule_aus()):
        e, t = xe[:, j], xt[:, j]
        if not np.isfinite(t).any():
            continue
        on = np.isfinite(e) & (t >= TRACE)
        off = np.isfinite(e) & (t <= 0.01)
        gain = float((e[on] * t[on]).sum() / (t[on] ** 2).sum()) if on.any() else None
        out[f"AU{a}"] = {
            "gain": None if gain is None else round(gain, 3),
            "frames": int(on.sum()),
            "when_absent": round(float(e[off].mean()), 3) if off.any() else None,
        }
    return out


def readings_by_class(estimate, truth, ids, played, phase) -> dict:
    """What the rule is given, per class of frame: for each played expression, its apex
    frames' mean true and read intensity of every AU the truth has there (``"AU12": "0.68 ->
    0.25"``) and the AUs read at 0.2 or more that the truth does not have (spurious); and, on
    the rest frames, each AU's mean and 90th-percentile reading where nothing is played
    (``{"rest": {"AU23": "0.52 (p90 1.00)"}}``)."""
    from myoface.analysis.expressions import TRACE, au_fractions, rule_aus

    xe, xt = au_fractions(estimate, ids), au_fractions(truth, ids)
    read = np.isfinite(xe).any(axis=0) & np.isfinite(xt).any(axis=0)  # (AU7 is never read)
    xe[:, ~read], xt[:, ~read] = 0.0, 0.0
    played, phase = np.asarray(played), np.asarray(phase)
    out: dict = {}
    for name in dict.fromkeys(played[phase == "apex"]):
        m = (played == name) & (phase == "apex")
        t, e = np.nanmean(xt[m], axis=0), np.nanmean(xe[m], axis=0)
        own = {f"AU{a}": f"{t[j]:.2f} -> {e[j]:.2f}" for j, a in enumerate(rule_aus())
               if read[j] and t[j] >= 0.05}  # fmt: skip
        extra = {f"AU{a}": f"0 -> {e[j]:.2f}" for j, a in enumerate(rule_aus())
                 if read[j] and t[j] < 0.05 and e[j] >= TRACE}  # fmt: skip
        out[str(name)] = {"played": own, "read, not played": extra}
    rest = phase == "rest"
    if rest.any():
        mean, p90 = np.nanmean(xe[rest], axis=0), np.nanpercentile(xe[rest], 90, axis=0)
        out["rest"] = {f"AU{a}": f"{mean[j]:.2f} (p90 {p90[j]:.2f})"
                       for j, a in enumerate(rule_aus()) if read[j]}  # fmt: skip
    return out


def pattern_agreement(estimate, truth, ids, played, phase, intensity) -> dict:
    """Diagnosis, not the rule: whether the fit keeps each expression's *pattern* of AUs, what
    a rule that compares patterns (blind to a gain the fit puts on every AU) would need.
    ``cosine``: per played expression and intensity, the cosine between the mean AU
    intensities the fit reads on its apex frames and the true ones (1: the same pattern at
    any gain); ``nearest_true_pattern``: the share of apex frames whose read AUs are nearer
    (by cosine) to the played expression's true apex pattern than to any other expression's,
    the best that matching patterns could do with the true patterns known (neutral aside)."""
    from myoface.analysis.expressions import au_fractions

    xe = np.nan_to_num(au_fractions(estimate, ids))
    xt = np.nan_to_num(au_fractions(truth, ids))
    played, phase = np.asarray(played), np.asarray(phase)
    level = np.asarray(intensity, dtype=np.float64)
    apex = phase == "apex"

    def unit(v):
        n = np.linalg.norm(v, axis=-1, keepdims=True)
        return v / np.where(n > 0, n, 1.0)

    names = list(dict.fromkeys(played[apex]))
    cosine = {}
    for name in names:
        for lv in sorted(set(level[apex & (played == name)])):
            m = apex & (played == name) & (level == lv)
            c = float(unit(xe[m].mean(axis=0)) @ unit(xt[m].mean(axis=0)))
            cosine[f"{name} {lv:g}"] = round(c, 2)
    templates = unit(np.array([xt[apex & (played == n)].mean(axis=0) for n in names]))
    nearest = np.asarray(names)[np.argmax(unit(xe[apex]) @ templates.T, axis=1)]
    right = nearest == played[apex]
    return {
        "cosine": cosine,
        "nearest_true_pattern": round(float(right.mean()), 3),
        "nearest_true_pattern_per_expression": {
            n: round(float(right[played[apex] == n].mean()), 3) for n in names
        },
    }


def rest_readings_vs_pose(estimate, ids, phase, angles_deg, angles_true=None) -> dict:
    """Whether the AUs the fit reads at rest follow the head's pose (the fit's angles): per AU
    read at 0.05 or more on average on the rest frames, its mean reading, its correlation
    with the yaw, pitch and roll and with the turn (|yaw|), and the share of its variance a
    linear function of (yaw, pitch, roll) explains (R^2, the rest reference's model,
    :class:`~myoface.analysis.expressions.ExpressionReader`) on those frames, and with the
    turn |yaw| as a fourth term;
    ``{"AU17": {"mean": .., "corr yaw/pitch/roll": "+0.30 -0.51 +0.09", "corr |yaw|": ..,
    "r2 linear in pose": ..}}``. With ``angles_true`` (the true angles, a synthetic clip's),
    also its correlation with the fit's error in each angle (fit minus truth,
    ``"corr yaw/pitch/roll error"``): readings that follow the pose but not its error come from
    the points (the detector's or the tracker's view-dependent offsets), not from the fit
    trading its pose for muscles."""
    from myoface.analysis.expressions import au_fractions, rule_aus

    x = au_fractions(estimate, ids)
    a = np.asarray(angles_deg, dtype=np.float64)
    rest = (np.asarray(phase) == "rest") & np.isfinite(a).all(axis=1)
    rest &= np.isfinite(np.nan_to_num(x, nan=0.0)).all(axis=1)
    out: dict = {}
    if rest.sum() < 5:
        return out
    f = np.column_stack([np.ones(rest.sum()), a[rest]])
    for j, au in enumerate(rule_aus()):
        y = x[rest, j]
        if not np.isfinite(y).all() or y.mean() < 0.05 or y.std() == 0:
            continue
        r2 = [_r2(g, y) for g in (f, np.column_stack([f, np.abs(a[rest, 0])]))]

        out[f"AU{au}"] = {
            "mean": round(float(y.mean()), 3),
            "corr yaw/pitch/roll": " ".join(f"{_corr(y, a[rest, i]):+.2f}" for i in range(3)),
            "corr |yaw|": round(_corr(y, np.abs(a[rest, 0])), 2),
            "r2 linear in pose": round(r2[0], 2),
            "r2 with |yaw|": round(r2[1], 2),
        }
        if angles_true is not None:
            e = (a - np.asarray(angles_true, dtype=np.float64))[rest]
            out[f"AU{au}"]["corr yaw/pitch/roll error"] = " ".join(
                f"{_corr(y, e[:, i]):+.2f}" for i in range(3)
            )
    return out


def _oracle_pose_features(angles_deg) -> np.ndarray:
    """Pose features of :func:`readings_ceiling`'s rest reference: 1, the angles, |yaw| and
    the angles squared (deg / 30), a richer function of the pose than the reader's."""
    a = np.nan_to_num(np.asarray(angles_deg, dtype=np.float64)) / 30.0
    return np.column_stack([np.ones(len(a)), a, np.abs(a[:, :1]), a**2])


def readings_ceiling(estimate, truth, played, phase, angles_deg) -> dict:
    """Diagnosis, not the rule: how far *any* rule on the fit's contractions could go, with the
    answers it does not have given to it. Each frame's contractions are taken relative to an
    **oracle rest reference**: per muscle, a least-squares function of the head's pose (the
    *true* angles; 1, yaw, pitch, roll, |yaw| and the angles squared) fitted to the video's
    true rest frames, all of them, before and after (the reader has only the frames before,
    and only those it labels neutral, and the fit's angles). Then, over the apex and rest
    frames:

    - ``presence``: whether the face moved at all: each frame's largest muscle residual in
      units of that muscle's spread at rest (a z-score), and the best over all thresholds of
      the lower of the apex frames above it and the rest frames below (the threshold chosen on
      the answers: an upper bound on telling expression from rest);
    - ``identity_true_patterns``: the share of apex frames whose residual is nearest (cosine)
      to the played expression's *true* contraction pattern (the mean of its apex frames'
      true contractions) among the six: what matching prototypes could do, given the exact
      prototypes the clip plays and the presence;
    - ``identity_own_readings``: the same against the fit's own mean residual on the *other*
      apex episodes of each expression (leave one episode out): whether the fit reads an
      expression alike from one episode to the next, at another intensity and head pose (only
      when every expression has two episodes or more).

    The benchmark's target (0.9 of each) needs presence and identity both near 0.9; where the
    identity is far below, no rule on these contractions reaches it (it is the fit's)."""
    c = np.asarray(estimate, dtype=np.float64)
    t = np.asarray(truth, dtype=np.float64)
    played, phase = np.asarray(played), np.asarray(phase)
    ok = np.isfinite(c).all(axis=1)
    rest, apex = ok & (phase == "rest"), ok & (phase == "apex")
    if rest.sum() < 10 or not apex.any():
        return {}
    f = _oracle_pose_features(angles_deg)
    w, *_ = np.linalg.lstsq(f[rest], c[rest], rcond=None)
    r = np.where(ok[:, None], c - f @ w, 0.0)
    spread = r[rest].std(axis=0)
    z = (np.abs(r) / np.where(spread > 1e-6, spread, np.inf)).max(axis=1)
    best = 0.0
    for th in np.unique(z[apex | rest]):
        best = max(best, min(float((z[apex] >= th).mean()), float((z[rest] < th).mean())))
    names = list(dict.fromkeys(played[apex]))

    def unit(v):
        n = np.linalg.norm(v, axis=-1, keepdims=True)
        return v / np.where(n > 0, n, 1.0)

    true = unit(np.array([t[apex & (played == e)].mean(axis=0) for e in names]))
    nearest = np.asarray(names)[np.argmax(unit(r[apex]) @ true.T, axis=1)]
    right = nearest == played[apex]
    out = {
        "presence": round(best, 3),
        "identity_true_patterns": round(float(right.mean()), 3),
        "identity_true_patterns_per_expression": {
            e: round(float(right[played[apex] == e].mean()), 2) for e in names
        },
    }
    idx = np.flatnonzero(apex)
    episodes = np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1)
    of = [str(played[ep[0]]) for ep in episodes]
    if all(of.count(e) >= 2 for e in names):
        hits = []
        for k, ep in enumerate(episodes):
            cents = unit(np.array([
                r[np.concatenate([q for j, q in enumerate(episodes) if j != k and of[j] == e])]
                .mean(axis=0) for e in names
            ]))  # fmt: skip
            hits += list(np.asarray(names)[np.argmax(unit(r[ep]) @ cents.T, axis=1)] == of[k])
        out["identity_own_readings"] = round(float(np.mean(hits)), 3)
    return out


def _r2(f, y) -> float:
    """The share of the variance of ``y`` a least-squares fit on the columns of ``f`` explains."""
    w, *_ = np.linalg.lstsq(f, y, rcond=None)
    return float(1.0 - ((y - f @ w) ** 2).sum() / ((y - y.mean()) ** 2).sum())


def _corr(y, v) -> float:
    return float(np.corrcoef(y, v)[0, 1]) if np.std(v) > 0 else 0.0


def model_landmarks(poses, skins):
    """The landmarks a perfect detector would give: the model's own skin vertices (the 468 of
    MediaPipe's topology) posed and projected by the fit's camera, (x, y) pixels, no depth."""
    from myoface.analysis.camera import PinholeCamera
    from myoface.bench.headmotion import FOV_DEG, SIZE

    cam = PinholeCamera.for_image(SIZE[0], SIZE[1], FOV_DEG)
    return [cam.project(p.apply(s)) for p, s in zip(poses, skins, strict=True)]


#: the variants the detail has beside the default (name, tracker, AU-space prior), on the
#: same clip, head moving
VARIANTS = (
    ("points", "fit", False),
    ("flow", "flow", False),
    ("AU prior", "fit", True),
    ("flow, AU prior", "flow", True),
    ("photometric, AU prior", "photometric", True),
    ("photometric with flow", "flow+photometric", False),  # (myoface analyze --flow)
)
#: the trackers the detail measures: the 3-D fit on MediaPipe's points alone (``myoface
#: analyze --no-photometric``, the default before 2026-12-05), that fit with the
#: model-anchored point tracker (``--no-photometric --flow``), the fit with its photometric
#: term (``myoface analyze``'s default) and the photometric fit with the flow (``--flow``)
TRACKERS = ("fit", "flow", "photometric", "flow+photometric")
#: the analysis' default among :data:`TRACKERS`
DEFAULT_TRACKER = "photometric"


def _clip(quick: bool, still: bool, clean: bool, clip: str = "bench") -> tuple:
    """The synthetic clip ``clip`` (:data:`CLIPS`; cached): truth, played, phase, intensity,
    poses, skins, frames, the camera's report and MediaPipe's points on the frames."""
    key = ("clip", bool(quick), bool(still), bool(clean)) + ((clip,) if clip != "bench" else ())
    if key in _cache:
        return _cache[key]
    from dataclasses import replace

    from myoface.bench.headmotion import (
        _model,
        degraded_sequence,
        detect_sequence,
        head_trajectory,
        relaxed_skins,
        render_sequence,
    )
    from myoface.render.degrade import CameraDegradation

    fm = _model()
    episodes, loop, seed = _episodes(quick, clip)
    phases = QUICK_PHASES if quick else PHASES
    truth, played, phase = episode_programme(fm.ids, episodes, phases)
    intensity = _intensities(episodes, phases)
    poses = head_trajectory(len(truth), still, phase=loop)
    skins = relaxed_skins(fm, truth)
    if clean:
        frames, camera = render_sequence(fm.face, poses, skins), None
    else:
        frames, camera = degraded_sequence(
            fm.face, poses, skins, replace(CameraDegradation(), seed=seed)
        )
    points, _ = detect_sequence(frames)
    _cache[key] = (truth, played, phase, intensity, poses, skins, frames, camera, points)
    return _cache[key]


def _episodes(quick: bool, clip: str) -> tuple:
    """The episodes of ``clip`` (:data:`CLIPS`), where its head's loop starts and its camera
    seed; a quick run's short episodes for ``bench``."""
    if clip not in CLIPS:
        raise ValueError(f"clip must be one of {tuple(CLIPS)}; got {clip!r}")
    episodes, loop, seed = CLIPS[clip]
    return (QUICK_EPISODES if quick and clip == "bench" else episodes), loop, seed


def _synthetic(quick: bool, still: bool = False, clean: bool = False, exact=False,
               tracker: str | None = None, au_prior: bool = False,
               overrides=(), clip: str = "bench", registration=None) -> dict:  # fmt: skip
    """The synthetic run's detail (cached) on ``clip`` (:data:`CLIPS`); ``still``: the head
    frontal and still; ``clean``:
    on the renderer's own frames (:func:`~myoface.bench.headmotion.render_sequence`), not
    degraded by a camera; ``exact``: the fit given the model's own projected vertices
    (:func:`model_landmarks`) in place of MediaPipe's points on the frames (nothing
    rendered); ``tracker`` (:data:`TRACKERS`; None: :data:`DEFAULT_TRACKER`, or ``"fit"``
    with ``exact``, which has no frames to read): ``"fit"`` the fit on MediaPipe's points
    alone (``--no-photometric``), ``"flow"`` that fit with the model-anchored tracker's points
    (``--no-photometric --flow``), ``"photometric"`` the fit with its photometric term (the
    analysis' default), ``"flow+photometric"`` both (``--flow``); ``au_prior``: with the fit's AU-space prior
    (:mod:`myoface.analysis.au_prior`, ``FitSettings(au_prior_sigma=AU_PRIOR_SIGMA)``);
    ``overrides``: ``((field, value), ...)`` of :class:`~myoface.analysis.weights.FitSettings`
    set on top (a study's variant, e.g. ``(("sparsity", 0.0),)``: ``tools/expression_stages.py``);
    ``registration``: frames that register the appearance in place of the calibration
    window's (:func:`~myoface.bench.headmotion.run_headmotion`'s; ``tools/expression_calibration.py``)."""
    if tracker is None:
        tracker = "fit" if exact else DEFAULT_TRACKER
    if tracker not in TRACKERS:
        raise ValueError(f"tracker must be one of {TRACKERS}; got {tracker!r}")
    overrides = tuple((str(k), v) for k, v in overrides)
    key = ("synthetic", bool(quick), bool(still), bool(clean), bool(exact), tracker,
           bool(au_prior)) + ((overrides,) if overrides else ()) + (
        (("clip", clip),) if clip != "bench" else ()) + (
        (("registration", tuple(int(k) for k in registration)),) if registration is not None
        else ())  # fmt: skip
    if key in _cache:
        return _cache[key]
    import time

    from myoface.analysis.au_prior import AU_PRIOR_SIGMA
    from myoface.analysis.expressions import (
        expression_labels,
        expression_scores,
        expression_sequence,
    )
    from myoface.analysis.weights import FitSettings
    from myoface.bench.headmotion import _cache as hm_cache
    from myoface.bench.headmotion import (
        _model,
        head_trajectory,
        relaxed_skins,
        run_headmotion,
    )

    t0 = time.perf_counter()
    fm = _model()
    episodes, loop, _ = _episodes(quick, clip)
    phases = QUICK_PHASES if quick else PHASES
    frames = None
    if exact:
        truth, played, phase = episode_programme(fm.ids, episodes, phases)
        intensity = _intensities(episodes, phases)
        poses = head_trajectory(len(truth), still, phase=loop)
        skins = relaxed_skins(fm, truth)
        points, camera = model_landmarks(poses, skins), None
    else:
        truth, played, phase, intensity, poses, skins, frames, camera, points = _clip(
            quick, still, clean, clip
        )
    # (the tracker's settings, explicit: FitSettings' default is the photometric fit)
    settings = FitSettings(
        photometric="photometric" in tracker,
        au_prior_sigma=AU_PRIOR_SIGMA if au_prior else None,
        **dict(overrides),
    )
    res = run_headmotion(
        fm, points, truth, poses, skins, settings=settings,
        frames=frames if tracker != "fit" else None, anchored_flow="flow" in tracker,
        registration=registration,
    )  # fmt: skip
    # as contractions.csv has them: the frames in order, above the rest reference at the
    # fit's head pose (ExpressionReader)
    _, labels = expression_sequence(res.estimate, fm.ids, res.angles_est)
    _, ceiling = expression_sequence(truth, fm.ids, res.angles_true)
    alone = expression_labels(expression_scores(res.estimate, fm.ids))  # (no reference)
    out = {
        "clip": clip,
        "face": hm_cache.get("face_kind", "default"),
        "tracker": {
            "fit": "the 3-D fit on MediaPipe's points alone (--no-photometric)",
            "flow": "that fit with the model-anchored tracker's points (--no-photometric --flow)",
            "photometric": "the fit with its photometric term (the analysis' default)",
            "flow+photometric": "the fit with both (--flow)",
        }[tracker]
        + (f", with the AU-space prior (sigma {AU_PRIOR_SIGMA:g})" if au_prior else ""),
        "frames": len(truth),
        "episodes": [f"{e} {i:g}" for e, i in episodes],
        "phases_frames": dict(
            zip(("first rest", "onset", "apex", "offset", "rest"), phases, strict=True)
        ),
        "head": "still (frontal)"
        if still
        else "moving (yaw +-30, pitch/roll +-15 deg, translation)"
        + (f", the loop started {loop:.2g} of the way round" if loop else ""),
        "renders": (
            "none: the model's own vertices projected, in place of MediaPipe's points"
            if exact
            else "clean (the renderer's own)"
            if clean
            else "degraded by the camera (render.degrade)"
        ),
        "calibration_frame": int(res.calibration_index),
        "frames_fitted": int(np.isfinite(res.estimate).all(axis=1).sum()),
        **score_labels(labels, played, phase, intensity),
        "rule_on_true_contractions": {
            k: v
            for k, v in score_labels(ceiling, played, phase).items()
            if k in ("apex_accuracy", "rest_accuracy")
        },
        "each_frame_alone (no rest reference)": {
            k: v
            for k, v in score_labels(alone, played, phase).items()
            if k in ("apex_accuracy", "rest_accuracy")
        },
        "rest_readings_vs_pose": rest_readings_vs_pose(
            res.estimate, fm.ids, phase, res.angles_est, res.angles_true
        ),
        "au_readings": au_readings(res.estimate, truth, fm.ids),
        "readings_by_class": readings_by_class(res.estimate, truth, fm.ids, played, phase),
        "pattern_agreement": pattern_agreement(
            res.estimate, truth, fm.ids, played, phase, intensity
        ),
        "readings_ceiling": readings_ceiling(res.estimate, truth, played, phase, res.angles_true),
        "contraction_rmse_median": round(float(res.summary()["rmse_median_all"]), 4),
        "camera": camera,
        "seconds": round(time.perf_counter() - t0, 1),
    }
    _cache[key] = out
    # (the run's arrays, for a study of the rule on them: scripts, not the benchmark)
    _cache[("arrays", *key[1:])] = {
        "estimate": res.estimate, "truth": truth, "angles_est": res.angles_est,
        "angles_true": res.angles_true, "played": np.asarray(played),
        "phase": np.asarray(phase), "intensity": np.asarray(intensity),
        "ids": np.asarray(fm.ids),
    }  # fmt: skip
    return out


def _intensities(episodes, phases) -> list[float]:
    first, n_on, n_apex, n_off, n_rest = phases
    out = [0.0] * first
    for _, i in episodes:
        out += [i] * (n_on + n_apex + n_off) + [0.0] * n_rest
    return out


def _sample(quick: bool, flow: bool = False) -> dict:
    """The sample video's detail (cached): its rest and smile frames' labels, by the default
    analysis; ``flow``: by the fit on MediaPipe's points with the model-anchored tracker
    (``myoface analyze --no-photometric --flow``)."""
    key = ("sample", bool(quick), bool(flow))
    if key in _cache:
        return _cache[key]
    import tempfile
    import time
    from pathlib import Path

    from myoface.analysis.contractions_csv import read_contractions_csv
    from myoface.analysis.expressions import read_expressions
    from myoface.facemesh import mediapipe_available

    if not mediapipe_available():
        return {"skipped": "MediaPipe is not installed"}
    try:
        from myoface.analysis.sample import fetch_sample_video

        path = fetch_sample_video(quiet=True)
    except Exception as exc:  # no network and no cached copy
        return {"skipped": f"the sample video is not available: {exc}"}
    from myoface.analysis.outputs import analyze_to_folder

    t0 = time.perf_counter()
    n = SAMPLE_QUICK_FRAMES if quick else None
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "sample"
        res = analyze_to_folder(
            path, out, tracker="landmarks", max_frames=n, flow=flow,
            photometric=False if flow else None,
        )  # fmt: skip
        csv = out / "contractions.csv"
        _, _, quality = read_contractions_csv(csv, list(res.ids))
        _, labels = read_expressions(csv)
    index = [int(i) for i in res.frames.index]
    by_frame = dict(zip(index, labels, strict=True))
    rest = [by_frame.get(k, "") for k in SAMPLE_REST if k in by_frame]
    smile = [by_frame.get(k, "") for k in SAMPLE_SMILE if k in by_frame]
    out = {
        "video": Path(path).name,
        "frames_analysed": len(index),
        "frames_measured": int(sum(q == "ok" for q in quality)),
        "rest_frames": f"{SAMPLE_REST.start}-{SAMPLE_REST.stop - 1}",
        "smile_frames": f"{SAMPLE_SMILE.start}-{min(SAMPLE_SMILE.stop, len(index)) - 1}",
        "rest_neutral": float(np.mean([lab == "neutral" for lab in rest])),
        "smile_happiness": float(np.mean([lab == "happiness" for lab in smile])),
        "rest_labels": dict(Counter(rest).most_common()),
        "smile_labels": dict(Counter(smile).most_common()),
        "onset_labels (16-21)": "".join((by_frame.get(k) or "-")[0] for k in range(16, 22)),
        "offset_labels (69-71)": "".join(
            (by_frame.get(k) or "-")[0] for k in range(69, 72) if k in by_frame
        ),
        "labels": "".join((lab or "-")[0] for lab in labels),
        "seconds": round(time.perf_counter() - t0, 1),
    }
    _cache[key] = out
    return out


@benchmark("analysis.expression_accuracy", "-", higher_is_better=True)
def bench_expression_accuracy(quick: bool) -> Measurement:
    """The expression labelled from the fitted contractions (:mod:`myoface.analysis.expressions`:
    EMFACS prototypes over the AU table) on synthetic videos of the six expressions at
    intensities 0.5 and 1.0 on a person's face with its head moving, rendered, degraded as a
    webcam would and analysed end to end (:mod:`myoface.bench.expression`): the lower of the
    share of apex frames labelled with the expression played and the share of rest frames
    labelled neutral. The detail has both, per expression and intensity, the confusion, the
    rule on the true contractions, what the fit makes of each AU (its gain and its reading
    where the AU is absent; per class of frame; whether it keeps each expression's pattern),
    the same with the head still, the better trackers and the fit's AU-space prior on the
    same clip (:data:`VARIANTS`; these not in a quick run), and the sample video's
    (``single_face.mp4``) share of rest frames labelled neutral and of smile frames labelled
    happiness (also with ``--flow`` in a full run). The value is over the frames of
    :data:`CLIPS` pooled (``clips`` in the detail, with each clip's numbers; each held-out
    clip's detail as ``synthetic, clip NAME``); the variants are on the first. Full run: 10-13 minutes on the 2-core
    machine at a load of 10-15 (2026-12-02, with the variants; 4 minutes without them);
    quick (33 frames of three expressions at 0.75, the head moving; the sample's first 40
    frames): 34 s before the variants."""
    syn = _synthetic(quick)
    detail = {"synthetic": syn}
    # the held-out clips (a full run): the headline pools every clip's apex and rest frames
    runs = {"bench": syn}
    if not quick:
        for name in CLIPS:
            if name != "bench":
                runs[name] = detail[f"synthetic, clip {name}"] = _synthetic(quick, clip=name)
    pooled = pool_scores(runs)
    detail["clips"] = pooled
    # the better trackers and the fit's AU-space prior on the same clip (the head moving; not
    # in a quick run, a smoke run of the default's pipeline that is part of the test suite)
    for name, tracker, prior in VARIANTS if not quick else ():
        detail[f"synthetic, {name}"] = _synthetic(quick, tracker=tracker, au_prior=prior)
    if not quick:  # the same with the head still (what the head's motion costs), and on
        # the clean renders (what the camera costs)
        detail["synthetic, head still"] = _synthetic(quick, still=True)
        detail["synthetic, head still, clean renders"] = _synthetic(quick, True, clean=True)
        # the better tracker, head moving, on the clean renders (what the camera costs it)
        detail["synthetic, flow, clean renders"] = _synthetic(quick, clean=True, tracker="flow")
        detail["synthetic, flow, AU prior, clean renders"] = _synthetic(
            quick, clean=True, tracker="flow", au_prior=True
        )
        # ... and the fit given perfect landmarks (what MediaPipe's points cost)
        detail["synthetic, exact landmarks"] = _synthetic(quick, exact=True)
        detail["synthetic, head still, exact landmarks"] = _synthetic(quick, True, exact=True)
    detail["single_face.mp4"] = _sample(quick)
    if not quick:  # the better tracker on the real smile too
        detail["single_face.mp4, flow"] = _sample(quick, flow=True)
    # every run's two numbers at a glance (the detail of each above)
    detail["apex / rest, every run"] = {
        k: "{apex_accuracy:.3f} / {rest_accuracy:.3f}".format(**v)
        for k, v in detail.items()
        if k.startswith("synthetic")
    }
    value = min(pooled["apex_accuracy"], pooled["rest_accuracy"])
    return Measurement(value, pooled["apex_frames"] + pooled["rest_frames"], detail=detail)


def pool_scores(runs: dict) -> dict:
    """The headline over several clips' runs ({name: :func:`_synthetic`'s detail}): the
    share of all their apex frames labelled with the expression played and of all their rest
    frames labelled neutral (pooled: each frame counts once, whichever clip it is in), with
    each clip's own two numbers beside."""
    apex = sum(r["apex_frames"] for r in runs.values())
    rest = sum(r["rest_frames"] for r in runs.values())
    return {
        "what": "every clip's apex and rest frames pooled (the benchmark's value: the lower)",
        "apex_accuracy": sum(r["apex_accuracy"] * r["apex_frames"] for r in runs.values())
        / max(apex, 1),
        "rest_accuracy": sum(r["rest_accuracy"] * r["rest_frames"] for r in runs.values())
        / max(rest, 1),
        "apex_frames": apex,
        "rest_frames": rest,
        "per_clip (apex / rest)": {
            k: "{apex_accuracy:.3f} / {rest_accuracy:.3f}".format(**r) for k, r in runs.items()
        },
    }
