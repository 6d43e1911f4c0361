"""The model-based codec's rate and quality (issue 32), side by side with x264 and the zero-rate
baseline in one run (``myoface bench --only codec``).

Two clips:

- ``sample``: the shared sample video ``single_face.mp4`` (72 frames, 640x360) looped forward
  and back to :data:`SAMPLE_SECONDS` s (600 frames at 30 fps; ``--quick``: its first 30);
- ``headmotion``: a person's face (``face_from_photo`` on the sample's first frame) turning
  its head +-30 deg while it makes the six expressions, rendered and degraded as a webcam
  films it (:func:`myoface.bench.headmotion.degraded_sequence`, the same frames as the head
  motion benchmark; 90 frames at 640x480, quick 16).

Each clip is analysed once (the 3-D fit, :class:`~myoface.codec.encode.VideoParams`: its wall
time gives ``codec.encode_fps``); its parameters are then coded at every quality
(:data:`~myoface.codec.entropy.QUALITIES`, their measured ladder and the default's rule
there) and decoded by the whole decoder
(:class:`~myoface.codec.decode.Decoder`: header, person's model, picture, every frame).

Quality is measured against the clip's own frames: PSNR of the luma (BT.601) over the pooled
squared error of all frames (a frame identical to its reference does not make it infinite),
over the face region (the convex hull of the person's face mesh where the analysis placed it
on each frame: forehead to chin, ear to ear) and over the whole frame; SSIM (scikit-image's,
on the luma) on every :data:`SSIM_EVERY`-th frame, its map averaged over the same regions.

The peers, measured in the same run on the same frames:

- x264 (PyAV's libx264, preset ``medium``, one key frame, average bit rate searched by
  bisection to hit a number of bytes; the H.264 packets' bytes are counted, no container). At
  these rates x264 cannot code 640x360 (it needs about 35 bytes a frame for skipped
  macroblocks alone, 21 kB for the sample's 20 s), so it is also given the frames at half and
  a quarter of the size (area-averaged, then scaled back up bilinearly) and the size that
  does best at the bytes is taken: x264 at its best, not at a size it cannot reach (where it
  cannot get down to our bytes at any size, as at the default quality on the sample, it is
  compared at its fewest bytes, more than ours: ``at_its_fewest_bytes`` in the detail). The
  bytes x264 needs for our face PSNR-Y are read off its rate-PSNR curve: at each size, its
  points at constant rate factors 51, 45, ..., 21, bisected in CRF until two adjacent points
  bracket our PSNR within :data:`CURVE_GAP_DB`, the bytes interpolated between them in
  log-bytes; the fewest over the sizes, with the bracketing points in the detail (an
  average-rate search read its rate control's steps instead: 22.1 kB where the curve says
  14.7 kB, 2026-12-02; x264's constant rate factor is its better mode at these rates);
- the zero-rate baseline: the stream's own header picture (the calibration frame as the
  receiver has it) repeated, no packets at all.

Equal bytes means the whole stream: our header, packets and trailer against x264's packets.
"""

from __future__ import annotations

import io
import time

import numpy as np

from myoface.analysis.potentials import LUMA_601
from myoface.bench import Measurement, benchmark
from myoface.codec.entropy import DEFAULT_QUALITY

SAMPLE_SECONDS = 20.0
QUALITY_ORDER = ("low", "medium", "high", "max")
SSIM_EVERY = 5
#: x264's frame sizes tried (fractions of the clip's)
X264_SCALES = (1.0, 0.5, 0.25)
#: x264's bytes within this fraction of the target count as equal
BYTES_TOLERANCE = 0.05
#: x264's constant rate factors for its rate-PSNR curve (then bisected where it crosses a
#: target)
X264_CRFS = (51, 45, 39, 33, 27, 21)
#: the curve's bracketing points no more than this far apart in face PSNR-Y (dB) ...
CURVE_GAP_DB = 0.25
#: ... or this close in CRF
CURVE_MIN_CRF_GAP = 0.5
LUMA = np.asarray(LUMA_601, dtype=np.float32)  # (BT.601)

_cache: dict = {}


# ------------------------------------------------------------------ clips


