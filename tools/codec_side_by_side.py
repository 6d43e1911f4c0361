"""docs/codec_side_by_side.mp4 and docs/codec_contact_sheet.png
(``python tools/codec_side_by_side.py docs``): the sample video looped forward and back to 20 s
(as ``myoface bench --only codec`` codes it), side by side: the input, what ``myoface decode``
makes of its ``myoface encode`` stream at the default quality, x264 (PyAV's libx264) at the same
total bytes, at the frame size that does best there (where x264 cannot get down to our bytes at
any size, at its fewest bytes, more than ours: at 4 kbit/s it sends little more than grey), and
x264 where it reaches our face PSNR-Y over the clip (its constant rate factor point just at or
above it, on its rate-PSNR curve, :func:`myoface.bench.codec._x264_for_psnr`). Each panel says its
bytes over the whole 20-s clip and the face's PSNR-Y on that frame; the sheet shows four moments
(rest, the smile rising, its apex, and falling).

The video is the first 10 s (the clip's second half is the first played backwards)."""

import io
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from tools._sheet import grid, labelled  # noqa: E402

import myoface.bench.codec as C  # noqa: E402
from myoface.codec.decode import Decoder  # noqa: E402
from myoface.codec.encode import encode_params  # noqa: E402
from myoface.codec.stream import BytesSource  # noqa: E402
from myoface.render import VideoWriter  # noqa: E402

out_dir = Path(sys.argv[1] if len(sys.argv) > 1 else "docs")
QUALITY = "medium"
SECONDS = 10.0

a = C._analysed("sample", False)
clip, hulls = a["clip"], a["hulls"]
ours = C._ours("sample", False, QUALITY)
buf = io.BytesIO()
encode_params(buf, a["params"], lambda: a["setup"], quality=QUALITY, images=clip)
decoded = [f.copy() for f in Decoder(BytesSource(buf.getvalue())).frames()]
x = C._x264_at_bytes("sample", False, ours["total_bytes"])
x_bytes, x_frames = C._x264(clip, x["bit_rate"], x["scale"])
# ... and where it reaches our face PSNR-Y (over the clip) on its rate-PSNR curve: the
# constant rate factor point just at or above it (the curve's bracket's upper point)
need = C._x264_for_psnr("sample", False, ours["face_psnr_db"])
n_bytes, n_frames = C._x264(clip, None, need["scale"], crf=need["bracket"][1]["crf"])
inputs = list(clip)
n = min(len(inputs), len(decoded), len(x_frames), len(n_frames))


def face_psnr(k: int, img: np.ndarray) -> float:
    m = C._mask(hulls[k], img.shape[:2])
    d = (img.astype(np.float32) @ C.LUMA - clip.luma(k))[m]
    return float(10 * np.log10(255.0**2 / max(float(np.mean(d * d)), 1e-9)))


def panels(k: int) -> list[np.ndarray]:
    return [
        labelled(inputs[k], f"input, frame {k}"),
        labelled(
            decoded[k], f"myoface {ours['total_bytes']} B: face {face_psnr(k, decoded[k]):.1f} dB"
        ),
        labelled(
            x_frames[k],
            f"x264 {x_bytes} B{' (its fewest)' if x.get('at_its_fewest_bytes') else ''}, "
            f"{x['scale']:g} size: face {face_psnr(k, x_frames[k]):.1f} dB",
        ),
        labelled(
            n_frames[k],
            f"x264 {n_bytes} B ({n_bytes / ours['total_bytes']:.1f}x), {need['scale']:g} size: "
            f"face {face_psnr(k, n_frames[k]):.1f} dB",
        ),
    ]


out_dir.mkdir(parents=True, exist_ok=True)
video = out_dir / "codec_side_by_side.mp4"
with VideoWriter(video, clip.fps) as vw:
    for k in range(min(n, int(SECONDS * clip.fps))):
        vw.write(np.concatenate(panels(k), axis=1))
# four moments of the smile: rest, rising, apex, falling (frames of the sample's first pass)
moments = [5, 24, 45, 69]
sheet = grid([p for k in moments for p in panels(k)], 4)
from PIL import Image  # noqa: E402

Image.fromarray(sheet).save(out_dir / "codec_contact_sheet.png")
print(
    f"wrote {video} and {out_dir / 'codec_contact_sheet.png'}: ours {ours['total_bytes']} B "
    f"({ours['bits_per_frame']} bits a frame after a {ours['header_bytes']}-B header), x264 "
    f"{x_bytes} B at {x['scale']:g} of the size"
    + (" (its fewest)" if x.get("at_its_fewest_bytes") else "")
)
