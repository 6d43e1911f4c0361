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


def grid(tiles: list, per_row: int) -> np.ndarray:
    """Tiles of one size in rows of ``per_row``, the last row filled with white ones."""
    tiles = list(tiles)
    while len(tiles) % per_row:
        tiles.append(np.full_like(tiles[0], 255))
    rows = [np.concatenate(tiles[k : k + per_row], axis=1) for k in range(0, len(tiles), per_row)]
    return np.concatenate(rows, axis=0)
