"""docs/expressions_rest_reference.png: the benchmark's clip with the head moving
(:mod:`myoface.bench.expression`, analysed end to end), its labels read frame by frame alone
and read above the person's rest reference (:class:`myoface.analysis.expressions.ExpressionReader`),
and what the reference does to the two AUs the fit reads most where there are none (AU17,
AU23) as the head turns.

    python tools/expression_rest_reference.py [-o docs/expressions_rest_reference.png]

About 1.5 minutes on a loaded 2-core machine (render, webcam degradation, MediaPipe, fit).
"""

from __future__ import annotations

import argparse

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("-o", "--output", default="docs/expressions_rest_reference.png")
    args = ap.parse_args()

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from myoface.analysis.expressions import (
        COLORS,
        EXPRESSIONS,
        NEUTRAL,
        ExpressionReader,
        au_fractions,
        expression_labels,
        expression_scores,
        rule_aus,
    )
    from myoface.bench.expression import EPISODES, episode_programme
    from myoface.bench.headmotion import (
        _model,
        degraded_sequence,
        detect_sequence,
        head_trajectory,
        relaxed_skins,
        run_headmotion,
    )

    fm = _model()
    truth, played, phase = episode_programme(fm.ids, EPISODES)
    poses = head_trajectory(len(truth), False)
    skins = relaxed_skins(fm, truth)
    frames, _ = degraded_sequence(fm.face, poses, skins)
    points, _ = detect_sequence(frames)
    del frames
    res = run_headmotion(fm, points, truth, poses, skins)

    alone = expression_labels(expression_scores(res.estimate, fm.ids))
    reader = ExpressionReader(fm.ids)
    x = au_fractions(res.estimate, fm.ids)
    ref = np.zeros_like(x)
    labels = []
    for k, (c, a) in enumerate(zip(res.estimate, res.angles_est, strict=True)):
        ref[k] = reader.reference(a)  # (what frame k is read above)
        labels.append(reader.read(c, a)[1])
    shown = [
        "neutral" if p == "rest" else pl if p == "apex" else ""
        for p, pl in zip(phase, played, strict=True)
    ]

    t = np.arange(len(truth)) / 30.0
    fig, axes = plt.subplots(
        5, 1, figsize=(10, 6.4), sharex=True, gridspec_kw={"height_ratios": [1, 1, 1, 3, 2]}
    )

    def band(ax, labs, name):
        for k, lab in enumerate(labs):
            if lab:
                ax.axvspan(t[k] - 1 / 60, t[k] + 1 / 60, color=COLORS[lab], lw=0)
        ax.set_yticks([])
        ax.set_ylabel(name, rotation=0, ha="right", va="center", fontsize=8)

    band(axes[0], shown, "played\n(apex, rest)")
    band(axes[1], alone, "each frame\nalone (before)")
    band(axes[2], labels, "above the\nrest reference")
    aus = rule_aus()
    for au, col in ((17, "#444"), (23, "#c44")):
        j = aus.index(au)
        axes[3].plot(t, x[:, j], color=col, lw=1.2, label=f"AU{au} read")
        axes[3].plot(t, ref[:, j], color=col, lw=1.0, ls="--", label=f"AU{au} rest reference")
    for k in range(len(t)):
        if phase[k] == "rest":
            axes[3].axvspan(t[k] - 1 / 60, t[k] + 1 / 60, color="0.92", lw=0, zorder=0)
    axes[3].set_ylabel("AU intensity\n(grey: rest)", fontsize=8)
    axes[3].set_ylim(0, 1.02)
    axes[3].legend(fontsize=7, ncol=4, loc="upper left", frameon=False)
    for i, name in enumerate(("yaw", "pitch", "roll")):
        axes[4].plot(t, res.angles_est[:, i], lw=1.0, label=name)
    axes[4].set_ylabel("head (deg,\nthe fit's)", fontsize=8)
    axes[4].legend(fontsize=7, ncol=3, loc="upper left", frameon=False)
    axes[4].set_xlabel("time (s)", fontsize=8)
    for ax in axes:
        ax.tick_params(labelsize=7)
    handles = [plt.Rectangle((0, 0), 1, 1, color=COLORS[e]) for e in (*EXPRESSIONS, NEUTRAL)]
    fig.legend(handles, [*EXPRESSIONS, NEUTRAL], ncol=7, fontsize=7, loc="upper center",
               bbox_to_anchor=(0.5, 0.965),
               frameon=False)  # fmt: skip
    fig.suptitle(
        "the benchmark's clip, head moving (yaw +-30, pitch/roll +-15 deg): labels read from the"
        " fit's contractions",
        fontsize=9,
        y=0.995,
    )
    fig.tight_layout(rect=(0, 0, 1, 0.93))
    fig.savefig(args.output, dpi=100)
    print(f"wrote {args.output}")


if __name__ == "__main__":
    main()
