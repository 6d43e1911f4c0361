"""Which stage holds the known warps' regions with the anchored flow (issue 30): the fit with
``--flow`` (:mod:`myoface.analysis.modelflow`) on ``analysis.known_warp_gain``'s clips, head
still, with one stage of the tracker replaced by the warp's own answer (the warp moves every
pixel, so the true position of each tracked vertex on each frame is known):

- ``real``: nothing replaced (the fit as ``myoface analyze --flow`` runs it);
- ``exact_all``: every usable vertex given at its true position (the fit's reach with a
  perfect reader);
- ``exact_kept``: the vertices the tracker keeps given at their true positions, the others
  MediaPipe's (what the points it drops cost);
- ``exact_patch``: the vertices the tracker keeps given where the warp moves their patch on
  average (a perfect patch tracker: what a patch reads where the motion peaks);
- ``true_map``: the templates deformed by the warp's local maps, not the model's prediction;
- ``true_gap``: the mouth's gap masked where the warp puts it, not the prediction;
- ``true_start``: Lucas-Kanade started from the true positions.

Each prints the fit's gain and explained fraction per region (as the benchmark), the
tracker's own reading at the regions' points (its gain against the warp, over the points it
keeps), and its gain against the warp's motion averaged over each point's patch (uniformly,
and weighted by the calibration frame's structure tensor). ``--set JSON`` overrides
ModelFlow's parameters, e.g. ``--set '{"window": 7}'``; ``--fit JSON`` FitSettings', e.g.
``--fit '{"flow_footprint": false}'``; ``--moving`` the clips with fake head motion;
``--dump PREFIX`` saves the tracker's readings (reference, true, read, kept) to
``PREFIX_MODE.npz``. Runs with :data:`~myoface.analysis.modelflow.PREDICTION_LAG` 1
(``--lag``).

    python tools/flow_known_warp_stages.py real exact_all exact_kept true_map

What it found (2026-12-02, before FitSettings.flow_footprint): the tracker read 0.90 of the
mouth corners' motion and 0.97 of the brows' at the points, but 0.98 and 1.00 of the warp's
motion averaged over its 11-px patch (0.98 over every point it keeps): a patch reads its
window's mean motion, and where the motion peaks that is short of the peak. The fit, reading
the points at their vertices, gave every muscle less (the corners 0.80, the brows 0.87);
its priors (sparsity, magnitude, temporal: off, 0.80 / 0.89) and Huber's threshold (off:
0.77 / 0.87) did not hold them. With the footprint (the model's motion averaged over the
same patch) 0.88 / 0.93; a perfect patch tracker (``exact_patch``) 0.91 / 0.95.
"""

from __future__ import annotations

import argparse
import json

import numpy as np

MODES = ("real", "exact_all", "exact_kept", "exact_patch", "true_map", "true_gap", "true_start")


