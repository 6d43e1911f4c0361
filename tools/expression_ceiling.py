"""What holds the expression benchmark: the rule and its variants on cached fits, and how far
any rule on those fits could go (docs/expressions.md, "What holds the number").

    python tools/expression_runs.py /tmp/runs          # once: the clips fitted (~1 min each)
    python tools/expression_ceiling.py /tmp/runs [--sample CSV]

For each cached run (tools/expression_runs.py) it prints apex / rest accuracy (%) of

- ``committed``: the rule as contractions.csv has it (ExpressionReader);
- the variants tried and not kept (below, :data:`VARIANTS`), each causal as the reader is;

and the ceilings of :func:`myoface.bench.expression.readings_ceiling` (an oracle rest
reference; presence, identity against the true patterns and against the fit's own readings
of the other episodes), with ``causal presence``: the same presence test with a reference that
learns, frame by frame, from the true rest frames before it only (what a causal reader could
do if it knew which frames are at rest). ``--sample``: a ``myoface analyze`` contractions.csv
of single_face.mp4 (rest 0-15, smile 22-68) is labelled by each variant too.
"""

from __future__ import annotations

import argparse
import csv
import glob
from pathlib import Path

import numpy as np


def _reader(x, c, ang, ids, *, floor_k=0.0, z_k=None, z_mode="and", level=None, label=None):
    """The committed reader (linear pose reference on neutral frames, the AU rule), with:
    ``floor_k``: each AU read above its reference plus floor_k times its spread at rest;
    ``z_k``: a presence test on the contractions (their largest residual over the same kind
    of reference, in units of its spread at rest) combined with the rule's label
    (``and``: the rule's label only where the test passes; ``replace``: the test decides
    presence, the rule's strongest expression the identity); ``level`` / ``label``: the
    rule's LEVEL_MIN / LABEL_MIN."""
    import myoface.analysis.expressions as X
    from myoface.analysis.expressions import NEUTRAL, expression_labels

    saved = X.LEVEL_MIN, X.LABEL_MIN
    X.LEVEL_MIN = saved[0] if level is None else level
    X.LABEL_MIN = saved[1] if label is None else label
    try:
        a_n, m_n = x.shape[1], c.shape[1]
        gram = np.diag([1e-9] + [X.REST_RIDGE] * 3)
        rx, rc = np.zeros((4, a_n)), np.zeros((4, m_n))
        sx, sc = np.zeros(a_n), np.zeros(m_n)
        high, n, out = np.zeros(a_n), 0, []
        for t in range(len(x)):
            if not np.isfinite(x[t]).any() or not np.isfinite(c[t]).all():
                out.append("")
                continue
            f = X.ExpressionReader._features(ang[t])
            seen = np.nan_to_num(np.clip(x[t], 0, 1))
            if n:
                inv = np.linalg.inv(gram)
                refx, refc = np.clip(f @ inv @ rx, 0, high), f @ inv @ rc
                sdx, sdc = np.sqrt(sx / n), np.sqrt(sc / n) + 0.01
            else:
                refx, refc, sdx, sdc = np.zeros(a_n), np.zeros(m_n), np.zeros(a_n), None
            above = np.where(np.isfinite(x[t]), np.clip(x[t] - refx - floor_k * sdx, 0, 1), x[t])
            s = X.expression_scores_from_aus(above[None])[0]
            lab = expression_labels(s[None])[0]
            if z_k is not None and n >= 8:
                moved = ((c[t] - refc) / sdc).max() >= z_k
                if z_mode == "and":
                    lab = lab if moved else NEUTRAL
                else:
                    X.LEVEL_MIN, old = 1e-6, X.LEVEL_MIN
                    s = X.expression_scores_from_aus(above[None])[0]
                    X.LEVEL_MIN = old
                    j = int(np.nanargmax(s[:6]))
                    lab = X.EXPRESSIONS[j] if moved and s[j] > 0 else NEUTRAL
            out.append(lab)
            if lab == NEUTRAL:
                sx += (seen - (f @ np.linalg.solve(gram, rx) if n else 0)) ** 2
                sc += (c[t] - (f @ np.linalg.solve(gram, rc) if n else 0)) ** 2
                gram += np.outer(f, f)
                rx += np.outer(f, seen)
                rc += np.outer(f, c[t])
                high = np.maximum(high, seen)
                n += 1
        return out
    finally:
        X.LEVEL_MIN, X.LABEL_MIN = saved


