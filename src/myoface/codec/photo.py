"""The person's own photo, animated: a still picture driven by expressions, action units,
visemes and timelines through the decoder's picture (:class:`~myoface.codec.picture.PictureModel`),
``myoface synth --in-photo PHOTO``.

The face model is the person's (``--face person.myoface``) or, without one, made from the
photo itself as ``myoface face from-photo`` makes it (:func:`~myoface.face.personal.face_from_photo`);
either is aligned to the face MediaPipe finds in the photo (:func:`~myoface.codec.picture.photo_setup`)
and the photo is moved by the model's skin: the photo smiles, frowns, talks, blinks and looks
around, its background still.

>>> anim = PhotoAnimation.from_image(photo)            # doctest: +SKIP
>>> img = anim.image(contractions)                     # (H, W, 3) uint8
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from myoface.codec.params import FrameParams
from myoface.codec.picture import PictureModel, photo_setup
from myoface.errors import MyofaceValueError

__all__ = ["ANIMATE_MAX_SIDE", "SHOWCASE", "PhotoAnimation", "read_photo"]

#: a photo is animated at most this many pixels a side (a larger one is scaled down first):
#: a video of a 4096-px photo would be a 4K video, and every frame's warp costs its pixels
ANIMATE_MAX_SIDE = 1920


def read_photo(path: str | os.PathLike, max_side: int = ANIMATE_MAX_SIDE) -> np.ndarray:
    """The photo at ``path`` as (H, W, 3) uint8 RGB, upright by its EXIF orientation, at most
    ``max_side`` pixels a side (scaled down, aspect kept)."""
    import cv2

    from myoface.errors import MyofaceFileNotFoundError
    from myoface.face.image import read_image

    p = Path(path)
    if p.is_dir():
        raise MyofaceValueError(f"--in-photo {p} is a folder; expected an image")
    if not p.is_file():
        raise MyofaceFileNotFoundError(f"--in-photo: no such photo: {p}")
    img = read_image(p, "photo", max_side=2 * max_side, orient=True)
    h, w = img.shape[:2]
    if max(h, w) <= max_side:
        return img
    k = max_side / max(h, w)
    size = (max(1, round(w * k)), max(1, round(h * k)))
    return cv2.resize(img, size, interpolation=cv2.INTER_AREA)


#: the panels of :meth:`PhotoAnimation.showcase`: (title, kind, name, intensity, gaze rad)
SHOWCASE = (
    ("the photo", None, None, 0.0, None),
    ("smiling (happiness)", "expression", "happiness", 1.0, None),
    ("frowning (anger)", "expression", "anger", 1.0, None),
    ("talking (viseme A)", "viseme", "A", 1.0, None),
    ("blinking (AU45)", "au", "45", 1.0, None),
    ("looking aside (20 deg)", None, None, 0.0, (0.35, 0.0)),
)


class PhotoAnimation:
    """A photo and the model aligned to it: :meth:`image` renders the photo at contractions
    (and a gaze); :meth:`frames` a table of them.

    Attributes
    ----------
    picture : PictureModel — the photo's.
    model : FaceModel — the person's (made from the photo when none was given).
    made_face : bool — whether the model was made from the photo.
    """

    def __init__(self, picture: PictureModel, made_face: bool):
        self.picture = picture
        self.model = picture.model
        self.made_face = made_face

    @classmethod
    def from_image(cls, image: np.ndarray, model=None, *, face_index: int | None = None,
                   physics: str = "relax") -> PhotoAnimation:  # fmt: skip
        """The animation of ``image`` (H, W, 3) uint8 RGB with ``model`` (a FaceModel in the
        default topology; None: the person's face made from the photo). Needs the
        ``mediapipe`` extra (the face's points in the photo)."""
        from myoface.face.personal import choose_face, face_from_photo, photo_faces
        from myoface.model import build_face_model

        img = np.ascontiguousarray(np.asarray(image)[:, :, :3])
        faces = photo_faces(img)
        k = choose_face(faces, face_index)
        made = model is None
        if made:
            face, _ = face_from_photo(img, face_index=k, name="photo")
            model = build_face_model(face)
        elif model.face.n_vertices != len(faces[k]):
            raise MyofaceValueError(
                "animating a photo needs a face model in MediaPipe's 468-point topology (the "
                "default face or a personal face made by myoface face from-scan/from-photo); "
                f"this one has {model.face.n_vertices} vertices"
            )
        cam, params = photo_setup(model, faces[k], img.shape[1], img.shape[0])
        return cls(PictureModel(model, cam, img, params, physics=physics), made)

    def params(self, contractions, gaze=None) -> FrameParams:
        """The photo's parameters at ``contractions`` (M,) with the eyes turned by ``gaze``
        (``(yaw, pitch)`` rad, both eyes; None: as in the photo, straight ahead)."""
        cal = self.picture.calibration
        g = np.zeros(4) if gaze is None else np.tile(np.asarray(gaze, dtype=np.float64), 2)
        return FrameParams(cal.rotation, cal.translation, contractions, g)

    def image(self, contractions, gaze=None) -> np.ndarray:
        """The photo (H, W, 3) uint8 at ``contractions`` (see :meth:`params`)."""
        return self.picture.render(self.params(contractions, gaze))

    def head_box(self, margin: float = 0.25) -> tuple[slice, slice]:
        """(rows, columns) of the photo around the head: the face's rim at calibration,
        ``margin`` of its size wider each side (clipped to the photo)."""
        pm = self.picture
        rim = pm.face_outline()
        (x0, y0), (x1, y1) = rim.min(axis=0), rim.max(axis=0)
        mx, my = margin * (x1 - x0), margin * (y1 - y0)
        h, w = pm.height, pm.width
        rows = slice(max(int(y0 - 1.3 * my), 0), min(int(y1 + my) + 1, h))
        cols = slice(max(int(x0 - mx), 0), min(int(x1 + mx) + 1, w))
        return rows, cols

    def showcase(self) -> dict[str, np.ndarray]:
        """The photo as it is and smiling, frowning, talking, blinking and looking aside
        (:data:`SHOWCASE`), each cropped around the head (:meth:`head_box`): a contact
        sheet's panels."""
        from myoface.control import au_contractions, expression_contractions, viseme_contractions

        ids = self.model.ids
        box = self.head_box()
        out = {}
        for name, kind, what, value, gaze in SHOWCASE:
            if kind == "expression":
                c = expression_contractions(what, value, ids)
            elif kind == "viseme":
                c = viseme_contractions(what, value, ids)
            elif kind == "au":
                c = au_contractions({what: value}, ids)
            else:
                c = np.zeros(len(ids))
            out[name] = self.image(c, gaze)[box]
        return out

    def frames(self, table: np.ndarray, gaze: np.ndarray | None = None):
        """A generator of the photo at each row of ``table`` (T, M), the eyes at ``gaze``
        (T, 2) rad when given."""
        for k, c in enumerate(np.asarray(table, dtype=np.float64)):
            yield self.image(c, None if gaze is None else gaze[k])
