"""The ``.myo`` bitstream (format version :data:`VERSION`; every field in docs/codec-format.md):
a header sent once, the frames' packets as one range-coded body cut into segments, and a
trailer.

- :class:`Header`: the stream's sizes, the camera, the quantiser's steps, the person's face
  (the default face's ids and the person's identity offsets), the calibration frame's
  parameters and its picture (a WebP, AVIF or JPEG image);
- :class:`StreamWriter`: writes the header, then each frame's packet as it is given (the words
  of the range coder that can no longer change are written and flushed after every frame), a
  segment's check and seal every :attr:`Header.segment_frames` frames, the end marker and the
  trailer (:meth:`StreamWriter.close`);
- :class:`StreamReader`: reads a stream from a :class:`ByteSource` (a file, a growing file, a
  pipe), yielding each frame's :class:`~myoface.codec.params.FrameParams` as soon as the words
  it needs have arrived. Every failure is a :class:`~myoface.errors.MyofaceFormatError`
  (:class:`StreamTruncated` for a stream that stops early, with the frames decoded so far).

Nothing a stream says makes the reader allocate more than its bounds: the header's sizes are
checked against :data:`MAX_WIDTH`, :data:`MAX_PIXELS` and the other limits before anything is
read into memory, the picture's own size against the header's before it is decoded, and a
segment's words against :data:`MAX_SEGMENT_WORDS_PER_FRAME`.
"""

from __future__ import annotations

import io
import os
import struct
import sys
import time
import zlib
from dataclasses import dataclass

import numpy as np

from myoface.analysis.camera import PinholeCamera, rotmat, rotvec
from myoface.codec.entropy import ParamCoder, RangeIO, Steps, code_identity, identity_order
from myoface.codec.params import N_APPEARANCE, FrameParams
from myoface.errors import MyofaceFormatError

MAGIC = b"MYOF"
#: the format version written (2: the packets carry the appearance terms,
#: :data:`~myoface.codec.params.APPEARANCE_FIELDS`; 3: the same packets' symbols under
#: better adaptive models, :class:`~myoface.codec.entropy.ParamCoder`'s ``model=3``)
VERSION = 3
#: the versions read (1: packets without the appearance; 2: version 3's packets under the
#: first models)
VERSIONS_READ = (1, 2, 3)
TRAILER_MAGIC = b"MYOE"
#: the header's bounds (a stream beyond them is refused before anything is allocated)
MAX_WIDTH = MAX_HEIGHT = 4096
MAX_PIXELS = 4096 * 2304
MAX_HEADER_BYTES = 32 << 20
MAX_IMAGE_BYTES = 24 << 20
MAX_IDENTITY_BYTES = 1 << 20
MAX_SEGMENT_FRAMES = 4096
MAX_CONTRACTIONS = 255
MAX_VERTICES = 1 << 16
#: a frame's packet never needs more words than this (measured: 2-4 at the default
#: quality); a segment longer than its frames allow is corrupted
MAX_SEGMENT_WORDS_PER_FRAME = 256
#: frames per segment (each segment ends in a 16-bit check and the range coder's seal)
SEGMENT_FRAMES = 128
#: a segment's filler: 0 to PAD_CHOICES - 1 symbols of 16 uniform bits before its check
PAD_CHOICES = 8
#: the picture's codecs, by their byte in the header
IMAGE_CODECS = {1: "webp", 2: "avif", 3: "jpeg"}
IMAGE_CODEC_IDS = {v: k for k, v in IMAGE_CODECS.items()}
#: faces a stream can be based on, by their byte: 0 the bundled default face
FACES = {0: "default"}
#: what the receiver shows behind the head, by its byte: 0 the calibration picture's own
#: pixels (no separate plate)
BACKGROUNDS = {0: "calibration picture"}
#: the qualities' names by their byte (255: steps of one's own)
QUALITY_NAMES = {0: "low", 1: "medium", 2: "high", 3: "max", 255: "custom"}


