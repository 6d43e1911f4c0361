"""The expression level, read backward: how strongly each of the six basic expressions (and
neutral) is present in a frame, from its fitted contractions.

The paper's hierarchy runs expression -> FACS action units -> muscles -> physics -> images;
its discussion proposes running it backward "all the way up to the expression level". This
module is that last step: an explainable rule over action units, not a classifier trained on
appearance. Per frame:

1. **AU intensities.** The fitted contractions are read as FACS action units through the
   project's AU table (``data/facs_action_units.toml``), exactly as the OpenFace CSV's
   ``AUxx_r`` columns are (:func:`myoface.analysis.openface.au_intensities`), divided by 5:
   ``x_a`` in [0, 1], FACS's letters A-E at 0.2-1.0. In a video (:class:`ExpressionReader`,
   what contractions.csv is written with) each AU is read above the person's **rest
   reference**: what the fit reads of it on this video's frames labelled neutral, as a linear
   function of the head's pose (yaw, pitch, roll, and |yaw|: how far it is turned either
   way), ``x_a - b_a(pose)`` (0 below it). With
   the head moving, the fit reads AUs that are not there, in step with the pose (AU17 up to
   1.0 with the head turned 30 deg; docs/expressions.md); the reference takes them off. A
   single frame (:func:`expression_scores`) has no reference.
2. **Prototypes.** Each expression is a list of AU combinations, the EMFACS prototypes and
   major variants of P. Ekman, W. V. Friesen & J. C. Hager, *Facial Action Coding System:
   Investigator's Guide* (2002), table 10-1 ("EMFACS predictions"; EMFACS-7 is W. V. Friesen
   & P. Ekman, 1983), restricted to the AUs the analysis reads (:data:`PROTOTYPES`; what
   was left out and why, :data:`LEFT_OUT`).
3. **A prototype's match** reads the AUs as a *pattern*: each frame's intensities over its
   strongest AU (``r_a = x_a / max x``). It is the mean of its AUs' ``r_a`` times a gate per
   AU that opens from half a trace (0.1) to a trace (FACS's A, 0.2; for ``12>=C`` from
   C - 0.1 to C) of that scale: a coder scores a prototype only when every one of its AUs is
   there. The fit reads AUs at a fraction of their strength (a gain of 0.1-0.6 from
   MediaPipe's points, docs/expressions.md), so an absolute trace would miss whole
   expressions; the pattern is the same at any gain. An AU7 that is not measured is read as
   AU6 (:data:`READ_AS`).
4. **An expression's strength** (``expr_<name>``, in [0, 1]) is its best prototype's match
   times its *coverage*, ``E / (E + U)``, times a level gate on the frame's strongest AU
   that opens, like each AU's, from half a trace to a trace (:data:`LEVEL_MIN`: FACS scores
   nothing below A; the fit reads an A at a fraction of it): ``E`` the frame's AU activity
   (sum of ``x_a**2``) in the AUs of that expression's prototypes and variants
   (:data:`EXPRESSION_AUS`) or in the AUs that go with any expression
   (:data:`ANY_EXPRESSION_AUS`: lips part, jaw drop, blink), ``U`` the activity it leaves
   unexplained, each AU weighted by how specific a sign it is (:func:`specificity`: 1 / the
   number of expressions that use it). A face that shows the AUs of surprise and, besides,
   the lip stretcher of fear is mostly explained by fear; an AU that several other
   expressions share (AU10: disgust, anger) speaks against an expression less than one that
   only another has (AU12: happiness).
5. **Neutral** (``expr_neutral``) is ``1 - `` the strongest expression's strength, and the
   **label** (``expression``) is the strongest expression when its strength reaches a trace
   (:data:`LABEL_MIN`, 0.2), else ``neutral``; empty on a frame that was not measured.

Limits (see docs/expressions.md): sadness and fear share AU1 and AU4 (told apart by AU15
against AU2, AU5 and AU20); surprise's AUs are a subset of fear's (told apart by coverage);
AU7 is not read (its muscles are AU6's and AU45's, :data:`~myoface.analysis.openface.UNMEASURED_AUS`),
so anger's prototypes are its table variants without AU7 and, with AU7 read as AU6 (the
orbital sphincter, its larger muscle: :data:`READ_AS`), those without AU5; AU11, AU16, AU22,
AU24 and AU27 are not among the AUs read (AU16's depressor is read as AU25, AU27's jaw as
AU26); the model's muscles cannot make AU22 (lip funneler) at all. A prototype with an AU that
is not measured is not scored, and an expression with none left is NaN: the snakes (the paper's
12 muscles and the jaw) measure AU1, 2, 9, 12, 25 and 26 only, so sadness, fear and anger are
NaN with them.

References: P. Ekman, W. V. Friesen & J. C. Hager, Facial Action Coding System: The Manual
and Investigator's Guide (Research Nexus, 2002), Investigator's Guide table 10-1; W. V.
Friesen & P. Ekman, EMFACS-7: Emotional Facial Action Coding System (unpublished manuscript,
University of California, San Francisco, 1983); Terzopoulos & Waters 1993, Section II (the
hierarchy).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

#: the six basic expressions, in the columns' order
EXPRESSIONS = ("happiness", "sadness", "surprise", "fear", "anger", "disgust")
#: the label of a frame that shows none of them
NEUTRAL = "neutral"
#: contractions.csv's (and openface.csv's) expression columns, in order
EXPRESSION_COLUMNS = (*(f"expr_{e}" for e in EXPRESSIONS), f"expr_{NEUTRAL}")
#: the column of the per-frame label
LABEL_COLUMN = "expression"

#: FACS intensity letters as AU intensities in [0, 1] (as :data:`myoface.control.facs.LETTERS`)
_LETTERS = {"A": 0.2, "B": 0.4, "C": 0.6, "D": 0.8, "E": 1.0}
#: an AU is present from a trace (FACS's A: 0.2 in [0, 1], 1 on OpenFace's 0-5 scale); its
#: gate opens over the half-trace below (Ekman, Friesen & Hager 2002, ch. 1: A, "trace")
TRACE = _LETTERS["A"]
#: the label is an expression when its strength reaches a trace, else neutral
LABEL_MIN = TRACE
#: a frame shows an expression only when its strongest AU reaches a trace: FACS scores no AU
#: below A (Ekman, Friesen & Hager 2002, ch. 1), and the prototypes compare the AUs with the
#: strongest (so a pattern read at any gain matches), which says nothing of whether the face
#: moved at all. (Replayed 2026-12-06 on the six clips' recorded readings, pooled apex / rest:
#: 0.696 / 0.885 as it is; the level gate at 0.15, 0.694 / 0.713; at 0.25, 0.689 / 0.950;
#: :data:`LABEL_MIN` 0.15 or 0.25, 0.705 / 0.861 and 0.693 / 0.892. The apex frames missed are
#: not below a level but without the AUs their prototypes need (docs/expressions.md, "Which
#: stage holds AU4 and AU5"), and a gate above FACS's trace would be one set on these clips'
#: rest frames: not taken.)
LEVEL_MIN = TRACE

#: The EMFACS prototypes and major variants (Ekman, Friesen & Hager 2002, FACS
#: Investigator's Guide, table 10-1) over the AUs the analysis reads. ``a+b+c``: every AU
#: present; ``12>=C``: AU12 at C or more. The table's intensity marks that describe the
#: prototype (5B, 15B: slight; ``*``: any intensity) are not minimums and are dropped; its
#: "25, 26 or 27" and "with or without 54+64" options are in :data:`ANY_EXPRESSION_AUS` or
#: not read (head and eye positions); AU27 (mouth stretch) is read as AU26.
PROTOTYPES = {
    # 6+12*; 12C/D
    "happiness": ("6+12", "12>=C"),
    # 1+4+15*, 1+4+15B (+17); 6+15*  (1+4+11, 11+15B, 11+17: AU11 not read)
    "sadness": ("1+4+15", "1+4+15+17", "6+15"),
    # 1+2+5B+26/27; variants 1+2+5B, 1+2+26/27, 5B+26/27
    "surprise": ("1+2+5+26", "1+2+5", "1+2+26", "5+26"),
    # 1+2+4+5*+20*+25/26/27, 1+2+4+5*+25/26/27; variants 1+2+4+5*, 5*+20*
    # (1+2+5Z: an intensity mark we do not read; L/R20: the rule is bilateral); and the fear
    # brow 1+2+4 alone (raised and drawn together: Ekman & Friesen, Unmasking the Face, 1975,
    # ch. 5; the CK+ emotion criteria, Lucey et al. 2010, table 2, ask for 1+2+4)
    "fear": ("1+2+4+5+20", "1+2+4+5", "5+20", "1+2+4"),
    # 4+5*+7+23, 4+5*+7+10*+23, 4+5*+7+17+23 (+25/26), and the table's variants "without any
    # one of 4, 5, 7 or 10": without AU7, and without AU5 with AU7 read as AU6 (READ_AS)
    # (4+5*+7+17+24: AU24 not read)
    "anger": ("4+5+23", "4+5+10+23", "4+5+17+23", "4+7+23", "4+7+10+23", "4+7+17+23"),
    # 9; 9+16+15/26; 9+17; 10*; 10*+16+25/26; 10+17  (AU16 not read: its depressor is AU25)
    "disgust": ("9", "9+15", "9+17", "10", "10+17"),
}
#: AUs of the table's prototypes and variants that the analysis does not read, and why; the
#: prototypes above leave them out (they still count as the expression's own in its coverage)
LEFT_OUT = {
    7: "lid tightener: its muscles are AU6's and AU45's (openface.UNMEASURED_AUS); where a "
    "prototype has it, it is read as AU6 (READ_AS)",
    11: "nasolabial deepener: not among OpenFace's AUs, which the analysis reads",
    16: "lower lip depressor: its muscle is read as AU25 (lips part) with the jaw",
    22: "lip funneler: not in the AU table; the model's muscles cannot make it",
    24: "lip pressor: not among OpenFace's AUs",
    27: "mouth stretch: the jaw alone, read as AU26 (jaw drop)",
}
#: AUs of a prototype that the analysis does not measure, read from the AU that holds their
#: largest muscle: AU7 (lid tightener) is the orbital sphincter at 0.5 with the lid's
#: palpebral part at 0.3 in the AU table, and the sphincter is what AU6 (cheek raiser) is read
#: from, so a lid tightened shows as AU6 (with a little AU45). Used only where the AU itself
#: is not measured (NaN).
READ_AS = {7: 6}
#: the rest reference's pose terms are yaw, pitch and roll in units of this many degrees
#: (the head's turn at which the fit's spurious readings were measured: docs/expressions.md)
REST_POSE_SCALE_DEG = 30.0
#: the rest reference's prior on its pose terms (ridge; in frames seen at
#: :data:`REST_POSE_SCALE_DEG`): until about a frame's worth of neutral frames have been seen
#: turned that far, the reference is mostly the same at every pose (its level alone)
REST_RIDGE = 0.3
#: the rest reference's terms, in order: its level, the head's yaw, pitch and roll, and how
#: far the head is turned either way (|yaw|). The last because the fit's spurious readings
#: at rest grow with the turn to either side (the face's far side foreshortened): on the
#: expression benchmark's clip (BENCHMARKS.md of 2026-12-06 19:29 UTC, its detail's
#: ``rest_readings_vs_pose``) a linear function of the angles explained 1-63 % of the rest
#: readings' variance of AU2, AU6, AU10 and AU23, one with |yaw| added 63-95 % (AU6: 0.01 ->
#: 0.78); on its six clips (the fit's readings recorded once and read again) the rest frames
#: labelled neutral 0.825 -> 0.885, the apex frames their expression 0.689 -> 0.696.
#: Measured and not taken: |pitch| too (rest 0.864, apex 0.674), |roll| as well (0.869 /
#: 0.696), the angles' squares in place of |yaw| (0.881 / 0.708: about the same, three
#: terms where one does).
REST_TERMS = ("level", "yaw", "pitch", "roll", "|yaw|")
#: AUs that go with any expression: the lips parting and the jaw dropping ("25 or 26 may
#: occur with all prototypes or major variants", table 10-1), and a blink
ANY_EXPRESSION_AUS = (25, 26, 45)
#: every AU of each expression's table entries (prototypes and variants, read or not): what
#: counts as explained by the expression (its coverage). AU7 is read as AU6 and AU45, so
#: fear and anger (AU7 in their prototypes) own AU6 too.
EXPRESSION_AUS = {
    "happiness": (6, 12),
    "sadness": (1, 4, 6, 11, 15, 17),
    "surprise": (1, 2, 5, 27),
    "fear": (1, 2, 4, 5, 6, 7, 20, 27),
    "anger": (4, 5, 6, 7, 10, 17, 22, 23, 24),
    "disgust": (9, 10, 15, 16, 17),
}


@dataclass(frozen=True)
class Prototype:
    """One AU combination of an expression: its AUs and the least intensity (in [0, 1]) at
    which each counts as present (:data:`TRACE` unless the table says more)."""

    expression: str
    aus: tuple
    least: tuple

    @property
    def text(self) -> str:
        return "+".join(
            f"{a}" if t == TRACE else f"{a}>={_letter(t)}"
            for a, t in zip(self.aus, self.least, strict=True)
        )


def _letter(v: float) -> str:
    return next(k for k, x in _LETTERS.items() if x == v)


def _parse(expression: str, text: str) -> Prototype:
    aus, least = [], []
    for term in text.split("+"):
        num, _, letter = term.partition(">=")
        aus.append(int(num))
        least.append(_LETTERS[letter] if letter else TRACE)
    return Prototype(expression, tuple(aus), tuple(least))


@lru_cache(maxsize=1)
def prototypes() -> dict[str, tuple[Prototype, ...]]:
    """:data:`PROTOTYPES` parsed: ``{expression: (Prototype, ...)}``."""
    return {e: tuple(_parse(e, t) for t in PROTOTYPES[e]) for e in EXPRESSIONS}


def rule_aus() -> tuple[int, ...]:
    """The AUs the rule reads: OpenFace's (:data:`~myoface.analysis.openface.OPENFACE_AUS`),
    the ones the OpenFace CSV reports."""
    from myoface.analysis.au_intensity import OPENFACE_AUS

    return OPENFACE_AUS


def specificity(aus) -> np.ndarray:
    """How specific a sign of an expression each AU of ``aus`` is: 1 / the number of
    expressions whose table entries use it (:data:`EXPRESSION_AUS`; AU12 is happiness's
    alone: 1; AU10 disgust's and anger's: 1/2); 1 for an AU that none uses (e.g. AU14)."""
    n = [sum(a in EXPRESSION_AUS[e] for e in EXPRESSIONS) for a in aus]
    return np.array([1.0 / k if k else 1.0 for k in n])


@lru_cache(maxsize=8)
def _plan(aus: tuple):
    """Per expression: the columns of its own AUs (and those of any expression), the others'
    with their :func:`specificity`, and its prototypes that ``aus`` can score, as
    ``(columns, least)`` arrays."""
    col = {a: j for j, a in enumerate(aus)}
    sign = specificity(aus)
    plan = []
    for e in EXPRESSIONS:
        mine = {*EXPRESSION_AUS[e], *ANY_EXPRESSION_AUS}
        own = np.array([j for j, a in enumerate(aus) if a in mine], dtype=int)
        other = np.array([j for j, a in enumerate(aus) if a not in mine], dtype=int)
        protos = [
            (np.array([col.get(a, col.get(READ_AS.get(a))) for a in p.aus]), np.array(p.least))
            for p in prototypes()[e]
            if all(a in col or READ_AS.get(a) in col for a in p.aus)
        ]
        plan.append((own, other, sign[other], protos))
    return plan


def _read_as(x: np.ndarray, aus: tuple) -> np.ndarray:
    """``x`` (T, len(aus)) with each AU of :data:`READ_AS` that is not measured (NaN) read
    from the AU that holds its largest muscle (AU7 from AU6)."""
    col = {a: j for j, a in enumerate(aus)}
    out = x
    for a, b in READ_AS.items():
        if a in col and b in col:
            out = out.copy() if out is x else out
            out[:, col[a]] = np.where(np.isnan(x[:, col[a]]), x[:, col[b]], x[:, col[a]])
    return out


def expression_scores_from_aus(intensities, aus=None) -> np.ndarray:
    """The rule on AU intensities: ``(T, 7)`` strengths in [0, 1] in :data:`EXPRESSION_COLUMNS`'
    order (the six expressions, then neutral) from ``intensities`` (T, len(aus)) in [0, 1]
    (FACS's A-E at 0.2-1.0; OpenFace's ``AUxx_r`` / 5) over the AU numbers ``aus`` (default
    :func:`rule_aus`); NaN for an AU that was not measured. One frame: (len(aus),) -> (7,).

    An expression's strength is its best prototype's match (the mean of its AUs' intensities
    relative to the frame's strongest AU, times each AU's presence gate on that relative
    intensity) times its coverage (``E / (E + U)``: the activity, sum of ``x**2``, in its
    own AUs and :data:`ANY_EXPRESSION_AUS`, against the activity it leaves unexplained
    weighted by :func:`specificity`), times a gate on the frame's strongest AU that opens from
    half a trace to :data:`LEVEL_MIN` (a trace); a prototype with an unmeasured AU is not
    scored, an expression with no prototype scored is NaN. Neutral is 1 minus the strongest
    (NaN when none was scored). A row with no AU measured is NaN throughout.
    """
    aus = tuple(rule_aus() if aus is None else aus)
    x = np.asarray(intensities, dtype=np.float64)
    one = x.ndim == 1
    x = np.atleast_2d(x)
    if x.shape[1] != len(aus):
        raise ValueError(f"intensities must be (T, {len(aus)}) over aus; got shape {x.shape}")
    x = np.clip(x, 0.0, 1.0)  # (NaN stays NaN)
    sq = np.where(np.isfinite(x), x**2, 0.0)
    # the frame's scale: its strongest AU; the prototypes read each AU relative to it (an
    # unmeasured AU7 read as AU6), and nothing is an expression until it reaches a trace
    top = np.max(np.where(np.isfinite(x), x, 0.0), axis=1)
    rel = np.minimum(_read_as(x, aus) / np.where(top > 0, top, 1.0)[:, None], 1.0)
    # the level gate opens like each AU's: from half a trace to a trace
    present = np.clip((top - (LEVEL_MIN - TRACE / 2)) / (TRACE / 2), 0.0, 1.0)
    out = np.full((len(x), len(EXPRESSION_COLUMNS)), np.nan)
    for i, (own, other, sign, protos) in enumerate(_plan(aus)):
        explained = sq[:, own].sum(axis=1)
        total = explained + sq[:, other] @ sign
        coverage = np.where(total > 0, explained / np.where(total > 0, total, 1.0), 1.0)
        best = np.full(len(x), np.nan)
        for cols, least in protos:
            v = rel[:, cols]  # (NaN where an AU is unmeasured: the match is NaN)
            gates = np.clip((v - (least - TRACE / 2)) / (TRACE / 2), 0.0, 1.0).prod(axis=1)
            best = np.fmax(best, gates * v.mean(axis=1))
        out[:, i] = best * coverage * present
    six = out[:, :-1]
    scored = np.isfinite(six).any(axis=1)
    strongest = np.where(scored, np.nanmax(np.where(np.isnan(six), -np.inf, six), axis=1), np.nan)
    out[:, -1] = 1.0 - strongest
    out[~np.isfinite(x).any(axis=1)] = np.nan
    return out[0] if one else out


def expression_labels(scores) -> list[str]:
    """The label of each row of ``scores`` (T, 7) (:func:`expression_scores_from_aus`): the
    strongest expression when its strength is at least :data:`LABEL_MIN`, else ``neutral``
    (of two equally strong, the first in :data:`EXPRESSIONS`' order); ``""`` for a row
    without any score (a frame not measured)."""
    s = np.atleast_2d(np.asarray(scores, dtype=np.float64))[:, : len(EXPRESSIONS)]
    out = []
    for row in s:
        if not np.isfinite(row).any():
            out.append("")
            continue
        k = int(np.nanargmax(row))
        out.append(EXPRESSIONS[k] if row[k] >= LABEL_MIN else NEUTRAL)
    return out


@lru_cache(maxsize=8)
def _basis(ids: tuple):
    from myoface.analysis.au_intensity import au_basis

    return au_basis(list(ids), rule_aus())


def au_fractions(contractions, muscle_ids) -> np.ndarray:
    """AU intensities (T, len(:func:`rule_aus`)) in [0, 1] of contractions (T, M) over
    ``muscle_ids``: :func:`~myoface.analysis.openface.au_intensities` / 5 (NaN for an AU not
    measured, and for a frame whose contractions are not all finite)."""
    from myoface.analysis.au_intensity import OPENFACE_SCALE, au_intensities

    ids = tuple(muscle_ids)
    x = au_intensities(contractions, list(ids), rule_aus(), basis=_basis(ids))
    return x / OPENFACE_SCALE


def expression_scores(contractions, muscle_ids) -> np.ndarray:
    """The expressions' strengths (T, 7) in :data:`EXPRESSION_COLUMNS`' order of contractions
    (T, M) over ``muscle_ids`` (one frame: (M,) -> (7,)): the AU table, then the EMFACS rule
    (:func:`expression_scores_from_aus`; see the module's docstring). NaN rows for frames
    whose contractions are not all finite.

    >>> from myoface.control import expression_contractions  # doctest: +SKIP
    >>> s = expression_scores(expression_contractions("happiness", 1.0, ids), ids)
    >>> expression_labels(s)
    ['happiness']
    """
    c = np.asarray(contractions, dtype=np.float64)
    one = c.ndim == 1
    x = au_fractions(np.atleast_2d(c), muscle_ids)
    s = expression_scores_from_aus(x)
    return s[0] if one else s


class ExpressionReader:
    """The expressions of one video's frames in order, each read above the person's **rest
    reference** (causal: a frame's scores depend on it and the frames before it, so the
    contractions CSV can be written row by row, with no delay).

    The fit reads AUs where there are none, and with the head moving it reads them in step
    with the pose (docs/expressions.md: at rest, AU17 correlates 0.74 with the turn of the
    head, AU10 and AU12 -0.87 and -0.82 with its pitch, and a linear function of the angles
    explains 73-79 % of the variance of those two; others grow with the turn to either
    side, :data:`REST_TERMS`). The reference of AU ``a`` is
    ``b_a(pose) = w_a . (1, yaw / 30, pitch / 30, roll / 30, |yaw| / 30)`` (degrees), least
    squares over the frames read
    so far whose label is neutral
    (:data:`REST_RIDGE` holding the pose terms near 0 until neutral frames at other poses
    show them), kept within 0 and the largest reading of the AU on those frames (no
    extrapolation above what was seen at rest). Each frame's AUs are read as ``x_a -
    b_a(pose)`` (0 below), then the rule (:func:`expression_scores_from_aus`). Before the
    first neutral frame the reference is 0 (the rule on the readings as they are). Without a
    pose (the snakes, or a frame whose pose is not finite) the pose terms are 0: the
    reference is the AU's level at rest. It never forgets: every neutral frame of the video so
    far counts alike.

    >>> r = ExpressionReader(ids)  # doctest: +SKIP
    >>> for c, pose in frames:
    ...     scores, label = r.read(c, pose.angles_deg)

    Attributes
    ----------
    n_neutral : int -- the neutral frames the reference was fitted on so far.
    """

    def __init__(self, muscle_ids, aus=None):
        self.ids = tuple(muscle_ids)
        self.aus = tuple(rule_aus() if aus is None else aus)
        self._gram = np.diag([1e-9] + [REST_RIDGE] * (len(REST_TERMS) - 1))
        self._rhs = np.zeros((len(REST_TERMS), len(self.aus)))
        self._high = np.zeros(len(self.aus))
        self.n_neutral = 0

    @staticmethod
    def _features(angles_deg) -> np.ndarray:
        a = np.zeros(3) if angles_deg is None else np.asarray(angles_deg, dtype=np.float64)
        if a.shape != (3,) or not np.isfinite(a).all():
            a = np.zeros(3)
        a = a / REST_POSE_SCALE_DEG
        return np.array([1.0, a[0], a[1], a[2], abs(a[0])])

    def reference(self, angles_deg=None) -> np.ndarray:
        """The rest reference (len(aus),) in [0, 1] at the pose ``angles_deg`` (yaw, pitch,
        roll deg; None: the level at rest)."""
        if not self.n_neutral:
            return np.zeros(len(self.aus))
        w = np.linalg.solve(self._gram, self._rhs)
        return np.clip(self._features(angles_deg) @ w, 0.0, self._high)

    def read_aus(self, intensities, angles_deg=None) -> tuple[np.ndarray, str]:
        """One frame's scores (7,) and label from its AU intensities (len(aus),) in [0, 1]
        and the head's ``angles_deg``; the frame joins the reference when labelled neutral.
        A frame with no AU measured: NaN scores, label ``""``, nothing learnt."""
        x = np.asarray(intensities, dtype=np.float64)
        if not np.isfinite(x).any():
            return np.full(len(EXPRESSION_COLUMNS), np.nan), ""
        above = np.where(np.isfinite(x), np.clip(x - self.reference(angles_deg), 0.0, 1.0), x)
        s = expression_scores_from_aus(above, self.aus)
        label = expression_labels(s)[0]
        if label == NEUTRAL:
            f = self._features(angles_deg)
            seen = np.nan_to_num(np.clip(x, 0.0, 1.0))
            self._gram = self._gram + np.outer(f, f)
            self._rhs = self._rhs + np.outer(f, seen)
            self._high = np.maximum(self._high, seen)
            self.n_neutral += 1
        return s, label

    def read(self, contractions, angles_deg=None) -> tuple[np.ndarray, str]:
        """One frame's scores (7,) in :data:`EXPRESSION_COLUMNS`' order and label from its
        contractions (M,) over the reader's muscle ids (NaN / ``""`` when they are not all
        finite: a frame not measured, which the reference does not learn from)."""
        c = np.asarray(contractions, dtype=np.float64)
        if c.shape != (len(self.ids),) or not np.isfinite(c).all():
            return np.full(len(EXPRESSION_COLUMNS), np.nan), ""
        return self.read_aus(au_fractions(c[None], self.ids)[0], angles_deg)

    def cells(self, contractions, angles_deg=None) -> list[str]:
        """One frame's expression cells for contractions.csv (:data:`EXPRESSION_COLUMNS`
        with 3 decimals, then the label); all empty when the contractions are not all
        finite."""
        s, label = self.read(contractions, angles_deg)
        if not label:
            return [""] * (len(EXPRESSION_COLUMNS) + 1)
        return [*("" if not np.isfinite(v) else f"{v:.3f}" for v in s), label]


def expression_sequence(contractions, muscle_ids, angles_deg=None) -> tuple[np.ndarray, list]:
    """A video's expressions as contractions.csv has them: ``(scores (T, 7), labels (T,))``
    of contractions (T, M) over ``muscle_ids`` read in order by one :class:`ExpressionReader`
    (the rest reference), with the head's ``angles_deg`` (T, 3) (yaw, pitch, roll) or None."""
    c = np.atleast_2d(np.asarray(contractions, dtype=np.float64))
    ang = None if angles_deg is None else np.asarray(angles_deg, dtype=np.float64)
    reader = ExpressionReader(muscle_ids)
    x = au_fractions(c, muscle_ids)
    scores = np.full((len(c), len(EXPRESSION_COLUMNS)), np.nan)
    labels = []
    for k in range(len(c)):
        if not np.isfinite(c[k]).all():
            labels.append("")
            continue
        scores[k], lab = reader.read_aus(x[k], None if ang is None else ang[k])
        labels.append(lab)
    return scores, labels