class _Frames:
    """A clip in memory: ``unique`` frames shown in the order ``order``, with what the
    analysis' driver reads of a video (fps, n_frames, iteration)."""

    def __init__(self, unique, order, fps: float, name: str):
        self.unique, self.order = unique, list(order)
        self.fps, self.n_frames = float(fps), len(self.order)
        self.size = (unique[0].shape[1], unique[0].shape[0])
        self.path = name
        self._luma: dict = {}

    def __iter__(self):
        return (self.unique[i] for i in self.order)

    def __len__(self) -> int:
        return self.n_frames

    def luma(self, k: int) -> np.ndarray:
        i = self.order[k]
        if i not in self._luma:
            self._luma[i] = self.unique[i].astype(np.float32) @ LUMA
        return self._luma[i]


def pingpong(n_unique: int, n_total: int) -> list[int]:
    """Frame indices 0..n-1, then back n-2..1, and so on, ``n_total`` of them."""
    cycle = list(range(n_unique)) + list(range(n_unique - 2, 0, -1))
    return [cycle[k % len(cycle)] for k in range(n_total)]


def _sample_clip(quick: bool) -> _Frames:
    from myoface.analysis.sample import fetch_sample_video
    from myoface.analysis.video import open_video

    video = open_video(fetch_sample_video(quiet=True))
    unique = list(video)
    fps = float(video.fps or 30.0)
    n = 30 if quick else int(round(SAMPLE_SECONDS * fps))
    return _Frames(unique, pingpong(len(unique), n), fps, "single_face.mp4 looped")


def _headmotion_clip(quick: bool) -> _Frames:
    from myoface.bench.headmotion import _frames

    frames = _frames(quick, still=False, degraded=True)
    return _Frames(frames, range(len(frames)), 30.0, "head-motion renders (degraded)")


# ------------------------------------------------------------------ analysis (once)


def _analysed(kind: str, quick: bool) -> dict:
    """The clip, its parameters by the analysis, the setup, the face hulls and the analysis'
    wall time (cached)."""
    key = ("analysed", kind, bool(quick))
    if key not in _cache:
        from myoface.codec.encode import VideoParams

        clip = _sample_clip(quick) if kind == "sample" else _headmotion_clip(quick)
        t0 = time.perf_counter()
        vp = VideoParams(clip)
        params = list(vp)
        seconds = time.perf_counter() - t0
        _cache[key] = {
            "clip": clip,
            "params": params,
            "setup": vp.setup,
            "analysis_seconds": seconds,
            "qualities": dict(vp.qualities),
            "hulls": _face_hulls(vp.setup, params),
        }
    return _cache[key]


def _face_hulls(setup, params) -> list[np.ndarray]:
    """Per frame, the convex hull (px) of the person's face mesh at the frame's pose (the
    analysis' own, held on frames it did not measure)."""
    import cv2

    from myoface.model import build_face_model

    neutral = build_face_model().skin_vertices() + setup.identity_mm
    cam = setup.camera
    out = []
    for p in params:
        uv = cam.project(p.pose.apply(neutral)).astype(np.float32)
        out.append(cv2.convexHull(uv).reshape(-1, 2))
    return out


def _mask(hull: np.ndarray, shape) -> np.ndarray:
    import cv2

    m = np.zeros(shape[:2], np.uint8)
    cv2.fillConvexPoly(m, np.round(hull).astype(np.int32), 1)
    return m.astype(bool)


# ------------------------------------------------------------------ quality


class _Quality:
    """PSNR-Y (pooled) and SSIM of test frames against a clip's, over the face and the frame."""

    def __init__(self, clip: _Frames, hulls, ssim: bool = True):
        self.clip, self.hulls, self.ssim = clip, hulls, ssim
        self.se_face = self.n_face = self.se_all = self.n_all = 0.0
        self.ssim_face: list[float] = []
        self.ssim_all: list[float] = []
        self.k = 0

    def add(self, frame: np.ndarray) -> None:
        from skimage.metrics import structural_similarity

        ref = self.clip.luma(self.k)
        y = frame.astype(np.float32) @ LUMA
        d = (y - ref) ** 2
        m = _mask(self.hulls[self.k], ref.shape)
        self.se_face += float(d[m].sum())
        self.n_face += int(m.sum())
        self.se_all += float(d.sum())
        self.n_all += d.size
        if self.ssim and self.k % SSIM_EVERY == 0:
            s, smap = structural_similarity(ref, y, data_range=255.0, full=True)
            self.ssim_all.append(float(s))
            self.ssim_face.append(float(smap[m].mean()))
        self.k += 1

    @staticmethod
    def _db(se, n) -> float:
        mse = se / max(n, 1)
        return float("inf") if mse == 0 else float(10 * np.log10(255.0**2 / mse))

    def result(self) -> dict:
        out = {
            "face_psnr_db": round(self._db(self.se_face, self.n_face), 3),
            "frame_psnr_db": round(self._db(self.se_all, self.n_all), 3),
        }
        if self.ssim_all:
            out["face_ssim"] = round(float(np.mean(self.ssim_face)), 4)
            out["frame_ssim"] = round(float(np.mean(self.ssim_all)), 4)
        return out