#: the variants tried (name: keyword arguments of :func:`_reader`)
VARIANTS = {
    "committed": {},
    "AU above reference + 1 spread at rest": {"floor_k": 1.0},
    "AU above reference + 2 spreads at rest": {"floor_k": 2.0},
    "and: contractions moved (z >= 3)": {"z_k": 3.0},
    "presence from contractions (z >= 3), identity from the rule": {"z_k": 3.0, "z_mode": "x"},
    "level gate from 0.05 to 0.1 (a gain of 0.5 on the fit)": {"level": 0.1},
    "label from 0.15": {"label": 0.15},
}


def causal_presence(estimate, phase, angles_deg) -> float:
    """:func:`~myoface.bench.expression.readings_ceiling`'s presence test (largest muscle
    residual in units of its spread at rest) with a reference that learns causally from the
    true rest frames before each frame (the fit's angles, the reader's linear pose terms):
    the best over thresholds of the lower of apex frames above and rest frames below."""
    from myoface.analysis.expressions import REST_RIDGE, ExpressionReader

    c = np.nan_to_num(np.asarray(estimate, dtype=np.float64))
    phase = np.asarray(phase)
    apex, rest = phase == "apex", phase == "rest"
    gram = np.diag([1e-9] + [REST_RIDGE] * 3)
    rhs, ss, n = np.zeros((4, c.shape[1])), np.zeros(c.shape[1]), 0
    z = np.zeros(len(c))
    for t in range(len(c)):
        f = ExpressionReader._features(angles_deg[t])
        res = c[t] - f @ np.linalg.solve(gram, rhs)
        # before 5 rest frames are seen the test is not scored: apex passes, rest passes
        z[t] = (
            (np.abs(res) / (np.sqrt(ss / n) + 1e-3)).max()
            if n >= 5
            else (np.inf if apex[t] else 0.0)
        )
        if rest[t]:
            ss += res**2
            gram += np.outer(f, f)
            rhs += np.outer(f, c[t])
            n += 1
    ths = np.unique(z[apex | rest])
    return max(min(float((z[apex] >= h).mean()), float((z[rest] < h).mean())) for h in ths)


def _sample(path):
    from myoface.analysis.expressions import au_fractions
    from myoface.muscles.io import load_default_muscles

    ids = list(load_default_muscles().ids)
    rows = list(csv.DictReader(open(path)))
    c = np.array([[float(r[i]) if r[i] else np.nan for i in ids] for r in rows])
    keys = ("head_yaw_deg", "head_pitch_deg", "head_roll_deg")
    a = np.array([[float(r[k]) if r[k] else np.nan for k in keys] for r in rows])
    return au_fractions(c, ids), c, a, ids


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("runs", help="folder of tools/expression_runs.py's .npz files")
    ap.add_argument("--sample", help="contractions.csv of single_face.mp4")
    args = ap.parse_args()

    from myoface.analysis.expressions import au_fractions
    from myoface.bench.expression import (
        SAMPLE_REST,
        SAMPLE_SMILE,
        readings_ceiling,
        score_labels,
    )

    runs = {}
    for f in sorted(glob.glob(str(Path(args.runs) / "*.npz"))):
        d = dict(np.load(f))
        d["x"] = au_fractions(d["estimate"], list(d["ids"]))
        runs[Path(f).stem] = d
    sample = _sample(args.sample) if args.sample else None
    for name, kw in VARIANTS.items():
        cells = []
        for run, d in runs.items():
            labs = _reader(d["x"], d["estimate"], d["angles_est"], list(d["ids"]), **kw)
            s = score_labels(labs, list(d["played"]), list(d["phase"]))
            cells.append(f"{run} {100 * s['apex_accuracy']:.0f}/{100 * s['rest_accuracy']:.0f}")
        if sample is not None:
            labs = _reader(*sample, **kw)
            r = np.mean([labs[k] == "neutral" for k in SAMPLE_REST if k < len(labs)])
            s = np.mean([labs[k] == "happiness" for k in SAMPLE_SMILE if k < len(labs)])
            cells.append(f"sample {100 * r:.0f}/{100 * s:.0f}")
        print(f"{name}: " + " | ".join(cells))
    print("ceilings (presence / identity, true patterns / identity, own readings / causal "
          "presence, true rest labels):")  # fmt: skip
    for run, d in runs.items():
        r = readings_ceiling(d["estimate"], d["truth"], d["played"], d["phase"], d["angles_true"])
        cp = causal_presence(d["estimate"], d["phase"], d["angles_est"])
        own = r.get("identity_own_readings", float("nan"))
        print(f"  {run}: {r['presence']:.2f} / {r['identity_true_patterns']:.2f} / "
              f"{own:.2f} / {cp:.2f}  {r['identity_true_patterns_per_expression']}")  # fmt: skip


if __name__ == "__main__":
    main()
