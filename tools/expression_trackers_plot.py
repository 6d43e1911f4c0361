"""docs/expression_trackers.png: the benchmark's clip, played expression and phase, and the
label of every frame per tracker and with or without the fit's AU-space prior (cached fits of
``tools/expression_trackers.py fit OUTDIR bench``; runs whose file is missing are skipped).

    python tools/expression_trackers_plot.py OUTDIR [PNG]
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np


def main() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from myoface.analysis.expressions import COLORS, expression_sequence

    out = Path(sys.argv[1])
    png = Path(sys.argv[2]) if len(sys.argv) > 2 else Path("docs/expression_trackers.png")
    rows = []
    for tracker in ("fit", "flow", "photometric"):
        for prior in ("None", "0.1"):
            f = out / f"bench_{tracker}_{prior}.npz"
            if f.exists():
                rows.append((f"{tracker}" + (", AU prior" if prior != "None" else ""), f))
    d0 = dict(np.load(rows[0][1]))
    played, phase = d0["played"], d0["phase"]
    truth = [
        p if ph in ("apex", "onset", "offset") else "neutral"
        for p, ph in zip(played, phase, strict=True)
    ]
    fig, axes = plt.subplots(len(rows) + 1, 1, figsize=(10, 0.5 * (len(rows) + 1) + 0.9),
                             sharex=True)  # fmt: skip

    def band(ax, labels, name, score=""):
        for k, lab in enumerate(labels):
            ax.axvspan(k - 0.5, k + 0.5, color=COLORS.get(lab, "white"), lw=0)
        ax.set_yticks([])
        ax.set_ylabel(name + score, rotation=0, ha="right", va="center", fontsize=8)

    band(axes[0], truth, "played")
    for ax, (name, f) in zip(axes[1:], rows, strict=True):
        d = dict(np.load(f))
        _, labels = expression_sequence(d["estimate"], [str(i) for i in d["ids"]], d["angles_est"])
        apex = [labels[k] == played[k] for k in range(len(labels)) if phase[k] == "apex"]
        rest = [labels[k] == "neutral" for k in range(len(labels)) if phase[k] == "rest"]
        band(ax, labels, name, f"\napex {np.mean(apex):.2f} rest {np.mean(rest):.2f}")
    axes[-1].set_xlabel("frame (30 fps)", fontsize=8)
    handles = [plt.Rectangle((0, 0), 1, 1, color=c) for c in COLORS.values()]
    fig.legend(handles, list(COLORS), loc="upper center", ncol=7, fontsize=7, frameon=False)
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    fig.savefig(png, dpi=100)
    print("wrote", png)


if __name__ == "__main__":
    main()
