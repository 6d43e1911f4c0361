"""The decoder's picture alone (:class:`~myoface.codec.picture.PictureModel`): how fast the
calibration frame is moved by the person's model at 640x360, and how far the fixed-cost physics
is from the relaxed tissue.

The sample video's first frame (640x360) is the picture, the person's model made from it and
aligned to it (``myoface synth --in-photo``'s path, :class:`~myoface.codec.photo.PhotoAnimation`);
a 90-frame performance drives it: a smile, the viseme A (the jaw open: the model's mouth is
rendered), a blink, a surprise, the viseme O, one after the other, each rising and falling, the
head turning +-8 degrees and the eyes +-0.2 rad. ``codec.decode_fps`` measures the whole decoder
(stream, model, picture); this is the picture's share.
"""

from __future__ import annotations

import numpy as np

from myoface.bench import Measurement, benchmark

#: frames of the benchmark's performance (one cycle; the quick run renders a third of them)
N_FRAMES = 90


def _performance(model, calibration, n: int):
    """The benchmark's per-frame parameters (see the module)."""
    from scipy.spatial.transform import Rotation

    from myoface.codec.params import FrameParams
    from myoface.control import au_contractions, expression_contractions, viseme_contractions

    ids = model.ids
    keys = [
        expression_contractions("happiness", 1.0, ids),
        viseme_contractions("A", 1.0, ids),
        au_contractions({"45": 1.0}, ids),
        expression_contractions("surprise", 1.0, ids),
        viseme_contractions("O", 1.0, ids),
    ]
    out = []
    for k in range(n):
        a = k / n * len(keys)
        i = int(a)
        c = keys[i] * np.sin(np.pi * (a - i))
        yaw = np.deg2rad(8.0 * np.sin(2 * np.pi * k / 45))
        g = 0.2 * np.sin(2 * np.pi * k / 30)
        rot = Rotation.from_euler("y", yaw).as_matrix() @ calibration.rotation
        out.append(FrameParams(rot, calibration.translation, c, np.array([g, 0.0, g, 0.0])))
    return out


def _frames(quick: bool):
    from myoface.analysis.sample import fetch_sample_video
    from myoface.analysis.video import open_video

    frame = next(iter(open_video(fetch_sample_video(quiet=True))))
    return frame, N_FRAMES // 3 if quick else N_FRAMES


@benchmark("codec.picture_fps", "frames/s", higher_is_better=True)
def bench_picture_fps(quick: bool) -> Measurement:
    """Frames per second of PictureModel.render at 640x360 (the default physics, "linear"),
    the whole render (physics, warp, remap over the background, the model's mouth), median
    over the performance's frames after a warm-up; the detail: each stage's median ms and the
    whole render's 95th percentile, the same with the tissue relaxed per frame
    (physics="relax"), and the "linear" physics' skin against the relaxed one (px: median and
    largest of the frames' largest vertex error)."""
    from myoface.codec.photo import PhotoAnimation
    from myoface.codec.picture import PictureModel

    frame, n = _frames(quick)
    anim = PhotoAnimation.from_image(frame)
    model, cal, cam = anim.model, anim.picture.calibration, anim.picture.camera
    perf = _performance(model, cal, n)
    detail = {"size": f"{frame.shape[1]}x{frame.shape[0]}", "frames": n}
    skins = {}
    for physics in ("linear", "relax"):
        pm = PictureModel(model, cam, frame, cal, physics=physics)
        for p in perf[: max(n // 6, 3)]:  # warm-up: the JIT, the mouth's renderer
            pm.render(p)
        pm.stats = type(pm.stats)()
        skins[physics] = []
        for p in perf:
            pm.render(p)
            skins[physics].append(cam.project(p.pose.apply(pm.skin(p.contractions))))
        st = pm.stats
        detail[physics] = {
            "fps": round(1e3 / float(np.median(st.total_ms)), 1),
            "total_ms_p95": round(float(np.percentile(st.total_ms, 95)), 2),
            **{k: round(float(np.median(getattr(st, k))), 2)
               for k in ("physics_ms", "warp_ms", "remap_ms", "mouth_ms", "total_ms")},
        }  # fmt: skip
    err = np.linalg.norm(np.array(skins["linear"]) - np.array(skins["relax"]), axis=2).max(axis=1)
    detail["linear_vs_relax_px"] = {
        "median": round(float(np.median(err)), 2),
        "max": round(float(err.max()), 2),
    }
    return Measurement(detail["linear"]["fps"], n, detail=detail)