# ------------------------------------------------------------------ ours


def _ours(kind: str, quick: bool, quality: str) -> dict:
    """Our stream at ``quality``: bytes, bits per frame, the decoder's wall time, quality."""
    key = ("ours", kind, bool(quick), quality)
    if key not in _cache:
        from myoface.codec.decode import Decoder
        from myoface.codec.encode import encode_params
        from myoface.codec.stream import BytesSource

        a = _analysed(kind, quick)
        setup = a["setup"]
        buf = io.BytesIO()
        t0 = time.perf_counter()
        stats = encode_params(buf, a["params"], lambda: setup, quality=quality,
                              images=a["clip"])  # fmt: skip
        code_s = time.perf_counter() - t0
        data = buf.getvalue()
        q = _Quality(a["clip"], a["hulls"])
        t0 = time.perf_counter()
        dec = Decoder(BytesSource(data))
        setup_s = time.perf_counter() - t0
        picture = dec.picture
        frames = dec.frames()
        n, t_frames = 0, 0.0
        while True:
            t1 = time.perf_counter()
            img = next(frames, None)
            t_frames += time.perf_counter() - t1  # (the decoder's time; not the measuring)
            if img is None:
                break
            n += 1
            q.add(img)
        zero = _Quality(a["clip"], a["hulls"])
        for _ in range(len(a["clip"])):
            zero.add(picture)
        _cache[key] = {
            "quality": quality,
            "header_bytes": stats.header_bytes,
            "body_bytes": stats.body_bytes,
            "total_bytes": len(data),
            "bits_per_frame": round(stats.bits_per_frame, 2),
            "frames": n,
            "picture": stats.picture,
            "header_parts": {
                **stats.picture["parts"],
                "other": stats.header_bytes - sum(stats.picture["parts"].values()),
            },
            "packet_bits_per_frame": {
                k: round(v / max(n, 1), 2) for k, v in stats.channel_bits.items()
            },
            "coding_seconds": round(code_s, 3),
            "decoder_setup_seconds": round(setup_s, 3),
            "decoder_frames_seconds": round(t_frames, 3),
            "decode_fps": round(n / (setup_s + t_frames), 2),
            "render_ms_median": round(float(np.median(dec.stats.render_ms)), 2),
            **q.result(),
            "zero_rate": zero.result(),
        }
    return _cache[key]


# ------------------------------------------------------------------ x264


def _x264(clip: _Frames, bit_rate: float | None, scale: float,
          crf: float | None = None) -> tuple[int, list]:  # fmt: skip
    """``clip`` through libx264 at ``bit_rate`` (bit/s, ABR), or at the constant rate factor
    ``crf`` (``bit_rate`` None), at ``scale`` of its size: the H.264 packets' bytes and the
    decoded frames at the clip's size."""
    import av
    import cv2

    w, h = clip.size
    sw, sh = max(16, int(round(w * scale / 2)) * 2), max(16, int(round(h * scale / 2)) * 2)
    buf = io.BytesIO()
    out = av.open(buf, "w", format="mp4")
    s = out.add_stream("libx264", rate=int(round(clip.fps)))
    s.width, s.height, s.pix_fmt = sw, sh, "yuv420p"
    opts = {"preset": "medium", "x264-params": "keyint=infinite:qpmax=69"}
    if crf is None:
        s.bit_rate = max(1000, int(bit_rate))  # (libx264 takes kbit/s: at least 1)
    else:
        opts["crf"] = f"{crf:.2f}"
    s.options = opts
    n_bytes = 0
    for f in clip:
        img = f if (sw, sh) == (w, h) else cv2.resize(f, (sw, sh), interpolation=cv2.INTER_AREA)
        for pk in s.encode(av.VideoFrame.from_ndarray(np.ascontiguousarray(img), format="rgb24")):
            n_bytes += pk.size
            out.mux(pk)
    for pk in s.encode(None):
        n_bytes += pk.size
        out.mux(pk)
    out.close()
    buf.seek(0)
    frames = []
    with av.open(buf, "r") as inp:
        for fr in inp.decode(video=0):
            img = fr.to_ndarray(format="rgb24")
            if (sw, sh) != (w, h):
                img = cv2.resize(img, (w, h), interpolation=cv2.INTER_LINEAR)
            frames.append(img)
    return n_bytes, frames