def expression_cells(
    contractions, muscle_ids, reader: ExpressionReader | None = None, angles_deg=None
) -> list[str]:
    """One frame's expression cells for contractions.csv (:data:`EXPRESSION_COLUMNS` with 3
    decimals, then the label); all empty when the contractions are not all finite. With a
    ``reader`` (:class:`ExpressionReader`, one per video) read above its rest reference at
    the head's ``angles_deg``; without, the frame alone, with no rest reference."""
    if reader is not None:
        return reader.cells(contractions, angles_deg)
    c = np.asarray(contractions, dtype=np.float64)
    if not np.isfinite(c).all():
        return [""] * (len(EXPRESSION_COLUMNS) + 1)
    s = expression_scores(c, tuple(muscle_ids))
    return [*("" if not np.isfinite(v) else f"{v:.3f}" for v in s), expression_labels(s)[0]]


def read_expressions(path, table=None, muscle_ids=None) -> tuple[np.ndarray, list[str]]:
    """The expressions of a contractions CSV: ``(scores (T, 7), labels (T,))`` from its
    :data:`EXPRESSION_COLUMNS` and :data:`LABEL_COLUMN`; a CSV without them (written before
    they were) has them computed from its contractions ``table`` (T, M) over ``muscle_ids``
    (from :func:`~myoface.analysis.contractions_csv.read_contractions_csv`), or raises a
    :class:`~myoface.errors.MyofaceFormatError` when those are not given."""
    import csv
    from pathlib import Path

    from myoface._io import read_text
    from myoface.errors import MyofaceFormatError

    p = Path(path)
    lines = read_text(p, "contractions CSV").splitlines()
    reader = csv.reader(lines)
    head = [c.strip() for c in next(reader, [])]
    wanted = (*EXPRESSION_COLUMNS, LABEL_COLUMN)
    if all(c in head for c in wanted):
        cols = [head.index(c) for c in wanted]
        values, labels = [], []  # (only the expression cells of each row are kept)
        for k, r in enumerate(reader, start=2):
            if not any(c.strip() for c in r):
                continue
            cells = [r[i].strip() if i < len(r) else "" for i in cols]
            row = []
            for c, cell in zip(EXPRESSION_COLUMNS, cells, strict=False):
                try:
                    row.append(float(cell) if cell else np.nan)
                except ValueError:
                    raise MyofaceFormatError(
                        f"{p}: row {k}: {c} is not a number: {cell[:40]!r}"
                    ) from None
            lab = cells[-1]
            if lab not in ("", NEUTRAL, *EXPRESSIONS):
                raise MyofaceFormatError(
                    f"{p}: row {k}: {LABEL_COLUMN} must be one of "
                    f"{', '.join((*EXPRESSIONS, NEUTRAL))} or empty; got {lab[:40]!r}"
                )
            values.append(row)
            labels.append(lab)
        scores = np.array(values, dtype=np.float64).reshape(-1, len(EXPRESSION_COLUMNS))
        return scores, labels
    if table is None or muscle_ids is None:
        raise MyofaceFormatError(f"{p}: no expression columns ({', '.join(EXPRESSION_COLUMNS)})")
    return expression_sequence(table, muscle_ids, _angles(head, reader))