def ids_checksum(ids) -> int:
    """The CRC-32 of the contraction ids (``","``-joined, UTF-8): the header names the
    receiver's model by it."""
    return zlib.crc32(",".join(ids).encode())


def coder_of(h: Header) -> ParamCoder:
    """The packets' coder of a stream with header ``h`` (both sides make it the same)."""
    return ParamCoder(h.n_contractions, h.steps, h.calibration, h.n_appearance, h.packet_model)


class StreamTruncated(MyofaceFormatError):
    """The stream stopped before its end marker; :attr:`frames` were decoded before that."""

    def __init__(self, message: str, frames: int):
        super().__init__(message)
        self.frames = frames


# ------------------------------------------------------------------ the header


@dataclass
class Header:
    """Everything the receiver needs before the first packet (docs/codec-format.md,
    "Header").

    Attributes
    ----------
    width, height : the frames' size, px.
    fps : frames per second.
    n_frames_hint : the frames the sender expects to send (0: not known; the trailer has the
        count).
    quality : the quality's name (:data:`~myoface.codec.entropy.QUALITIES`, or "custom").
    steps : the quantiser's steps.
    segment_frames : frames per segment.
    camera : the analysis' pinhole camera.
    face : the face the model is based on (``"default"``).
    ids_crc : :func:`ids_checksum` of the model's contraction ids.
    n_contractions : len(ids).
    calibration_index : the calibration frame's index among the stream's frames.
    calibration : its parameters (the neutral; contractions on the quantiser's grid).
    identity_mm : (V, 3) the person's neutral minus the face's (head frame, mm), on a grid
        of ``identity_step_mm``.
    identity_step_mm : that grid's step.
    background : :data:`BACKGROUNDS`' key.
    image_codec : "webp", "avif" or "jpeg".
    image : the calibration picture, encoded.
    version : the stream's format version (the writer's: :data:`VERSION`).
    """

    width: int
    height: int
    fps: float
    n_frames_hint: int
    quality: str
    steps: Steps
    segment_frames: int
    camera: PinholeCamera
    face: str
    ids_crc: int
    n_contractions: int
    calibration_index: int
    calibration: FrameParams
    identity_mm: np.ndarray
    identity_step_mm: float
    background: int
    image_codec: str
    image: bytes
    version: int = VERSION

    @property
    def packet_model(self) -> int:
        """The packets' adaptive models (:class:`~myoface.codec.entropy.ParamCoder`'s
        ``model``): 2 for versions 1 and 2, 3 from version 3."""
        return 3 if self.version >= 3 else 2

    @property
    def n_appearance(self) -> int:
        """The appearance terms a packet carries (version 1: none)."""
        return N_APPEARANCE if self.version >= 2 else 0

    # -------------------------------------------------------------- writing

    def to_bytes(self) -> bytes:
        """The header as the stream carries it (magic, version, length, payload, CRC-32)."""
        st = self.steps
        q_names = {v: k for k, v in QUALITY_NAMES.items()}
        cal = self.calibration
        c_q = np.round(np.clip(cal.contractions, 0, 1) / st.contraction).astype("<u2")
        ident = np.round(self.identity_mm / self.identity_step_mm)
        ident = np.clip(ident, -32767, 32767).astype(np.int64)
        packed = _pack_identity(ident, self.face)
        out = io.BytesIO()
        w = out.write
        w(struct.pack("<HHfIB", self.width, self.height, self.fps, self.n_frames_hint,
                      q_names.get(self.quality, 255)))  # fmt: skip
        w(struct.pack("<4f", *st.as_tuple()))
        w(struct.pack("<H", self.segment_frames))
        cam = self.camera
        w(struct.pack("<3f", cam.focal_px, cam.cx, cam.cy))
        face_ids = {v: k for k, v in FACES.items()}
        w(struct.pack("<BBI", face_ids[self.face], self.n_contractions, self.ids_crc))
        w(struct.pack("<I", self.calibration_index))
        w(struct.pack("<3f", *rotvec(cal.rotation)))
        w(struct.pack("<3f", *cal.translation))
        w(struct.pack("<4f", *cal.gaze))
        w(c_q.tobytes())
        w(struct.pack("<HfI", len(ident), self.identity_step_mm, len(packed)))
        w(packed)
        w(struct.pack("<B", self.background))
        w(struct.pack("<BI", IMAGE_CODEC_IDS[self.image_codec], len(self.image)))
        w(self.image)
        payload = out.getvalue()
        return (
            MAGIC + struct.pack("<BI", self.version, len(payload)) + payload
            + struct.pack("<I", zlib.crc32(payload))
        )  # fmt: skip

    # -------------------------------------------------------------- reading

    @classmethod
    def parse(cls, payload: bytes) -> Header:
        """The header of ``payload`` (after its length, before its CRC); a clear error on
        any field out of its bounds."""
        r = _Fields(payload)
        width, height, fps, n_hint, q = r.unpack("<HHfIB")
        if not (16 <= width <= MAX_WIDTH and 16 <= height <= MAX_HEIGHT):
            raise MyofaceFormatError(f"corrupted header: frame size {width}x{height}")
        if width * height > MAX_PIXELS:
            raise MyofaceFormatError(f"the stream's frames ({width}x{height}) are too large")
        if not (np.isfinite(fps) and 0 < fps <= 240):
            raise MyofaceFormatError(f"corrupted header: {fps} frames/s")
        if q not in QUALITY_NAMES:
            raise MyofaceFormatError(f"corrupted header: quality {q}")
        steps = Steps(*(float(v) for v in r.unpack("<4f")))
        steps.check()
        (seg,) = r.unpack("<H")
        if not 1 <= seg <= MAX_SEGMENT_FRAMES:
            raise MyofaceFormatError(f"corrupted header: {seg} frames per segment")
        focal, cx, cy = r.unpack("<3f")
        if not (np.isfinite([focal, cx, cy]).all() and focal > 0):
            raise MyofaceFormatError("corrupted header: the camera")
        camera = PinholeCamera(float(focal), float(cx), float(cy))
        face, m, ids_crc = r.unpack("<BBI")
        if face not in FACES:
            raise MyofaceFormatError(f"the stream's face ({face}) is not one this myoface has")
        if not 1 <= m <= MAX_CONTRACTIONS:
            raise MyofaceFormatError(f"corrupted header: {m} contractions")
        (cal_index,) = r.unpack("<I")
        rv = np.array(r.unpack("<3f"), dtype=np.float64)
        tr = np.array(r.unpack("<3f"), dtype=np.float64)
        gz = np.array(r.unpack("<4f"), dtype=np.float64)
        if not (np.isfinite(rv).all() and np.isfinite(tr).all()) or np.linalg.norm(rv) > 4:
            raise MyofaceFormatError("corrupted header: the calibration pose")
        if np.any(np.abs(tr) > 3000) or np.any(np.abs(gz[np.isfinite(gz)]) > np.pi / 2):
            raise MyofaceFormatError("corrupted header: the calibration pose")
        c_q = np.frombuffer(r.take(2 * m), dtype="<u2").astype(np.float64)
        if np.any(c_q * steps.contraction > 1 + steps.contraction):
            raise MyofaceFormatError("corrupted header: the calibration's contractions")
        cal = FrameParams(rotmat(rv), tr, np.minimum(c_q * steps.contraction, 1.0), gz)
        n_v, id_step, n_packed = r.unpack("<HfI")
        if not (1 <= n_v <= MAX_VERTICES and n_packed <= MAX_IDENTITY_BYTES):
            raise MyofaceFormatError("corrupted header: the identity's size")
        if not (np.isfinite(id_step) and 1e-4 <= id_step <= 10):
            raise MyofaceFormatError("corrupted header: the identity's step")
        ident = _unpack_identity(r.take(n_packed), n_v, FACES[face]) * float(id_step)
        (bg,) = r.unpack("<B")
        if bg not in BACKGROUNDS:
            raise MyofaceFormatError(f"corrupted header: background {bg}")
        codec, n_img = r.unpack("<BI")
        if codec not in IMAGE_CODECS:
            raise MyofaceFormatError(f"corrupted header: image codec {codec}")
        if n_img > MAX_IMAGE_BYTES:
            raise MyofaceFormatError(f"corrupted header: a {n_img}-byte picture")
        image = r.take(n_img)
        if r.left:
            raise MyofaceFormatError(f"corrupted header: {r.left} bytes after its fields")
        return cls(
            int(width), int(height), float(fps), int(n_hint), QUALITY_NAMES[q], steps, int(seg),
            camera, FACES[face], int(ids_crc), int(m), int(cal_index), cal, ident,
            float(id_step), int(bg), IMAGE_CODECS[codec], bytes(image),
        )  # fmt: skip

    def picture(self) -> np.ndarray:
        """The calibration picture (H, W, 3) uint8, decoded once its own size is known to be
        the header's."""
        return decode_image(self.image, self.image_codec, (self.width, self.height))