def run(mode: str, params: dict, lag: int, fit: dict | None = None, dump: str | None = None,
        moving: bool = False) -> None:  # fmt: skip
    import myoface.analysis.knownwarp as kwa
    import myoface.analysis.modelflow as mfm
    import myoface.bench.knownwarp as kwb
    from myoface.analysis.fidelity import REGIONS
    from myoface.analysis.weights import FitSettings

    warps: dict = {}  # id(frame) -> its warp
    made: list = []
    state = {"warp": None, "in_track": False, "origin": None, "true": None}
    saved = {
        (kwa, "expression_warp"): kwa.expression_warp,
        (kwb, "make_clip"): kwb.make_clip,
        (mfm, "local_affines"): mfm.local_affines,
        (mfm, "track_points"): mfm.track_points,
        (mfm, "PREDICTION_LAG"): mfm.PREDICTION_LAG,
        (mfm.ModelFlow, "__init__"): mfm.ModelFlow.__init__,
        (mfm.ModelFlow, "_pyramid"): mfm.ModelFlow._pyramid,
        (mfm.ModelFlow, "track"): mfm.ModelFlow.track,
    }
    orig = {k[1]: v for k, v in saved.items()}

    def expression_warp(*a, **k):
        w, s = orig["expression_warp"](*a, **k)
        made.append(w)
        return w, s

    def make_clip(*a, **k):
        made.clear()
        frames, truth, c = orig["make_clip"](*a, **k)
        warps.update({id(f): w for f, w in zip(frames, made, strict=True)})
        return frames, truth, c

    def init(self, **kw):
        orig["__init__"](self, **{**kw, **params})

    def local_affines(src, dst, start, nbr):
        if mode == "true_map" and state["in_track"] and state["warp"] is not None:
            dst = state["warp"].moved(src)
        return orig["local_affines"](src, dst, start, nbr)

    def pyramid(self, frame, lo, hi, polygon=None, prepared=None):
        w = state["warp"] if state["in_track"] else None
        if mode == "true_gap" and w is not None and polygon is not None:
            polygon = w.moved(self._ref["uv"][self._ref["gap"]])
        out = orig["_pyramid"](self, frame, lo, hi, polygon, prepared)
        if w is not None and out is not None:
            state["origin"], state["true"] = out[4], w.moved(self._ref["uv"])
        return out

    def track_points(*a):
        a = list(a)
        if mode == "true_start" and state["in_track"] and state["true"] is not None:
            a[9] = np.ascontiguousarray(state["true"] - state["origin"])  # (the guess)
        return orig["track_points"](*a)

    records = []
    avgs = []  # the warp's motion averaged over each point's patch: (uniform, gradient-weighted)

    def track(self, image, points, prediction=None, prepared=None, since=mfm._LAST):
        state["warp"], state["in_track"], state["true"] = warps.get(id(image)), True, None
        try:
            r = orig["track"](self, image, points, prediction, prepared=prepared, since=since)
        finally:
            state["in_track"] = False
        w = state["warp"]
        if r is None or w is None:
            return r
        true = w.moved(self._ref["uv"])
        records.append((self._ref["uv"].copy(), true, r[0].copy(), r[1].copy()))
        avgs.append(_patch_truth(self, w))
        if mode == "exact_patch":
            return np.where(r[1][:, None], avgs[-1][0], r[0]), r[1]
        if mode not in ("exact_all", "exact_kept"):
            return r
        xy, ok = r
        if mode == "exact_all":
            ok = self._ref["usable"].copy()
        return np.where(ok[:, None], true, xy), ok

    kwa.expression_warp, kwb.make_clip = expression_warp, make_clip
    mfm.local_affines, mfm.track_points, mfm.PREDICTION_LAG = local_affines, track_points, lag
    mfm.ModelFlow.__init__, mfm.ModelFlow._pyramid, mfm.ModelFlow.track = init, pyramid, track
    try:
        settings = FitSettings(**{"flow": True, **(fit or {})})
        out = kwb.run_known_warp(moving, False, settings, flow_method="anchored", field="flat")
    finally:
        for (obj, name), v in saved.items():
            setattr(obj, name, v)
    if dump:
        ref, true, xy, ok = (np.array(a) for a in zip(*records, strict=True))
        np.savez_compressed(f"{dump}_{mode}.npz", ref=ref, true=true, xy=xy, ok=ok)
    got = {r: (round(v["gain"], 3), round(v["explained"], 3)) for r, v in out["regions"].items()}
    print(f"{mode}: the fit's (gain, explained) {json.dumps(got)}, leak {out['leak']:.3f}")
    if avgs:
        for k, what in enumerate(("uniform", "gradient-weighted")):
            num = den = 0.0
            per = {}
            for name, ids in REGIONS.items():
                ids = np.asarray(ids)
                n2 = d2 = 0.0
                for (ref, _true, xy, ok), a in zip(records, avgs, strict=True):
                    o = ok[ids]
                    dt, dr = (a[k] - ref)[ids][o], (xy - ref)[ids][o]
                    n2 += float((dt * dr).sum())
                    d2 += float((dt * dt).sum())
                per[name] = round(n2 / max(d2, 1e-9), 3)
            for (ref, _true, xy, ok), a in zip(records, avgs, strict=True):
                dt, dr = (a[k] - ref)[ok], (xy - ref)[ok]
                num += float((dt * dr).sum())
                den += float((dt * dt).sum())
            print(
                f"  the tracker against the warp's motion averaged over its patch ({what}): "
                f"every kept point {num / max(den, 1e-9):.3f}, {json.dumps(per)}",
                flush=True,
            )
    for name, ids in REGIONS.items():
        ids = np.asarray(ids)
        num = den = res = 0.0
        kept = tot = 0
        for ref, true, xy, ok in records:
            o = ok[ids]
            kept, tot = kept + int(o.sum()), tot + len(ids)
            dt, dr = (true - ref)[ids][o], (xy - ref)[ids][o]
            num += float((dt * dr).sum())
            den += float((dt * dt).sum())
            res += float(((dr - dt) ** 2).sum())
        print(f"  the tracker at {name}: kept {kept / max(tot, 1):.2f}, gain "
              f"{num / max(den, 1e-9):.3f}, explained {1 - res / max(den, 1e-9):.3f}",
              flush=True)  # fmt: skip