#: the head's angles in a contractions CSV written by the 3-D fit (camera.POSE_COLUMNS' first)
_ANGLE_COLUMNS = ("head_yaw_deg", "head_pitch_deg", "head_roll_deg")


def _angles(head, rows) -> np.ndarray | None:
    """The head's angles (T, 3) deg of a contractions CSV's remaining ``rows`` (NaN where a
    cell is empty or not a number), or None when it has no angle columns (the snakes')."""
    if not all(c in head for c in _ANGLE_COLUMNS):
        return None
    cols = [head.index(c) for c in _ANGLE_COLUMNS]
    out = []
    for r in rows:
        if not any(c.strip() for c in r):
            continue
        vals = []
        for i in cols:
            try:
                vals.append(float(r[i]) if i < len(r) and r[i].strip() else np.nan)
            except ValueError:
                vals.append(np.nan)
        out.append(vals)
    return np.array(out, dtype=np.float64).reshape(-1, 3)


#: the plot's colour per expression (and grey for neutral)
COLORS = {
    "happiness": "#e6a100",
    "sadness": "#3a6fd8",
    "surprise": "#19a7a0",
    "fear": "#8a4fc7",
    "anger": "#d62728",
    "disgust": "#5b8c2a",
    NEUTRAL: "0.55",
}