_TOPOLOGY: dict = {}


def _topology(face: str):
    """The identity's coding order over ``face``'s mesh (:func:`identity_order`), cached."""
    if face not in _TOPOLOGY:
        from myoface.face import load_default_face

        mesh = load_default_face()
        _TOPOLOGY[face] = (mesh.n_vertices, *identity_order(mesh.triangles, mesh.n_vertices))
    return _TOPOLOGY[face]


def _pack_identity(q: np.ndarray, face: str) -> bytes:
    n, order, before = _topology(face)
    if q.shape != (n, 3):
        raise MyofaceFormatError(f"the identity has {len(q)} vertices; the {face} face {n}")
    io_ = RangeIO()
    code_identity(io_, order, before, q)
    return io_.encoder.get_compressed().astype("<u4").tobytes()


def _unpack_identity(data: bytes, n_v: int, face: str) -> np.ndarray:
    """The identity's integers (V, 3) from its range-coded words; a clear error unless they
    are exactly what coding them again gives."""
    n, order, before = _topology(face)
    if n_v != n:
        raise MyofaceFormatError(f"corrupted header: an identity of {n_v} vertices ({face}: {n})")
    if len(data) % 4 or not data:
        raise MyofaceFormatError("corrupted header: the identity's data")
    import constriction

    words = np.frombuffer(data, dtype="<u4").astype(np.uint32)
    io_ = RangeIO(constriction.stream.queue.RangeDecoder(words.copy()))
    try:
        q = code_identity(io_, order, before)
    except (MyofaceFormatError, *_decode_errors()):
        raise MyofaceFormatError("corrupted header: the identity's data") from None
    if not np.array_equal(io_.encoder.get_compressed(), words):
        raise MyofaceFormatError("corrupted header: the identity's data")
    return q.astype(np.float64)


