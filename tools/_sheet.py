"""What the contact-sheet scripts in tools/ share."""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw


def labelled(img: np.ndarray, label: str) -> np.ndarray:
    """``img`` (H, W, 3) uint8 above an 18-px white band with ``label`` written in it."""
    h, w = img.shape[:2]
    canvas = Image.new("RGB", (w, h + 18), (255, 255, 255))
    canvas.paste(Image.fromarray(img), (0, 0))
    ImageDraw.Draw(canvas).text((6, h + 3), label, fill=(0, 0, 0))
    return np.asarray(canvas)
