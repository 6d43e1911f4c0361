"""Which stage holds the expression benchmark's accuracy (issue 33): the same episodes read
through each stage in turn, from the rule on the true contractions to the whole analysis on
the camera's frames with the head moving, for the default fit and the photometric one.

    python tools/expression_stages.py            # the benchmark's clip (~12 min, 2 cores)
    python tools/expression_stages.py --quick    # its quick clip (a smoke run)

Each row is ``bench.expression._synthetic`` (the benchmark's clip: six expressions at 0.5 and
1.0 on the face made from the sample video's first frame) with one stage changed: ``exact``
(the model's own projected vertices in place of MediaPipe's points), ``still`` (the head
frontal and still), ``clean`` (the renderer's frames, no camera), the tracker, and a
:class:`~myoface.analysis.weights.FitSettings` override. Printed as a Markdown table: apex
and rest accuracy (the benchmark's two numbers), the AUs read on the rest frames (the sum
over the AUs of their mean, and of their 90th percentile: what the analysis reads where
nothing is played, from ``bench.expression.readings_by_class``), the readings' gain of the AUs that tell the
expressions apart (the AU read over the AU played on the apex frames,
``bench.expression.au_readings``) and how the fear and sadness apexes were labelled.
docs/expression_trackers.md has a run's table and what it says.
"""

from __future__ import annotations

import sys
import time

#: (label, _synthetic's keyword arguments)
ROWS = (
    ("default fit, exact points, head moving", {"exact": True}),
    ("default fit, MediaPipe, head still, clean renders", {"still": True, "clean": True}),
    ("default fit, MediaPipe, head still", {"still": True}),
    ("**default fit, MediaPipe, head moving (the benchmark's value)**", {}),
    (
        "photometric, head still, clean renders",
        {"tracker": "photometric", "still": True, "clean": True},
    ),
    (
        "... the same, sparsity 0",
        {"tracker": "photometric", "still": True, "clean": True, "overrides": (("sparsity", 0.0),)},
    ),
    ("photometric, head still", {"tracker": "photometric", "still": True}),
    ("photometric, head moving, clean renders", {"tracker": "photometric", "clean": True}),
    ("photometric, head moving", {"tracker": "photometric"}),
    ("... the same, sparsity 2", {"tracker": "photometric", "overrides": (("sparsity", 2.0),)}),
    ("... the same, sparsity 1", {"tracker": "photometric", "overrides": (("sparsity", 1.0),)}),
)
#: the AUs whose gains the table shows (those the six expressions' apexes differ by)
AUS = ("AU1", "AU2", "AU4", "AU5", "AU15", "AU20", "AU23")


def _labelled(confusion: dict, played: str) -> str:
    row = confusion.get(played, {})
    n = sum(row.values())
    if not n:
        return "-"
    return ", ".join(f"{k} {v}" for k, v in sorted(row.items(), key=lambda kv: -kv[1]))


def main(argv=None) -> int:
    from myoface.bench.expression import _synthetic

    args = sys.argv[1:] if argv is None else argv
    quick = "--quick" in args
    head = ["stage", "apex", "rest", "rest readings (sum, p90 sum)", *(f"{a} gain" for a in AUS),
            "fear apexes", "sadness apexes", "s"]  # fmt: skip
    print("| " + " | ".join(head) + " |")
    print("|" + "---|" * len(head))
    truth = None
    for label, kw in ROWS:
        t0 = time.perf_counter()
        d = _synthetic(quick, **kw)
        if truth is None:
            truth = d["rule_on_true_contractions"]
            print(f"| the rule on the true contractions | {truth['apex_accuracy']:.3f} | "
                  f"{truth['rest_accuracy']:.3f} |" + " |" * (len(head) - 3))  # fmt: skip
        gains = []
        for a in AUS:
            g = d["au_readings"].get(a, {}).get("gain")
            gains.append("-" if g is None else f"{g:.2f}")
        rest = d["readings_by_class"]["rest"]
        means = [float(v.split()[0]) for v in rest.values()]
        p90 = [float(v.split("p90 ")[1].rstrip(")")) for v in rest.values()]
        cells = [label, f"{d['apex_accuracy']:.3f}", f"{d['rest_accuracy']:.3f}",
                 f"{sum(means):.2f}, {sum(p90):.2f}", *gains,
                 _labelled(d["confusion"], "fear"), _labelled(d["confusion"], "sadness"),
                 f"{time.perf_counter() - t0:.0f}"]  # fmt: skip
        print("| " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