class _Fields:
    """Reads a payload's fields in order; running out is a clear error."""

    def __init__(self, data: bytes):
        self.data = memoryview(data)
        self.at = 0

    @property
    def left(self) -> int:
        return len(self.data) - self.at

    def take(self, n: int) -> bytes:
        if n > self.left:
            raise MyofaceFormatError("corrupted header: it ends inside a field")
        out = bytes(self.data[self.at : self.at + n])
        self.at += n
        return out

    def unpack(self, fmt: str) -> tuple:
        return struct.unpack(fmt, self.take(struct.calcsize(fmt)))


def encode_image(rgb: np.ndarray, codec: str, quality: int) -> bytes:
    """``rgb`` (H, W, 3) uint8 as a ``codec`` image (Pillow) at ``quality`` (0-100)."""
    from PIL import Image

    img = Image.fromarray(np.ascontiguousarray(rgb, dtype=np.uint8), "RGB")
    buf = io.BytesIO()
    if codec == "webp":
        img.save(buf, "WEBP", quality=int(quality), method=6)
    elif codec == "avif":
        img.save(buf, "AVIF", quality=int(quality), speed=4)
    elif codec == "jpeg":
        img.save(buf, "JPEG", quality=int(quality), optimize=True, subsampling=2)
    else:
        raise MyofaceFormatError(f"unknown image codec {codec!r}")
    return buf.getvalue()


