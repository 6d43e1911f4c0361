"""A ``.myo`` stream to frames (``myoface decode``): the header's person, camera and picture
make a :class:`~myoface.codec.picture.PictureModel`; each packet's parameters
(:class:`~myoface.codec.stream.StreamReader`) are rendered by it as they arrive.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

from myoface.codec.stream import ByteSource, Header, StreamReader, StreamTruncated, ids_checksum
from myoface.errors import MyofaceFormatError

#: the picture's physics for decoding (:data:`myoface.codec.picture.PHYSICS`): the skin's
#: linear response about the calibration, a fixed cost a frame (the relaxed tissue's is not)
DECODE_PHYSICS = "linear"


def person_model(header: Header):
    """The person's face model the stream describes: the header's face (the default face)
    with the person's identity offsets on its vertices, and the face's muscles."""
    from myoface.face import load_default_face
    from myoface.face.mesh import FaceMesh
    from myoface.model import build_face_model

    if header.face != "default":  # (Header.parse refuses others)
        raise MyofaceFormatError(f"the stream's face {header.face!r} is not one this myoface has")
    face = load_default_face()
    model0_ids = _default_ids()
    if header.ids_crc != ids_checksum(model0_ids) or header.n_contractions != len(model0_ids):
        raise MyofaceFormatError(
            "the stream was made with another face model's muscles than this myoface's "
            f"({header.n_contractions} contractions)"
        )
    if header.identity_mm.shape != face.vertices.shape:
        raise MyofaceFormatError(
            f"the stream's identity has {len(header.identity_mm)} vertices; the default face "
            f"{face.n_vertices}"
        )
    person = FaceMesh(face.vertices + header.identity_mm, face.triangles, face.uv, None,
                      face.landmarks, name="stream person")  # fmt: skip
    return build_face_model(person)


def picture_model_of(header: Header, physics: str = DECODE_PHYSICS):
    """The receiver's picture of ``header`` (its picture, the person's model, the camera and
    the calibration): the decoder's, and the encoder's for fitting the appearance terms on
    what the decoder will show. Returns (picture (H, W, 3) uint8, model, PictureModel)."""
    from myoface.codec.picture import PictureModel

    picture = header.picture()
    model = person_model(header)
    pm = PictureModel(model, header.camera, picture, header.calibration, physics=physics)
    return picture, model, pm


_IDS: list = []


def _default_ids() -> tuple:
    if not _IDS:
        from myoface.model import build_face_model

        _IDS.append(tuple(build_face_model().ids))
    return _IDS[0]


@dataclass
class DecodeStats:
    """What a decode did: frames rendered, the stream's end (``"end"`` or ``"truncated"``),
    and the wall time of the setup (header, model, picture) and of the frames."""

    n_frames: int = 0
    ended: str = ""
    setup_seconds: float = 0.0
    frame_seconds: float = 0.0
    render_ms: list = field(default_factory=list)

    @property
    def fps(self) -> float:
        """Frames per second over the whole decode (setup included)."""
        return self.n_frames / max(1e-9, self.setup_seconds + self.frame_seconds)


class Decoder:
    """A stream's frames: :attr:`header` and the picture model once made, then iterate
    :meth:`frames` for each frame's (H, W, 3) uint8 picture, and :meth:`params` for the
    parameters alone."""

    def __init__(self, source: ByteSource, physics: str = DECODE_PHYSICS):
        t0 = time.perf_counter()
        try:
            self.reader = StreamReader(source)
            self.header = self.reader.header
            self.picture, self.model, self.picture_model = picture_model_of(self.header, physics)
        except BaseException:
            source.close()
            raise
        self.stats = DecodeStats(setup_seconds=time.perf_counter() - t0)

    def params(self):
        """Each frame's parameters, as the stream carries them."""
        yield from self.reader

    def frames(self):
        """Each frame's picture (H, W, 3) uint8, rendered as its packet arrives."""
        t0 = time.perf_counter()
        try:
            for p in self.reader:
                t1 = time.perf_counter()
                img = self.picture_model.render(p)
                self.stats.render_ms.append((time.perf_counter() - t1) * 1e3)
                self.stats.n_frames += 1
                self.stats.frame_seconds = time.perf_counter() - t0
                yield img
            self.stats.ended = "end"
        except StreamTruncated:
            self.stats.ended = "truncated"
            raise
        finally:
            self.stats.frame_seconds = time.perf_counter() - t0

    def close(self) -> None:
        self.reader.close()


def decode_to_video(source: ByteSource, output, *, show_progress: bool = False,
                    physics: str = DECODE_PHYSICS) -> DecodeStats:  # fmt: skip
    """Decode ``source`` into the video ``output`` (written by
    :class:`~myoface.render.io.VideoWriter`: it appears when complete). A stream that stops
    early (:class:`StreamTruncated`) keeps the frames decoded until then in ``output`` and
    raises with a message that says so; any other bad stream leaves no output."""
    from myoface.render import progress
    from myoface.render.io import VideoWriter

    dec = Decoder(source, physics=physics)
    h = dec.header
    cut: StreamTruncated | None = None
    try:
        total = h.n_frames_hint or None
        with VideoWriter(output, fps=h.fps, background=True) as vw:
            frames = progress(dec.frames(), total=total, desc="decoding", enabled=show_progress)
            try:
                for img in frames:
                    vw.write(img)
            except StreamTruncated as exc:
                cut = exc
                if vw.n_frames == 0:
                    raise
    finally:
        dec.close()
    if cut is not None:
        raise StreamTruncated(
            f"{cut}; the {dec.stats.n_frames} frames decoded are in {output}", cut.frames
        )
    return dec.stats