def plot_expressions(path, times, scores, labels, quality) -> None:
    """``expressions.png``: the six expressions' strengths and neutral (``scores`` (T, 7))
    over ``times`` (T,) s, and below them the label of each frame as a coloured band; frames
    whose ``quality`` is not "ok" (or without a label) hatched. Written atomically."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    from myoface._io import atomic_output

    t = np.asarray(times, dtype=np.float64)
    s = np.asarray(scores, dtype=np.float64).reshape(len(t), len(EXPRESSION_COLUMNS))
    fig, (ax, band) = plt.subplots(
        2, 1, figsize=(8, 3.6), sharex=True, gridspec_kw={"height_ratios": [5, 1]}
    )
    names = (*EXPRESSIONS, NEUTRAL)
    for j, e in enumerate(names):
        label = e if np.isfinite(s[:, j]).any() else f"{e} (not read)"
        ax.plot(t, s[:, j], color=COLORS[e], lw=1.4 if e != NEUTRAL else 1.0,
                ls="-" if e != NEUTRAL else "--", label=label)  # fmt: skip
    ax.axhline(LABEL_MIN, color="0.3", lw=0.6, ls=":", zorder=0)
    ax.set_ylim(-0.02, 1.02)
    ax.set_ylabel("strength", fontsize=8)
    ax.tick_params(labelsize=7)
    dt = float(np.median(np.diff(t))) if len(t) > 1 else 1.0 / 30
    lost = False
    for k, (lab, q) in enumerate(zip(labels, quality, strict=True)):
        span = (t[k] - dt / 2, t[k] + dt / 2)
        if q != "ok" or not lab:
            lost = True
            for a in (ax, band):
                a.axvspan(*span, facecolor="white", edgecolor="#c44", hatch="////", lw=0)
            continue
        band.axvspan(*span, color=COLORS[lab], lw=0)
    handles, _ = ax.get_legend_handles_labels()
    if lost:
        handles.append(
            Patch(facecolor="white", edgecolor="#c44", hatch="////", label="not measured")
        )
    ax.legend(handles=handles, loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7,
              frameon=False, title="expression", title_fontsize=7)  # fmt: skip
    band.set_yticks([])
    band.set_ylabel("label", rotation=0, ha="right", va="center", fontsize=8)
    band.set_xlabel("time (s)", fontsize=8)
    band.tick_params(labelsize=7)
    ax.set_title(
        "expressions read from the fitted contractions (EMFACS prototypes over the AU table,\n"
        "each AU above the person's rest reference); "
        f"label: the strongest expression from {LABEL_MIN:g} (dotted), else neutral",
        fontsize=8,
    )
    fig.tight_layout()
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)