def image_codecs() -> list[str]:
    """The picture codecs this Pillow writes and reads."""
    from PIL import features

    return [c for c in ("webp", "avif", "jpeg") if features.check(c if c != "jpeg" else "jpg")]


def decode_image(data: bytes, codec: str, size: tuple[int, int]) -> np.ndarray:
    """The picture ``data`` (a ``codec`` image of ``size`` (width, height)) as (H, W, 3)
    uint8; its size is read from its own header and checked before its pixels are decoded."""
    from PIL import Image, UnidentifiedImageError

    if codec not in image_codecs():
        raise MyofaceFormatError(
            f"the stream's picture is {codec.upper()}, which this Pillow cannot read "
            "(pip install -U pillow)"
        )
    fmt = {"webp": "WEBP", "avif": "AVIF", "jpeg": "JPEG"}[codec]
    try:
        img = Image.open(io.BytesIO(data), formats=[fmt])
        if img.size != tuple(size):
            raise MyofaceFormatError(
                f"corrupted header: the picture is {img.size[0]}x{img.size[1]}, the stream's "
                f"frames {size[0]}x{size[1]}"
            )
        img.load()
        rgb = np.asarray(img.convert("RGB"))
    except MyofaceFormatError:
        raise
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError, EOFError) as exc:
        raise MyofaceFormatError(f"corrupted header: the picture ({type(exc).__name__})") from None
    if rgb.shape != (size[1], size[0], 3):
        raise MyofaceFormatError("corrupted header: the picture's size")
    return rgb


# ------------------------------------------------------------------ writing


class StreamWriter:
    """Writes a stream to the binary file object ``fh`` (flushed after every frame).

    ``header`` is written at once; :meth:`write` codes a frame and returns what the decoder
    will decode from it; :meth:`close` writes the end marker and the trailer."""

    def __init__(self, fh, header: Header):
        self.fh = fh
        raw = header.to_bytes()
        # both sides start from the header as the stream carries it (its float32 fields)
        self.header = parse_header_bytes(raw)
        self.header_bytes = len(raw)
        self.coder = coder_of(self.header)
        self.n_frames = 0
        self.body_bytes = 0
        self._crc = 0
        self._new_segment()
        self._out(raw, body=False)

    def _new_segment(self) -> None:
        self.io = RangeIO()
        self._seg_frames = 0
        self._written: list[np.ndarray] = []
        self._n_written = 0
        #: the most words a frame of the segment needs (the reader's margin: one word past
        #: those the range coder has produced)
        self._max_need = 0

    def _out(self, data: bytes, body: bool = True) -> None:
        self.fh.write(data)
        if body:
            self.body_bytes += len(data)
            self._crc = zlib.crc32(data, self._crc)

    def _emit_settled(self) -> None:
        """Write the words the range coder can no longer change: all it has produced, unless
        its interval straddles a carry (then none more until it does not)."""
        pos, (lower, rng) = self.io.encoder.pos()
        if lower + rng > 1 << 64 or pos <= self._n_written:
            return
        words = self.io.encoder.get_compressed()
        new = words[self._n_written : pos].astype("<u4")
        self._written.append(new)
        self._n_written = pos
        self._out(new.tobytes())

    def _seal(self) -> None:
        """End the segment: filler (so that every frame's words lie inside the segment),
        its check, then the range coder's seal."""
        for n_pad in range(PAD_CHOICES):
            trial = RangeIO(encoder=self.io.encoder.clone(), crc=self.io.crc)
            trial.categorical(np.ones((1, PAD_CHOICES)), [n_pad])
            trial.uniform(n_pad, np.zeros(n_pad, dtype=np.int32))
            trial.uniform(1, [trial.check_value()])
            words = trial.encoder.get_compressed().astype("<u4")
            if len(words) >= self._max_need:
                break
        else:  # (never seen: a word of filler is 32 bits, a frame's margin one word)
            raise RuntimeError("a segment's filler did not reach its frames' words")
        if self._written:
            sent = np.concatenate(self._written)
            if not np.array_equal(words[: len(sent)], sent):  # (never seen; see _emit_settled)
                raise RuntimeError("the range coder changed words already written")
        self._out(words[self._n_written :].tobytes())
        self._new_segment()

    def write(self, params: FrameParams, appearance_of=None) -> FrameParams:
        """Code one frame; returns the parameters the decoder will decode. ``appearance_of``:
        the encoder's fit of the frame's appearance terms
        (:meth:`~myoface.codec.entropy.ParamCoder.encode_frame`); None: ``params``' own."""
        out = self.coder.encode_frame(self.io, params, appearance_of)
        self._max_need = max(self._max_need, self.io.encoder.num_words() + 1)
        self.n_frames += 1
        self._seg_frames += 1
        if self._seg_frames >= self.header.segment_frames:
            self._seal()
        else:
            self._emit_settled()
        self.fh.flush()
        return out

    def close(self) -> None:
        """The end marker, the last segment's check and seal, and the trailer."""
        self.coder.encode_end(self.io)
        self._seal()
        self.fh.write(TRAILER_MAGIC + struct.pack("<II", self.n_frames, self._crc))
        self.fh.flush()

    @property
    def bits_per_frame(self) -> float:
        """The body's bits per frame so far (the segments' checks and seals included)."""
        return 8.0 * self.body_bytes / max(1, self.n_frames)