def _x264_point(kind: str, quick: bool, bit_rate: float, scale: float, ssim: bool) -> dict:
    key = ("x264", kind, bool(quick), int(bit_rate), scale, ssim)
    if key not in _cache:
        a = _analysed(kind, quick)
        n_bytes, frames = _x264(a["clip"], bit_rate, scale)
        q = _Quality(a["clip"], a["hulls"], ssim=ssim)
        for f in frames[: len(a["clip"])]:
            q.add(f)
        _cache[key] = {"bytes": n_bytes, "bit_rate": int(bit_rate), "scale": scale, **q.result()}
    return _cache[key]


def _rate_for_bytes(kind, quick, scale, target: int, tries: int = 6) -> dict | None:
    """x264's point at ``scale`` whose bytes are within :data:`BYTES_TOLERANCE` of ``target``
    (the average bit rate corrected by the bytes it gave, secant-wise), None when x264
    cannot get down to them at that size (its bytes stop falling)."""
    a = _analysed(kind, quick)
    seconds = len(a["clip"]) / a["clip"].fps
    rate = max(1000.0, 8 * target / seconds)
    best = None
    for _ in range(tries):
        p = _x264_point(kind, quick, rate, scale, False)
        err = p["bytes"] / target - 1
        if best is None or abs(err) < abs(best[0]):
            best = (err, p)
        if abs(err) <= BYTES_TOLERANCE:
            return p
        if p["bytes"] > target and rate <= 1000.0:
            return None  # (its floor)
        new = max(1000.0, rate * target / p["bytes"])
        if abs(new - rate) < 1.0:
            break
        rate = new
    return best[1] if abs(best[0]) <= BYTES_TOLERANCE else None


def _x264_at_bytes(kind: str, quick: bool, target: int) -> dict | None:
    """x264 at (about) ``target`` bytes, at the size that does best there (None: at no size)."""
    key = ("x264_bytes", kind, bool(quick), target)
    if key not in _cache:
        tried = {}
        for scale in _scales(quick):
            p = _rate_for_bytes(kind, quick, scale, target)
            if p is not None:
                tried[scale] = _x264_point(kind, quick, p["bit_rate"], scale, True)
        floor = False
        if not tried:
            # x264 cannot get down to the bytes at any size: it is given its fewest bytes (more
            # than ours, in its favour), at the size where they are fewest
            floor = True
            pts = [v for k, v in _cache.items() if k[0] == "x264" and k[1:3] == (kind, quick)]
            p = min(pts, key=lambda v: v["bytes"])
            tried[p["scale"]] = _x264_point(kind, quick, p["bit_rate"], p["scale"], True)
        best = max(tried.values(), key=lambda c: c["face_psnr_db"])
        _cache[key] = {**best, "at_its_fewest_bytes": floor, "sizes_tried": {
            str(s): {k: v[k] for k in ("bytes", "face_psnr_db", "frame_psnr_db")}
            for s, v in tried.items()}}  # fmt: skip
    return _cache[key]


def _x264_crf_point(kind: str, quick: bool, crf: float, scale: float) -> dict:
    """x264 at constant rate factor ``crf`` and ``scale`` of the clip's size: its bytes and
    quality (no SSIM)."""
    crf = round(float(crf), 2)
    key = ("x264_crf", kind, bool(quick), crf, scale)
    if key not in _cache:
        a = _analysed(kind, quick)
        n_bytes, frames = _x264(a["clip"], None, scale, crf=crf)
        q = _Quality(a["clip"], a["hulls"], ssim=False)
        for f in frames[: len(a["clip"])]:
            q.add(f)
        _cache[key] = {"bytes": n_bytes, "crf": crf, "scale": scale, **q.result()}
    return _cache[key]


def _interp_log_bytes(lo: dict, hi: dict, target_db: float) -> float:
    """The bytes at face PSNR-Y ``target_db`` on the straight line through points ``lo`` and
    ``hi`` in (PSNR, log bytes)."""
    p0, p1 = lo["face_psnr_db"], hi["face_psnr_db"]
    l0, l1 = np.log(lo["bytes"]), np.log(hi["bytes"])
    t = 0.0 if p1 == p0 else (target_db - p0) / (p1 - p0)
    return float(np.exp(l0 + t * (l1 - l0)))