def _patch_truth(flow, warp):
    """Where each reference point's patch (the tracker's window, level 0, in the calibration
    frame) goes on average under ``warp``: uniformly, and weighted by the calibration frame's
    high-passed structure tensor (what translation-only Lucas-Kanade's least squares weighs
    each pixel's motion by). (2 of (V, 2) px.)"""
    ref = flow._ref
    uv = ref["uv"]
    h = flow.window // 2
    o = np.stack(np.meshgrid(np.arange(-h, h + 1), np.arange(-h, h + 1)), -1).reshape(-1, 2)
    pix = uv[:, None, :] + o[None].astype(np.float64)  # (V, P, 2)
    moved = warp.moved(pix.reshape(-1, 2)).reshape(pix.shape) - o[None]
    uni = moved.mean(1)
    flat, _, offs, shapes, org = ref["pyr"]
    img = flat[offs[0] : offs[0] + shapes[0, 0] * shapes[0, 1]].reshape(shapes[0, 0], shapes[0, 1])
    gy, gx = np.gradient(img)
    ij = np.round(pix - org).astype(int)
    ij[..., 0] = np.clip(ij[..., 0], 0, img.shape[1] - 1)
    ij[..., 1] = np.clip(ij[..., 1], 0, img.shape[0] - 1)
    ax, ay = gx[ij[..., 1], ij[..., 0]], gy[ij[..., 1], ij[..., 0]]
    g = np.stack([np.stack([ax * ax, ax * ay], -1), np.stack([ax * ay, ay * ay], -1)], -2)
    gs = g.sum(1) + 1e-9 * np.eye(2)
    rhs = np.einsum("vpij,vpj->vi", g, moved)
    grad = np.linalg.solve(gs, rhs[..., None])[..., 0]
    return uni, grad


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("modes", nargs="+", choices=MODES)
    ap.add_argument("--set", default="{}", help="ModelFlow's parameters, JSON")
    ap.add_argument("--lag", type=int, default=1, help="modelflow.PREDICTION_LAG")
    ap.add_argument("--fit", default="{}", help="FitSettings' fields, JSON")
    ap.add_argument("--moving", action="store_true", help="the clips with fake head motion")
    ap.add_argument("--dump", default=None, help="save the tracker's readings to DUMP_MODE.npz")
    args = ap.parse_args(argv)
    for mode in args.modes:
        run(mode, json.loads(args.set), args.lag, json.loads(args.fit), args.dump, args.moving)


if __name__ == "__main__":
    main()