def parse_header_bytes(raw: bytes) -> Header:
    """The header of a stream's first bytes ``raw`` (exactly the header)."""
    src = BytesSource(raw)
    return read_header(_Buffer(src))


# ------------------------------------------------------------------ sources


class ByteSource:
    """Where a stream's bytes come from: :meth:`read` gives the bytes available (at most
    ``n``), waiting as the source's kind says; ``b""`` means there will be no more."""

    name = "stream"

    def read(self, n: int) -> bytes:  # pragma: no cover (the interface)
        raise NotImplementedError

    def close(self) -> None:
        pass


class BytesSource(ByteSource):
    def __init__(self, data: bytes, name: str = "stream"):
        self.data = memoryview(bytes(data))
        self.at = 0
        self.name = name

    def read(self, n: int) -> bytes:
        out = bytes(self.data[self.at : self.at + n])
        self.at += len(out)
        return out


class FileSource(ByteSource):
    """A file; with ``follow``, a file still being written: at its end, wait for it to grow
    (polling every :data:`POLL_S`) until it has not grown for ``timeout_s`` seconds."""

    POLL_S = 0.02

    def __init__(self, path, follow: bool = False, timeout_s: float = 10.0):
        self.name = str(path)
        self.fh = open(path, "rb")  # noqa: SIM115 (closed by close())
        self.follow = bool(follow)
        self.timeout_s = float(timeout_s)

    def read(self, n: int) -> bytes:
        data = self.fh.read(n)
        if data or not self.follow:
            return data
        t0 = time.monotonic()
        while time.monotonic() - t0 < self.timeout_s:
            time.sleep(self.POLL_S)
            data = self.fh.read(n)
            if data:
                return data
        return b""

    def close(self) -> None:
        self.fh.close()


class PipeSource(ByteSource):
    """A pipe (standard input): each read waits for what the writer sends."""

    def __init__(self, fd: int | None = None, name: str = "<stdin>"):
        self.fd = sys.stdin.fileno() if fd is None else fd
        self.name = name

    def read(self, n: int) -> bytes:
        return os.read(self.fd, n)


class _Buffer:
    """The bytes read from a source and not yet consumed."""

    def __init__(self, source: ByteSource):
        self.source = source
        self.buf = bytearray()
        self.ended = False

    def more(self, want: int = 1 << 16) -> bool:
        """Read what the source gives (waiting as it waits); False once it has ended."""
        if self.ended:
            return False
        data = self.source.read(want)
        if not data:
            self.ended = True
            return False
        self.buf += data
        return True

    def need(self, n: int) -> bool:
        """Whether ``n`` bytes are (or become) available."""
        while len(self.buf) < n:
            if not self.more(max(n - len(self.buf), 1 << 12)):
                return False
        return True

    def take(self, n: int) -> bytes:
        out = bytes(self.buf[:n])
        del self.buf[:n]
        return out