def _x264_bracket(kind: str, quick: bool, scale: float, target_db: float) -> dict | None:
    """x264's rate-PSNR curve at ``scale`` (its points at the constant rate factors
    :data:`X264_CRFS`, then bisected in CRF) around ``target_db``: the two points of
    adjacent CRFs whose face PSNR-Y brackets it, no more than :data:`CURVE_GAP_DB` apart
    (or CRFs :data:`CURVE_MIN_CRF_GAP` apart), and the bytes interpolated between them in
    log-bytes. None when x264 does not reach ``target_db`` at that size; ``below_curve``
    when it beats it at its fewest bytes (CRF 51: then those bytes, an upper bound)."""

    def pt(c):
        return _x264_crf_point(kind, quick, c, scale)

    crfs = sorted(X264_CRFS, reverse=True)  # (fewest bytes first)
    pts = [pt(c) for c in crfs]
    if pts[0]["face_psnr_db"] >= target_db:
        return {"bytes": pts[0]["bytes"], "scale": scale, "below_curve": True,
                "lo": pts[0], "hi": pts[0]}  # fmt: skip
    k = next((i for i, p in enumerate(pts) if p["face_psnr_db"] >= target_db), None)
    if k is None:
        return None
    lo, hi = pts[k - 1], pts[k]  # (lo: the higher CRF, below the target; hi: at or above)
    while (hi["face_psnr_db"] - lo["face_psnr_db"] > CURVE_GAP_DB
           and lo["crf"] - hi["crf"] > CURVE_MIN_CRF_GAP):  # fmt: skip
        mid = pt((lo["crf"] + hi["crf"]) / 2)
        if mid["face_psnr_db"] >= target_db:
            hi = mid
        else:
            lo = mid
    return {"bytes": int(round(_interp_log_bytes(lo, hi, target_db))), "scale": scale,
            "below_curve": False, "lo": lo, "hi": hi}  # fmt: skip


def _x264_for_psnr(kind: str, quick: bool, target_db: float) -> dict | None:
    """The bytes x264 needs to reach face PSNR-Y ``target_db``: on its rate-PSNR curve at
    each size (:func:`_x264_bracket`: constant rate factor points bracketing the target,
    interpolated in log-bytes; no reading at a rate control's step), the fewest over the
    sizes; with the bracketing points and every size's answer."""
    key = ("x264_psnr", kind, bool(quick), round(target_db, 3))
    if key not in _cache:
        found = {}
        for scale in _scales(quick):
            b = _x264_bracket(kind, quick, scale, target_db)
            if b is not None:
                found[scale] = b
        if not found:
            _cache[key] = None
        else:
            best = min(found.values(), key=lambda b: b["bytes"])
            keep = ("crf", "bytes", "face_psnr_db")
            _cache[key] = {
                "bytes": best["bytes"], "scale": best["scale"], "target_db": round(target_db, 3),
                "below_curve": best["below_curve"],
                "bracket": [{k: best[e][k] for k in keep} for e in ("lo", "hi")],
                "sizes": {str(s): b["bytes"] for s, b in found.items()},
            }  # fmt: skip
    return _cache[key]


# ------------------------------------------------------------------ the comparison


def _scales(quick: bool) -> tuple[float, ...]:
    """x264's frame sizes tried (a quick run: half size only)."""
    return (0.5,) if quick else X264_SCALES


def _qualities(quick: bool) -> tuple[str, ...]:
    return (DEFAULT_QUALITY,) if quick else QUALITY_ORDER


def _compare(kind: str, quick: bool) -> dict:
    """Ours at each quality, x264 at the same bytes, the zero-rate baseline, and the bytes
    x264 needs for our face PSNR-Y (default quality)."""
    key = ("compare", kind, bool(quick))
    if key not in _cache:
        rows = {}
        for qn in _qualities(quick):
            o = _ours(kind, quick, qn)
            x = _x264_at_bytes(kind, quick, o["total_bytes"])
            rows[qn] = {"ours": o, "x264_equal_bytes": x}
        med = rows[DEFAULT_QUALITY]["ours"]
        need = _x264_for_psnr(kind, quick, med["face_psnr_db"])
        a = _analysed(kind, quick)
        _cache[key] = {
            "clip": a["clip"].path,
            "frames": len(a["clip"]),
            "size": list(a["clip"].size),
            "analysis_seconds": round(a["analysis_seconds"], 2),
            "analysis_qualities": a["qualities"],
            "qualities": rows,
            "x264_for_our_face_psnr": need,
        }
    return _cache[key]


