"""The lids' reader (:mod:`myoface.analysis.lidtemplate`) on the gaze benchmark's clip, where
the truth is known: the degraded renders of the personal face (head +-30 deg, eyes turning,
four blinks), read through the true poses from the first frame's template.

    python tools/lidtemplate_check.py [--clip2] [key=value ...]

``key=value``: fields of :class:`~myoface.analysis.lidtemplate.LidTemplateSettings`. Prints,
per frame, the true and read shift of the upper lid and closure of the opening (gaps), and
their RMS error over the open frames and over the blinks' frames (true closure above 0.2), and
the read closures' gain there.
"""

from __future__ import annotations

import ast
import sys

import numpy as np


def main(argv) -> None:
    from myoface.analysis.camera import PinholeCamera
    from myoface.analysis.lidtemplate import LidTemplate, LidTemplateSettings
    from myoface.bench.headmotion import FOV_DEG, SIZE
    from myoface.muscles.lids import LOWER_SHARE

    sys.path.insert(0, "tools")
    from lidedge_check import _clip

    kw = {k: ast.literal_eval(v) for k, v in (a.split("=", 1) for a in argv if "=" in a)}
    _, frames, poses, _, closure, skins = _clip("--clip2" in argv)
    cam = PinholeCamera.for_image(SIZE[0], SIZE[1], FOV_DEG)
    t = LidTemplate(_face(), skins[0], frames[0], cam, poses[0], LidTemplateSettings(**kw))
    up_true, up_read, cl_true, cl_read = [], [], [], []
    for k in range(len(frames)):
        d = ((skins[k][t.vertices] - t.x0) * t.dir).sum(1) / t.gap_mm
        d = np.array([d[t.eye == e].mean() for e in (0, 1)])
        out = t.read(frames[k], poses[k])
        up_true.append(d)
        up_read.append(out["delta"])
        cl_true.append(d / (1 - LOWER_SHARE))  # (the lower lid rises LOWER_SHARE of the way)
        cl_read.append(out["closure"])
        print(k, f"closure {closure[k]:.2f}", "upper", d.round(2), out["delta"].round(2),
              "closure", cl_true[-1].round(2), out["closure"].round(2))  # fmt: skip
    for name, a, b in (("upper", up_read, up_true), ("closure", cl_read, cl_true)):
        a, b = np.array(a), np.array(b)
        e = a - b
        blink = np.array(cl_true) > 0.2
        both = blink & np.isfinite(a)
        gain = (a[both] * b[both]).sum() / (b[both] ** 2).sum()
        print(
            f"{name}: open RMS {np.sqrt(np.nanmean(e[~blink] ** 2)):.3f} (worst "
            f"{np.nanmax(np.abs(e[~blink])):.2f}, not read {np.isnan(e[~blink]).mean():.2f}); "
            f"blinks RMS {np.sqrt(np.nanmean(e[blink] ** 2)):.3f}, gain {gain:.2f} (not read "
            f"{np.isnan(e[blink]).mean():.2f})"
        )


def _face():
    from myoface.bench.headmotion import _model

    return _model().face


if __name__ == "__main__":
    main(sys.argv[1:])
