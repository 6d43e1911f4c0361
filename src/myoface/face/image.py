"""Reading images: the one place myoface reads a picture file (a photograph, a texture, a frame
of a folder of images, the texture of a face file), through Pillow, as 8-bit RGB.

Every colour space Pillow decodes becomes RGB (:func:`read_image`):

- CMYK (JPEGs of print workflows, TIFF), YCbCr, LAB and HSV by Pillow's conversion;
- palette images through their palette; black-and-white and grey (8 or 16 bits) repeated over
  the three channels;
- 16 bits per channel scaled to 8 (x 255 / 65535, rounded);
- an alpha channel dropped (the colour under it kept);
- 32-bit integer and floating-point images are refused (their range is not known), as are
  images of more than :data:`MAX_IMAGE_PIXELS` pixels.

Every failure is one :class:`~myoface.errors.MyofaceError` naming the file.
"""

from __future__ import annotations

import io
import os
import re
import warnings
from pathlib import Path

import numpy as np

from myoface.errors import (
    MyofaceFileNotFoundError,
    MyofaceFormatError,
    MyofaceValueError,
    user_message,
)

#: the most pixels of an image myoface reads (100 million: a 12000 x 8000 photograph is 96
#: million; decoded it is 300 MB of 8-bit RGB)
MAX_IMAGE_PIXELS = 100_000_000
#: 16-bit grey modes of Pillow
_GREY16 = ("I;16", "I;16L", "I;16B", "I;16N")


def _open(source, what: str, name: str):
    """``source`` (a path, or the bytes of a file called ``name``) opened by Pillow, its
    header read (the pixels are decoded when asked for)."""
    from PIL import Image, UnidentifiedImageError

    if isinstance(source, bytes | bytearray):
        source = io.BytesIO(source)
    else:
        p = Path(source)
        if not p.exists():
            raise MyofaceFileNotFoundError(f"no such {what}: {p}")
        if p.is_dir():
            raise MyofaceValueError(f"{what} {p} is a folder; expected an image file")
    with warnings.catch_warnings():
        # Pillow warns from 89 million pixels and refuses from 179: the bound is ours; and
        # it warns of what it mends in a damaged header ("Corrupt EXIF data"): the image is
        # read, or refused with a reason
        warnings.simplefilter("ignore")
        try:
            im = Image.open(source)
        except Image.DecompressionBombError as exc:  # (its size is in Pillow's message)
            m = re.search(r"\((\d+) pixels\)", str(exc))
            n = f"{int(m.group(1)) / 1e6:.0f} million" if m else "too many"
            raise MyofaceValueError(
                f"{name}: {n} pixels; myoface reads images of at most "
                f"{MAX_IMAGE_PIXELS / 1e6:g} million pixels (scale it down)"
            ) from None
        except UnidentifiedImageError:
            raise MyofaceFormatError(
                f"{name}: not an image file myoface can read (PNG, JPEG, TIFF, BMP, WebP, ...): "
                f"cannot read the {what}"
            ) from None
        except OSError as exc:
            raise MyofaceValueError(
                f"cannot read {what} {name}: {exc.strerror or user_message(exc)}"
            ) from None
    w, h = im.size
    if w < 1 or h < 1:
        raise MyofaceFormatError(f"{name}: an image of {w}x{h} pixels")
    if w * h > MAX_IMAGE_PIXELS:
        im.close()
        raise MyofaceValueError(
            f"{name}: {w}x{h} pixels ({w * h / 1e6:.0f} million); myoface reads images of at "
            f"most {MAX_IMAGE_PIXELS / 1e6:g} million pixels (scale it down)"
        )
    return im


def image_size(source, what: str = "image", *, name: str | None = None) -> tuple[int, int]:
    """The (width, height) in pixels of the image file ``source`` (a path, or the bytes of a
    file called ``name``), read from its header (checked as :func:`read_image` does)."""
    name = name or str(source)
    im = _open(source, what, name)
    try:
        return im.size
    finally:
        im.close()