def read_header(b: _Buffer) -> Header:
    name = b.source.name
    if not b.need(9):
        if not b.buf:
            raise MyofaceFormatError(f"{name}: empty stream")
        raise StreamTruncated(f"{name}: truncated stream: it ends inside the header", 0)
    head = b.take(9)
    if head[:4] != MAGIC:
        raise MyofaceFormatError(f"{name}: not a myoface stream (no {MAGIC.decode()} magic)")
    version, n = struct.unpack("<BI", head[4:])
    if version not in VERSIONS_READ:
        raise MyofaceFormatError(
            f"{name}: stream format version {version}; this myoface reads versions "
            + ", ".join(str(v) for v in VERSIONS_READ[:-1])
            + f" and {VERSIONS_READ[-1]}"
            + (" (upgrade myoface)" if version > VERSION else "")
        )
    if n > MAX_HEADER_BYTES:
        raise MyofaceFormatError(f"{name}: corrupted header: {n} bytes long")
    if not b.need(n + 4):
        raise StreamTruncated(f"{name}: truncated stream: it ends inside the header", 0)
    payload = b.take(n)
    (crc,) = struct.unpack("<I", b.take(4))
    if zlib.crc32(payload) != crc:
        raise MyofaceFormatError(f"{name}: corrupted header (its checksum fails)")
    try:
        h = Header.parse(payload)
        h.version = int(version)
        return h
    except MyofaceFormatError as exc:
        raise MyofaceFormatError(f"{name}: {exc}") from None


# ------------------------------------------------------------------ reading


def _decode_errors():
    """What the range decoder may raise on data that are not a stream (constriction raises
    AssertionError or ValueError; a Rust panic is pyo3's PanicException, a BaseException)."""
    out = [ValueError, AssertionError, RuntimeError, OverflowError, IndexError, TypeError]
    try:
        from pyo3_runtime import PanicException  # type: ignore[import-not-found]

        out.append(PanicException)
    except ImportError:
        pass
    return tuple(out)