def _plot(quick: bool) -> str | None:
    """docs/codec_rate_quality.png: face PSNR-Y against total bytes, both clips (a full run
    writes it; the path, or None)."""
    if quick:
        return None
    from pathlib import Path

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from myoface._io import atomic_output

    docs = Path(__file__).resolve().parents[3] / "docs"
    if not docs.is_dir():
        return None
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    for ax, kind in zip(axes, ("sample", "headmotion"), strict=True):
        c = _compare(kind, quick)
        ours = [c["qualities"][q]["ours"] for q in _qualities(quick)]
        ax.plot([o["total_bytes"] / 1e3 for o in ours], [o["face_psnr_db"] for o in ours],
                "o-", color="C0", label="myoface codec (low..max)")  # fmt: skip
        for k, o in enumerate(ours):
            ax.annotate(o["quality"], (o["total_bytes"] / 1e3, o["face_psnr_db"]), fontsize=7,
                        xytext=(-6, -11 if k % 2 else 6), textcoords="offset points")  # fmt: skip
        # x264's rate-PSNR curves: its constant rate factor points at each size, and the
        # average-rate points the equal-bytes comparison tried
        for scale, ls in zip(_scales(quick), ("-", "--", ":"), strict=False):
            pts = sorted((v["bytes"], v["face_psnr_db"]) for k, v in _cache.items()
                         if k[0] == "x264_crf" and k[1:3] == (kind, quick) and k[4] == scale)  # fmt: skip
            if pts:
                b, db = np.array(pts).T
                ax.plot(b / 1e3, db, ls, color="C3", lw=1.2, label=f"x264 CRF, {scale:g} size")
        abr = [(v["bytes"], v["face_psnr_db"]) for k, v in _cache.items()
               if k[0] == "x264" and k[1:3] == (kind, quick)]  # fmt: skip
        if abr:
            b, db = np.array(abr).T
            ax.plot(b / 1e3, db, ".", color="C3", ms=3, label="x264 average rate (equal bytes)")
        need = c["x264_for_our_face_psnr"]
        if need is not None:
            med = c["qualities"][DEFAULT_QUALITY]["ours"]["total_bytes"]
            ax.plot(need["bytes"] / 1e3, need["target_db"], "kx", ms=8,
                    label=f"x264 at our {DEFAULT_QUALITY}'s PSNR: {need['bytes'] / 1e3:.1f} kB "
                    f"({need['bytes'] / med:.1f}x)")  # fmt: skip
        zr = ours[0]["zero_rate"]["face_psnr_db"]
        ax.axhline(zr, color="0.5", ls="--", label="zero rate (calibration frame)")
        ax.set_xscale("log")
        lo = min(o["total_bytes"] for o in ours) / 1e3
        ax.set_xlim(lo / 1.5, max(o["total_bytes"] for o in ours) / 1e3 * 12)
        ax.set_xlabel("total bytes (kB, log)")
        ax.set_ylabel("face region PSNR-Y (dB)")
        ax.set_title(f"{c['clip']}: {c['frames']} frames {c['size'][0]}x{c['size'][1]}",
                     fontsize=9)  # fmt: skip
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    path = docs / "codec_rate_quality.png"
    with atomic_output(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
    return str(path)


def _all(quick: bool) -> dict:
    key = ("all", bool(quick))
    if key not in _cache:
        out = {"sample": _compare("sample", quick), "headmotion": _compare("headmotion", quick)}
        out["plot"] = _plot(quick)
        _cache[key] = out
    return _cache[key]


def _medium(kind: str, quick: bool) -> dict:
    return _all(quick)[kind]["qualities"][DEFAULT_QUALITY]


def _decoded_fidelity(quick: bool) -> dict:
    """:func:`~myoface.analysis.fidelity.fidelity_of_video` of the decoded sample (default
    quality) against the sample video, on the video's own frames (the loop's first pass), from
    the stream's calibration frame: how much of the person's expression motion the receiver
    sees (the fidelity measure of issue 30, both sides read by its validated reader)."""
    key = ("fidelity", bool(quick))
    if key not in _cache:
        import tempfile
        from pathlib import Path

        from myoface.analysis.fidelity import fidelity_of_video
        from myoface.analysis.sample import fetch_sample_video
        from myoface.codec.decode import Decoder
        from myoface.codec.encode import encode_params
        from myoface.codec.stream import BytesSource
        from myoface.render import VideoWriter

        a = _analysed("sample", quick)
        clip = a["clip"]
        n = min(len(clip.unique), len(clip))
        buf = io.BytesIO()
        encode_params(buf, a["params"], lambda: a["setup"], quality=DEFAULT_QUALITY, images=clip)
        t0 = time.perf_counter()
        with tempfile.TemporaryDirectory() as tmp:
            out = Path(tmp) / "decoded.mp4"
            with VideoWriter(out, clip.fps) as vw:
                for k, img in enumerate(Decoder(BytesSource(buf.getvalue())).frames()):
                    if k >= n:
                        break
                    vw.write(img)
            cal = int(a["setup"].calibration_index)
            res = fidelity_of_video(fetch_sample_video(quiet=True), out, cal, range(n))
        _cache[key] = {
            "what": "the decoded sample against the sample video: the same motion reader on "
            "both (analysis.fidelity.fidelity_of_video)",
            "calibration_frame": cal,
            "frames": res.n_frames,
            "explained": round(float(res.overall.explained), 4),
            "gain": round(float(res.overall.gain), 4),
            "regions": {
                k: {"explained": round(float(v.explained), 4), "gain": round(float(v.gain), 4)}
                for k, v in res.regions.items()
            },
            "seconds": round(time.perf_counter() - t0, 1),
        }
    return _cache[key]


# ------------------------------------------------------------------ the benchmarks
# ------------------------------------------------------------------ the benchmarks


def _summary(quick: bool) -> dict:
    """The detail every codec benchmark carries: per clip and quality, ours, x264 and zero."""
    out = {}
    for kind in ("sample", "headmotion"):
        c = _all(quick)[kind]
        rows = {}
        for qn, r in c["qualities"].items():
            o, x = r["ours"], r["x264_equal_bytes"]
            rows[qn] = {
                "ours": {k: o[k] for k in ("total_bytes", "header_bytes", "header_parts",
                         "bits_per_frame", "packet_bits_per_frame", "face_psnr_db",
                         "frame_psnr_db", "face_ssim", "frame_ssim")},
                "x264": None if x is None else {k: x.get(k) for k in (
                    "bytes", "scale", "at_its_fewest_bytes", "face_psnr_db", "frame_psnr_db",
                    "face_ssim", "frame_ssim")},
                "zero_rate": o["zero_rate"],
                "picture": o["picture"]["codec"],
            }  # fmt: skip
        need = c["x264_for_our_face_psnr"]
        out[kind] = {
            "frames": c["frames"], "size": c["size"], "qualities": rows,
            "x264_for_our_face_psnr": None if need is None else {
                k: need[k] for k in ("bytes", "scale", "target_db", "below_curve", "bracket",
                                     "sizes")},
        }  # fmt: skip
    out["plot"] = _all(quick)["plot"]
    return out


@benchmark("codec.bits_per_frame", "bits", higher_is_better=False)
def bench_bits_per_frame(quick: bool) -> Measurement:
    """Bits per frame of the stream after its header (packets, the segments' checks and
    seals, the trailer's not counted), default quality, on the sample looped to 20 s (quick:
    1 s). The detail: every quality on both clips, ours against x264 at equal bytes and the
    zero-rate baseline (:mod:`myoface.bench.codec`)."""
    m = _medium("sample", quick)["ours"]
    return Measurement(m["bits_per_frame"], m["frames"], detail=_summary(quick))


@benchmark("codec.header_bytes", "bytes", higher_is_better=False)
def bench_header_bytes(quick: bool) -> Measurement:
    """The header's bytes (person, camera, calibration, the picture), default quality,
    sample; the detail: the picture's codecs tried (bytes at the quality's PSNR-Y)."""
    m = _medium("sample", quick)["ours"]
    return Measurement(m["header_bytes"], 1, detail=m["picture"])


@benchmark("codec.total_bytes", "bytes", higher_is_better=False)
def bench_total_bytes(quick: bool) -> Measurement:
    """The whole stream's bytes (header, packets, trailer), default quality, the sample
    looped to 20 s (quick: 1 s)."""
    m = _medium("sample", quick)["ours"]
    return Measurement(m["total_bytes"], 1)


@benchmark("codec.face_psnr_db", "dB", higher_is_better=True, peer="x264 at equal bytes")
def bench_face_psnr(quick: bool) -> Measurement:
    """Face region PSNR-Y (dB) of the decoded sample (looped to 20 s), default quality; the
    peer: x264 at the same total bytes, at its best frame size (or at its fewest bytes when
    it cannot go as low as ours: then it has more)."""
    r = _medium("sample", quick)
    x = r["x264_equal_bytes"]
    return Measurement(r["ours"]["face_psnr_db"], r["ours"]["frames"],
                       peer_value=None if x is None else x["face_psnr_db"],
                       detail={"ours": r["ours"], "x264": x})  # fmt: skip


@benchmark("codec.decoded_fidelity", "-", higher_is_better=True)
def bench_decoded_fidelity(quick: bool) -> Measurement:
    """The fidelity measure (issue 30's, :func:`~myoface.analysis.fidelity.fidelity_of_video`)
    of the decoded sample (default quality) to the sample video: the explained fraction of the
    person's expression motion in the judged regions, both videos read by the same validated
    motion reader from the stream's calibration frame; per region explained and gain in the
    detail (the gain < 1 where the receiver's face moves less than the person's)."""
    f = _decoded_fidelity(quick)
    return Measurement(f["explained"], f["frames"], detail=f)


@benchmark("codec.face_psnr_gain_db", "dB", higher_is_better=True)
def bench_face_gain(quick: bool) -> Measurement:
    """Our face PSNR-Y less x264's at equal total bytes (sample looped to 20 s, default
    quality); when x264 cannot get down to our bytes at any of its sizes, less x264's at its
    fewest bytes (more than ours; the detail says ``at_its_fewest_bytes``)."""
    r = _medium("sample", quick)
    x = r["x264_equal_bytes"]
    v = float("nan") if x is None else r["ours"]["face_psnr_db"] - x["face_psnr_db"]
    return Measurement(round(v, 3), r["ours"]["frames"], detail={"ours": r["ours"]["total_bytes"],
                       "x264": x})  # fmt: skip


@benchmark("codec.x264_bytes_ratio", "x", higher_is_better=True)
def bench_x264_ratio(quick: bool) -> Measurement:
    """The bytes x264 needs to reach our face PSNR-Y (sample looped to 20 s, default quality),
    over ours: on x264's rate-PSNR curve (constant rate factor points at each of its sizes,
    bisected until two adjacent points bracket our PSNR within 0.25 dB, the bytes
    interpolated between them in log-bytes; the fewest over the sizes); the bracketing points
    in the detail. NaN when x264 does not reach our PSNR at CRF 21 at any size."""
    c = _all(quick)["sample"]
    ours = c["qualities"][DEFAULT_QUALITY]["ours"]
    need = c["x264_for_our_face_psnr"]
    v = float("nan") if need is None else need["bytes"] / ours["total_bytes"]
    return Measurement(round(v, 3), 1, detail={"x264": need, "ours_bytes": ours["total_bytes"]})


@benchmark("codec.headmotion_gain_db", "dB", higher_is_better=True, peer="zero-rate baseline")
def bench_headmotion_gain(quick: bool) -> Measurement:
    """Our face PSNR-Y less the zero-rate baseline's (the header's picture repeated) on the
    head-motion renders, default quality; the peer value: the baseline's face PSNR-Y."""
    o = _medium("headmotion", quick)["ours"]
    z = o["zero_rate"]["face_psnr_db"]
    return Measurement(round(o["face_psnr_db"] - z, 3), o["frames"], peer_value=z,
                       detail={"ours": o, "x264_equal_bytes": _medium("headmotion", quick)[
                           "x264_equal_bytes"]})  # fmt: skip


@benchmark("codec.encode_fps", "frames/s", higher_is_better=True)
def bench_encode_fps(quick: bool) -> Measurement:
    """Frames per second of the encoder on the sample looped to 20 s: the analysis (MediaPipe
    and the 3-D fit, its calibration included) and the coding at the default quality, wall
    time."""
    a = _analysed("sample", quick)
    o = _medium("sample", quick)["ours"]
    secs = a["analysis_seconds"] + o["coding_seconds"]
    return Measurement(round(len(a["params"]) / secs, 2), len(a["params"]),
                       detail={"analysis_seconds": round(a["analysis_seconds"], 2),
                               "coding_seconds": o["coding_seconds"]})  # fmt: skip


@benchmark("codec.decode_fps", "frames/s", higher_is_better=True)
def bench_decode_fps(quick: bool) -> Measurement:
    """Frames per second of the whole decoder on the sample looped to 20 s at 640x360, default
    quality: the header read, the person's model and the picture model made, every frame
    rendered (writing a video file is not counted)."""
    o = _medium("sample", quick)["ours"]
    return Measurement(o["decode_fps"], o["frames"], detail={
        k: o[k] for k in ("decoder_setup_seconds", "decoder_frames_seconds", "render_ms_median")
    })  # fmt: skip