def read_image(
    source: str | os.PathLike | bytes,
    what: str = "image",
    *,
    name: str | None = None,
    max_side: int | None = None,
    orient: bool = False,
) -> np.ndarray:
    """The image file ``source`` (a path, or the bytes of a file called ``name``) as an
    (H, W, 3) uint8 RGB array, row 0 at the top, whatever its colour space (see the module).

    Parameters
    ----------
    what : what the file should be, for the messages (a noun: ``"photo"``, ``"texture
        image"``).
    max_side : when given, an image with a longer side is scaled down (Lanczos; a JPEG is
        decoded at a reduced scale first, so that it never takes its full size in memory)
        to at most ``max_side`` pixels a side, its aspect kept.
    orient : turn the image upright as its EXIF orientation says (a photograph from a phone
        camera is stored sideways with a tag saying so); off for textures, whose pixels are
        addressed as stored.

    Raises
    ------
    MyofaceFileNotFoundError
        When ``source`` does not exist.
    MyofaceFormatError
        When it is not an image, is damaged or cut short, or its pixels are 32-bit.
    MyofaceValueError
        When it is a folder, or has more than :data:`MAX_IMAGE_PIXELS` pixels.
    """
    name = name or str(source)
    opened = _open(source, what, name)
    try:
        with warnings.catch_warnings():  # (what a decoder mends, see _open)
            warnings.simplefilter("ignore")
            rgb = _decoded(opened, what, name, max_side, orient)
    except (MyofaceFormatError, MyofaceValueError, MemoryError):
        raise
    except Exception as exc:  # Pillow's decoders raise many types on damaged data
        raise MyofaceFormatError(
            f"{name}: a damaged or truncated image ({user_message(exc, 150)}): cannot read "
            f"the {what}"
        ) from None
    finally:
        opened.close()
    return np.ascontiguousarray(rgb)


def _decoded(opened, what: str, name: str, max_side: int | None, orient: bool) -> np.ndarray:
    """The pixels of the opened image (see :func:`read_image`)."""
    from PIL import Image, ImageOps

    im = opened
    if max_side is not None and max(im.size) > max_side:
        k = max_side / max(im.size)
        target = (max(1, round(im.size[0] * k)), max(1, round(im.size[1] * k)))
        im.draft(im.mode, target)  # JPEG: decode at 1/2, 1/4 or 1/8 scale, >= target
    im.load()
    if orient:
        im = ImageOps.exif_transpose(im)
    im = _rgb8(im, what, name)
    if max_side is not None and max(im.size) > max_side:  # in Pillow: no numpy copy
        k = max_side / max(im.size)
        size = (max(1, round(im.size[0] * k)), max(1, round(im.size[1] * k)))
        im = im.resize(size, Image.Resampling.LANCZOS, reducing_gap=3.0)
    return np.asarray(im, dtype=np.uint8)


def _rgb8(im, what: str, name: str):
    """A loaded Pillow image as a Pillow RGB image (8 bits a channel)."""
    from PIL import Image

    mode = im.mode
    if mode in _GREY16 or (mode == "I" and im.format == "PNG"):  # (older Pillows: "I")
        a = np.asarray(im).astype(np.uint32)
        grey = ((a * 255 + 32767) // 65535).astype(np.uint8)
        return Image.fromarray(grey).convert("RGB")  # (Pillow's own I;16 -> RGB clips)
    if mode in ("I", "F") or mode.startswith("I;"):
        kind = "floating-point" if mode == "F" else "integer"
        raise MyofaceFormatError(
            f"{name}: a 32-bit {kind} image, whose range of values is not known; the {what} "
            "must have 8 or 16 bits per channel (RGB or grey)"
        )
    if mode != "RGB":
        try:
            im = im.convert("RGB")
        except ValueError:  # a mode Pillow cannot convert
            raise MyofaceFormatError(
                f"{name}: an image in Pillow's mode {mode!r}, which cannot be converted to RGB; "
                f"save the {what} as RGB"
            ) from None
    return im
