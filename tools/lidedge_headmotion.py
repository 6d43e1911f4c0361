"""The head-motion benchmark's loop (``myoface bench --only analysis.headmotion``) with and
without the lid margins' edge term (FitSettings.lid_edges), on the same frames:

    python tools/lidedge_headmotion.py [--quick] [--still]

prints each run's worst and median RMSE, the lid muscles' RMSE, skin (mm) and head (deg)
error, and the fit's time a frame. (The benchmark gives the fit no image unless its
photometric term is on; here each frame's image is handed to the fit with its points.)"""

from __future__ import annotations

import sys

import numpy as np


def main() -> None:
    import myoface.bench.headmotion as H
    from myoface.analysis.modelfit import ModelFit
    from myoface.analysis.weights import FitSettings

    quick, still = "--quick" in sys.argv, "--still" in sys.argv
    fm, truth, poses, skins, points, _ = H._sequence(quick, still, False, True)
    frames = H._frames(quick, still, True)
    by_id = {id(p): f for p, f in zip(points, frames, strict=True) if p is not None}
    fit = ModelFit.fit

    def with_image(self, pts, *a, **kw):
        if self.settings.lid_edges and kw.get("image") is None:
            kw["image"] = by_id.get(id(pts))
        return fit(self, pts, *a, **kw)

    ModelFit.fit = with_image
    for on in (False, True):
        res = H.run_headmotion(fm, points, truth, poses, skins,
                               settings=FitSettings(lid_edges=on), frames=frames)  # fmt: skip
        s = res.summary()
        ids = list(res.ids)
        lid = {m: round(float(np.sqrt(np.nanmean((res.estimate[:, ids.index(m)]
                                                   - res.truth[:, ids.index(m)]) ** 2))), 3)
               for m in ids if "palpebr" in m}  # fmt: skip
        keys = ("rmse_worst", "rmse_worst_muscle", "rmse_median_all", "skin_mm", "pose_deg")
        got = {k: (round(v, 3) if isinstance(v, float) else v) for k, v in s.items() if k in keys}
        print(f"lid_edges={on}:", got, "lids", lid,
              f"fit {1e3 * np.nanmean(res.fit_seconds):.1f} ms/frame")  # fmt: skip


if __name__ == "__main__":
    main()