class StreamReader:
    """Reads a stream from ``source``: :attr:`header` at once, then iterate for each frame's
    :class:`~myoface.codec.params.FrameParams`, each as soon as the words it needs are
    there (a live stream: usually one frame behind the writer; see docs/codec-format.md).
    Ends at the end marker, after checking the trailer."""

    def __init__(self, source: ByteSource):
        import constriction

        self._q = constriction.stream.queue
        self.source = source
        self.name = source.name
        self._b = _Buffer(source)
        self.header = read_header(self._b)
        h = self.header
        self.coder = coder_of(h)
        self.n_frames = 0
        self.ended = False
        self._crc = 0
        self._errors = _decode_errors()

    def _truncated(self, where: str) -> StreamTruncated:
        return StreamTruncated(
            f"{self.name}: truncated stream: it ends {where} after {self.n_frames} frames "
            "(no end marker)",
            self.n_frames,
        )

    def _corrupted(self, what: str) -> MyofaceFormatError:
        return MyofaceFormatError(
            f"{self.name}: corrupted stream: {what} (after {self.n_frames} frames)"
        )

    def _words(self, n_words: int) -> np.ndarray:
        """The segment's first words available (at most ``n_words``)."""
        n = min(len(self._b.buf) // 4, n_words)
        return np.frombuffer(bytes(self._b.buf[: 4 * n]), dtype="<u4").astype(np.uint32)

    def _attempt(self, words, base, since: int, in_seg: int):
        """Decode the next frame from the segment's ``words``: from the checkpoint ``base``
        (the mirror, the check's CRC and the coder's state at a frame's start), the ``since``
        frames decoded after it again, then the next one. Returns ``(valid, need, frame,
        check_ok, end_of_segment, io)``: ``valid`` when the words decode to it (else more
        words are needed, or the words are not a stream), ``need`` the words it takes (None:
        not known), ``frame`` None at the end marker."""
        mirror, crc, snap = base
        self.coder.restore(snap)
        pos, state = mirror.pos()
        data = words[pos:].copy()
        io_ = RangeIO(self._q.RangeDecoder(data), mirror.clone(), crc)
        try:
            io_.decoder.seek(0, state)
            for _ in range(since):
                self.coder.decode_frame(io_)
            out = self.coder.decode_frame(io_)
            end_seg = out is None or in_seg + 1 >= self.header.segment_frames
            ok = True
            if end_seg:
                n_pad = int(io_.categorical(np.ones((1, PAD_CHOICES)))[0])
                io_.uniform(n_pad)
                want = io_.check_value()
                ok = int(io_.uniform(1)[0]) == want
        except (MyofaceFormatError, *self._errors):
            return False, None, None, False, False, io_
        # the frame is what the words say only if the mirror, coding what was decoded, wrote
        # the same words (a decoder that ran past the words available decodes something)
        comp = io_.encoder.get_compressed()
        if end_seg:
            need = len(comp)  # (the sealed segment: exactly its words)
            same = need <= len(words) and np.array_equal(comp, words[:need])
        else:
            p, (lower, rng) = io_.encoder.pos()
            settled = p if lower + rng <= 1 << 64 else max(0, p - 2)
            need = io_.encoder.num_words() + 1
            same = need <= len(words) and np.array_equal(comp[:settled], words[:settled])
        return same, need, out, ok, end_seg, io_

    def __iter__(self):
        h = self.header
        max_words = MAX_SEGMENT_WORDS_PER_FRAME * (h.segment_frames + 1)
        while not self.ended:
            # the checkpoint frames are decoded from: a frame's start where the range coder's
            # interval does not straddle a carry (a decoder cannot start inside one)
            base = (self._q.RangeEncoder(), 0, self.coder.snapshot())
            since = 0
            in_seg = 0
            while True:
                while True:
                    avail = min(len(self._b.buf) // 4, max_words)
                    words = self._words(avail)
                    valid, need, out, ok, end_seg, io_ = self._attempt(words, base, since, in_seg)
                    if valid:
                        break
                    if avail >= max_words:
                        raise self._corrupted("a segment longer than its frames allow")
                    if not self._b.more(1 << 12):
                        if self._ends_in_trailer():
                            raise self._corrupted("undecodable data")
                        raise self._truncated("inside a packet")
                if not ok:
                    raise self._corrupted("a segment's check fails")
                lower, rng = io_.encoder.pos()[1]
                if lower + rng <= 1 << 64:
                    base, since = (io_.encoder, io_.crc, self.coder.snapshot()), 0
                else:
                    since += 1
                if out is None:
                    self._consume(need)
                    self._read_trailer()
                    self.ended = True
                    return
                in_seg += 1
                self.n_frames += 1
                if end_seg:
                    self._consume(need)
                yield out
                if end_seg:
                    break

    def _consume(self, n_words: int) -> None:
        data = self._b.take(4 * n_words)
        self._crc = zlib.crc32(data, self._crc)

    def _ends_in_trailer(self) -> bool:
        """Whether what was read ends in what looks like a trailer (a stream that has its
        end but cannot be decoded is corrupted, not truncated)."""
        tail = bytes(self._b.buf[-12:])
        return len(tail) == 12 and tail[:4] == TRAILER_MAGIC

    def _read_trailer(self) -> None:
        if not self._b.need(12):
            raise self._truncated("in its trailer")
        t = self._b.take(12)
        if t[:4] != TRAILER_MAGIC:
            raise self._corrupted("no trailer after the end marker")
        n, crc = struct.unpack("<II", t[4:])
        if n != self.n_frames:
            raise self._corrupted(f"the trailer says {n} frames, the stream has {self.n_frames}")
        if crc != self._crc:
            raise self._corrupted("the body's checksum fails")

    def close(self) -> None:
        self.source.close()
