"""docs/photo_animated.png (`python tools/photo_animated.py docs/photo_animated.png`): the person's
own photo animated (``myoface synth --in-photo``): the sample video's first frame as it is, then
smiling, frowning, talking, blinking and looking aside, each cropped around the head. The
person's model is made from the photo (as ``myoface face from-photo`` makes it); the sample video
is read from the user cache (``myoface demo`` fetches it) or ../shared/data."""

import os
import sys
from pathlib import Path

from myoface.analysis.video import open_video
from myoface.codec.photo import PhotoAnimation
from myoface.commands._common import contact_sheet

out = Path(sys.argv[1] if len(sys.argv) > 1 else "docs/photo_animated.png")
video = Path(os.path.expanduser("~/.cache/myoface/single_face.mp4"))
if not video.is_file():
    video = Path(__file__).resolve().parents[2] / "shared" / "data" / "video" / "single_face.mp4"
photo = next(iter(open_video(video)))
anim = PhotoAnimation.from_image(photo)
contact_sheet(
    anim.showcase(),
    out,
    "myoface synth --in-photo: the photo moved by the person's model",
)
print(f"wrote {out}")
