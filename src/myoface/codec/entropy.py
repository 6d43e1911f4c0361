"""The packets' quantiser, prediction and adaptive entropy coding (docs/codec-format.md).

A frame's parameters (:class:`~myoface.codec.params.FrameParams`) become integers on a uniform
grid of the header's steps (:class:`Steps`): the head's rotation as a rotation vector (rad),
its translation (mm), every contraction, and each eye's gaze (rad). Each integer is predicted
by the same channel's value in the previous frame (the last frame measured; for an eye, the
last frame it was read), and the residual is coded with an adaptive categorical model:
one table of counts per channel and context (the context: the channel's previous residual,
0, +-1 or more), updated after each symbol on both sides (so the model needs no side
information), coded by `constriction <https://bamler-lab.github.io/constriction/>`_'s range
coder (:class:`RangeIO`). Residuals beyond +-:data:`RESIDUAL_RANGE` are coded as an escape
symbol and 16 uniform bits.

The encoder's quantiser holds a channel's value while the parameter stays within
:data:`HOLD` steps of it (hysteresis): the fit's jitter then costs no bits; every decoded
value is within one step of the encoder's input (:meth:`ParamCoder.quantise`).

The same code decodes: :class:`ParamCoder` codes a frame through a :class:`RangeIO`, which
either encodes the symbols given or decodes them (and re-encodes them into a mirror of the
encoder, whose position tells the stream reader how many words the frame needed).
"""

from __future__ import annotations

import zlib
from dataclasses import dataclass

import numpy as np

from myoface.analysis.camera import rotmat, rotvec
from myoface.codec.params import APPEARANCE_LIMITS, APPEARANCE_STEPS, N_APPEARANCE, FrameParams
from myoface.errors import MyofaceFormatError

#: residuals coded directly (beyond: an escape and 16 bits)
RESIDUAL_RANGE = 12
#: the residual alphabet: escape-negative, -R..R, escape-positive
ALPHABET = 2 * RESIDUAL_RANGE + 3
ESC_NEG, ESC_POS = 0, ALPHABET - 1
#: an escape's payload: |residual| - R - 1 in [0, 2**16)
ESCAPE_BITS = 16
#: the adaptive tables: each use adds this to the symbol's count; a table whose total passes
#: :data:`COUNT_LIMIT` is halved (older statistics fade)
COUNT_STEP = 32
COUNT_LIMIT = 1 << 13
#: contexts per channel: the channel's previous residual 0, +-1, or larger
N_CONTEXTS = 3
#: format version 3's models (:class:`ParamCoder` with ``model=3``): each channel's tables
#: start nearly flat (:func:`_prior` at this scale and decay) and are blended with its
#: group's shared table (the rotation, the translation, the contractions, the appearance, the
#: gaze), weighted :data:`GROUP_WEIGHT` against the channel's own counts: a channel's first
#: symbols are coded with what its group has learnt, its later ones with its own statistics
#: (measured on the sample and the head-motion clips: 17-20 % and 6 % fewer bits than
#: version 2's models, identical values)
V3_PRIOR = (4, 0.3)
V3_GROUP_PRIOR = (64, 0.3)
GROUP_WEIGHT = 256
#: version 3's contexts: the channel's previous residual (-2..2, signed) ...
N_CONTEXTS_V3 = 5
#: ... and the sign of the residual just coded in the frame, when that was the same group's
#: (-, 0, +: a muscle's right side after its left, the head's rotation's axes together)
N_NEIGHBOUR = 3
#: the groups' channels: 0 rotation, 1 translation, 2 contractions, 3 appearance, 4 gaze
N_GROUPS = 5
#: the quantiser holds a value while the input stays within this many steps of it
HOLD = 0.75
#: the quantised values' bound (so that a residual's escape fits ESCAPE_BITS)
Q_LIMIT = 32000
#: the binary models: kind (frame / end), measured, left eye read, right eye read
BIN_KIND, BIN_MEASURED, BIN_EYE_L, BIN_EYE_R = range(4)
N_BINARY = 4
KIND_FRAME, KIND_END = 0, 1


@dataclass(frozen=True)
class Steps:
    """The quantiser's steps: rotation (rad, of the rotation vector), translation (mm),
    contractions (in [0, 1]) and gaze (rad)."""

    rotation_rad: float
    translation_mm: float
    contraction: float
    gaze_rad: float

    def as_tuple(self) -> tuple[float, float, float, float]:
        return (self.rotation_rad, self.translation_mm, self.contraction, self.gaze_rad)

    def check(self) -> None:
        """A clear error unless every step is finite, positive and its channel's range fits
        :data:`Q_LIMIT` steps."""
        lims = (np.pi, 3000.0, 1.0, np.pi / 2)
        for name, s, lim in zip(
            ("rotation", "translation", "contraction", "gaze"), self.as_tuple(), lims, strict=True
        ):
            if not (np.isfinite(s) and s > 0 and lim / s <= Q_LIMIT):
                raise MyofaceFormatError(
                    f"the {name} step must be in [{lim / Q_LIMIT:g}, ...); got {s}"
                )


#: the quality settings (``myoface encode --quality``): the steps and the calibration
#: picture's target PSNR-Y (dB) the image codec's quality is searched for.
#:
#: Measured (format version 3, ``myoface bench --only codec``'s clips: the sample looped to
#: 600 frames, the head-motion renders' 90; total bytes, face PSNR-Y, face SSIM):
#:
#: ======  =========================  ====  ======================  ======================
#: name    steps (rad, mm, -, rad)    dB    sample                  head motion
#: ======  =========================  ====  ======================  ======================
#: low     0.004, 1, 0.1, 0.08        33    4,092 B 26.11 0.774     3,694 B 23.55 0.745
#: medium  0.004, 1, 0.1, 0.08        36    4,457 B 26.23 0.788     3,972 B 23.57 0.747
#: high    0.002, 0.5, 0.025, 0.02    39    7,687 B 26.32 0.803     6,150 B 23.61 0.753
#: max     0.001, 0.25, 0.0125, 0.01  42    11,981 B 26.37 0.811    12,655 B 23.57 0.753
#: ======  =========================  ====  ======================  ======================
#:
#: The face's PSNR-Y is held by the model (the analysis, the picture's warp and appearance
#: terms), not by these steps: halving every step from medium's buys <= 0.1 dB on either
#: clip; the head's rotation step matters most (0.008 rad: -0.45 dB on the sample), the
#: contractions' least (0.025 -> 0.1: 0.00 dB on the sample, -0.09 on the head motion, and
#: the decoded fidelity measure 0.563 -> 0.576, unchanged). Above medium the bytes buy the
#: picture's texture (face SSIM, frame SSIM), below it the picture is AVIF's smallest.
#: The default is the knee by this rule: the cheapest setting whose face PSNR-Y is within
#: 0.2 dB of the best setting's on every bench clip (low: 0.27 dB below max on the sample).
QUALITIES = {
    "low": (Steps(0.004, 1.0, 0.1, 0.08), 33.0),
    "medium": (Steps(0.004, 1.0, 0.1, 0.08), 36.0),
    "high": (Steps(0.002, 0.5, 0.025, 0.02), 39.0),
    "max": (Steps(0.001, 0.25, 0.0125, 0.01), 42.0),
}
DEFAULT_QUALITY = "medium"


def _family():
    import constriction

    return constriction.stream.model.Categorical(perfect=False)


class RangeIO:
    """One segment's range coder: :meth:`categorical` encodes the symbols given, or, with a
    ``decoder``, decodes them and encodes them again into :attr:`encoder` (the encoder's
    mirror: its position is the encoder's)."""

    def __init__(self, decoder=None, encoder=None, crc: int = 0):
        import constriction

        q = constriction.stream.queue
        self.encoder = encoder if encoder is not None else q.RangeEncoder()
        self.decoder = decoder
        self._cat = _family()
        self._uniform = constriction.stream.model.Uniform(1 << ESCAPE_BITS)
        #: a CRC-32 of every symbol coded in the segment (its check, :meth:`check_value`)
        self.crc = int(crc)

    def categorical(self, probs: np.ndarray, symbols=None) -> np.ndarray:
        """Code ``len(probs)`` symbols, symbol k under the counts ``probs[k]``."""
        probs = np.ascontiguousarray(probs, dtype=np.float64)
        if len(probs) == 0:
            return np.zeros(0, dtype=np.int32)
        if self.decoder is not None:
            symbols = np.asarray(self.decoder.decode(self._cat, probs), dtype=np.int32)
        symbols = np.ascontiguousarray(symbols, dtype=np.int32)
        self.encoder.encode(symbols, self._cat, probs)
        self.crc = zlib.crc32(symbols.astype("<i4").tobytes(), self.crc)
        return symbols

    def uniform(self, n: int, symbols=None) -> np.ndarray:
        """Code ``n`` symbols of :data:`ESCAPE_BITS` uniform bits."""
        if n == 0:
            return np.zeros(0, dtype=np.int32)
        if self.decoder is not None:
            symbols = np.asarray(self.decoder.decode(self._uniform, n), dtype=np.int32)
        symbols = np.ascontiguousarray(symbols, dtype=np.int32).reshape(n)
        self.encoder.encode(symbols, self._uniform)
        self.crc = zlib.crc32(symbols.astype("<i4").tobytes(), self.crc)
        return symbols

    def check_value(self) -> int:
        """A 16-bit check of every symbol coded so far in the segment."""
        return self.crc & 0xFFFF


def _prior(scale: float = 256, decay: float = 0.5) -> np.ndarray:
    r = np.abs(np.arange(ALPHABET) - (RESIDUAL_RANGE + 1))
    c = np.maximum(1, np.round(scale * decay**r)).astype(np.int64)
    c[[ESC_NEG, ESC_POS]] = 1
    return c


class ParamCoder:
    """The prediction and adaptive models of one stream (both sides keep one, in step).

    Channels: the rotation vector (3), the translation (3), the ``n_contractions``
    contractions, the ``n_appearance`` appearance terms (:data:`APPEARANCE_FIELDS
    <myoface.codec.params.APPEARANCE_FIELDS>`; format version 2: all of them, version 1:
    none), then the gaze (4: each eye's yaw and pitch). :meth:`encode_frame` codes a frame and
    returns what the decoder will decode; :meth:`decode_frame` decodes one (None at the end
    marker)."""

    def __init__(self, n_contractions: int, steps: Steps, calibration: FrameParams,
                 n_appearance: int = N_APPEARANCE, model: int = 3):  # fmt: skip
        steps.check()
        if model not in (2, 3):
            raise MyofaceFormatError(f"model must be 2 or 3; got {model}")
        #: the residuals' models: 2 (format versions 1 and 2), 3 (format version 3)
        self.model = int(model)
        if n_appearance not in (0, N_APPEARANCE):
            raise MyofaceFormatError(
                f"n_appearance must be 0 or {N_APPEARANCE}; got {n_appearance}"
            )
        self.m = int(n_contractions)
        self.n_app = int(n_appearance)
        self.steps = steps
        self.i_app = 6 + self.m
        self.n_main = self.i_app + self.n_app
        n = self.n_main + 4
        self.step = np.array(
            [steps.rotation_rad] * 3 + [steps.translation_mm] * 3 + [steps.contraction] * self.m
            + list(APPEARANCE_STEPS[: self.n_app]) + [steps.gaze_rad] * 4
        )  # fmt: skip
        lim = np.full(n, float(Q_LIMIT))
        lim[self.i_app : self.n_main] = np.round(
            np.asarray(APPEARANCE_LIMITS[: self.n_app]) / APPEARANCE_STEPS[: self.n_app]
        )
        #: each channel's bound on its integers
        self.q_limit = lim.astype(np.int64)
        if self.model == 2:
            self.counts = np.tile(_prior(), (n * N_CONTEXTS, 1))
        else:
            self.counts = np.tile(_prior(*V3_PRIOR), (n * N_CONTEXTS_V3 * N_NEIGHBOUR, 1))
            self.group_counts = np.tile(_prior(*V3_GROUP_PRIOR),
                                        (N_GROUPS * N_CONTEXTS_V3 * N_NEIGHBOUR, 1))  # fmt: skip
            g = np.zeros(n, np.int64)
            g[3:6], g[6 : self.i_app], g[self.i_app : self.n_main], g[self.n_main :] = 1, 2, 3, 4
            #: each channel's group
            self.group = g
        #: each channel's bits so far (the ideal code length of its symbols and escapes, on
        #: the encoding side; what a channel costs: the benchmark's breakdown)
        self.bits = np.zeros(n)
        self.bin_counts = np.full((N_BINARY, 2), 4, dtype=np.int64)
        self.bin_counts[BIN_KIND] = (256, 1)
        # the prediction: the last value of each channel (quantised), its last residual
        self.prev = self._q_of(calibration)
        self.prev[self.i_app : self.n_main] = 0  # (the calibration picture's own appearance)
        self.prev[self.n_main :] = np.where(
            np.isfinite(calibration.gaze), self.prev[self.n_main :], 0
        )
        self.ctx = np.zeros(n, dtype=np.int64)
        self.last = self.dequantise(self.prev, np.isfinite(calibration.gaze))

    # -------------------------------------------------------------- state

    def snapshot(self):
        group = self.group_counts.copy() if self.model == 3 else None
        return (self.counts.copy(), self.bin_counts.copy(), self.prev.copy(), self.ctx.copy(),
                self.last.copy(), group)  # fmt: skip

    def restore(self, snap) -> None:
        self.counts, self.bin_counts, self.prev, self.ctx, last = (a.copy() for a in snap[:5])
        self.last = last
        if self.model == 3:
            self.group_counts = snap[5].copy()

    # -------------------------------------------------------------- quantiser

    def _values(self, p: FrameParams) -> np.ndarray:
        g = np.nan_to_num(p.gaze, nan=0.0)
        app = np.nan_to_num(p.appearance[: self.n_app], nan=0.0)
        return np.concatenate([rotvec(p.rotation), p.translation, p.contractions, app, g])

    def _q_of(self, p: FrameParams) -> np.ndarray:
        if len(p.contractions) != self.m:
            raise MyofaceFormatError(
                f"a frame has {len(p.contractions)} contractions; the stream has {self.m}"
            )
        q = np.round(self._values(p) / self.step)
        return np.clip(q, -self.q_limit, self.q_limit).astype(np.int64)

    def quantise(self, p: FrameParams) -> np.ndarray:
        """``p``'s integers: each channel held at its last value while ``p`` stays within
        :data:`HOLD` steps of it, else rounded (every value within one step of ``p``'s;
        contractions clipped to [0, 1]; the appearance to its bounds)."""
        v = self._values(p)
        v[6 : self.i_app] = np.clip(v[6 : self.i_app], 0.0, 1.0)
        x = v / self.step
        q = np.where(np.abs(x - self.prev) <= HOLD, self.prev, np.round(x))
        return np.clip(q, -self.q_limit, self.q_limit).astype(np.int64)

    def dequantise(self, q: np.ndarray, read=(True, True)) -> FrameParams:
        v = q * self.step
        gaze = v[self.n_main :].copy()
        for k, ok in enumerate(read):
            if not ok:
                gaze[2 * k : 2 * k + 2] = np.nan
        c = np.clip(v[6 : self.i_app], 0.0, 1.0)  # (a step's multiple may round past 1)
        app = np.zeros(N_APPEARANCE)
        app[: self.n_app] = v[self.i_app : self.n_main]
        return FrameParams(rotmat(v[:3]), v[3:6], c, gaze, appearance=app)

    # -------------------------------------------------------------- coding

    def _binary(self, io: RangeIO, which, bits=None) -> np.ndarray:
        which = np.atleast_1d(which)
        out = io.categorical(self.bin_counts[which], bits)
        for w, b in zip(which, out, strict=True):
            self.bin_counts[w, b] += COUNT_STEP
            if self.bin_counts[w].sum() > COUNT_LIMIT:
                self.bin_counts[w] = (self.bin_counts[w] + 1) // 2
        return out

    def _residuals(self, io: RangeIO, chans: np.ndarray, q=None) -> np.ndarray:
        """Code channels ``chans``' values (``q``; None: decode) against their prediction."""
        if self.model == 3:
            return self._residuals_v3(io, chans, q)
        slots = chans * N_CONTEXTS + self.ctx[chans]
        syms = None
        pay = None
        if q is not None:
            r = q[chans] - self.prev[chans]
            syms = np.clip(r + RESIDUAL_RANGE + 1, ESC_NEG, ESC_POS)
            big = (syms == ESC_NEG) | (syms == ESC_POS)
            pay = np.abs(r[big]) - RESIDUAL_RANGE - 1
        syms = io.categorical(self.counts[slots], syms)
        big = (syms == ESC_NEG) | (syms == ESC_POS)
        pay = io.uniform(int(big.sum()), pay)
        r = syms.astype(np.int64) - RESIDUAL_RANGE - 1
        r[big] = np.where(syms[big] == ESC_POS, 1, -1) * (pay.astype(np.int64) + RESIDUAL_RANGE + 1)
        val = self.prev[chans] + r
        if np.any(np.abs(val) > self.q_limit[chans]):
            raise MyofaceFormatError("corrupted stream: a parameter beyond its range")
        # the models learn
        np.add.at(self.counts, (slots, syms), COUNT_STEP)
        full = self.counts[slots].sum(axis=1) > COUNT_LIMIT
        if full.any():
            s = np.unique(slots[full])
            self.counts[s] = (self.counts[s] + 1) // 2
        self.prev[chans] = val
        self.ctx[chans] = np.minimum(np.abs(r), N_CONTEXTS - 1)
        return val

    @staticmethod
    def _learn(table: np.ndarray, row: int, sym: int) -> None:
        table[row, sym] += COUNT_STEP
        if table[row].sum() > COUNT_LIMIT:
            table[row] = (table[row] + 1) // 2

    def _residuals_v3(self, io: RangeIO, chans: np.ndarray, q=None) -> np.ndarray:
        """Version 3: the channels one after another, each residual's symbol (and an escape's
        16 bits right after it) under its channel's table blended with its group's, in the
        contexts of its own previous residual and of the residual just coded (when that
        channel was of the same group)."""
        out = np.empty(len(chans), np.int64)
        neighbour, last_group = 0, -1
        for k, c in enumerate(np.asarray(chans, np.int64)):
            g = int(self.group[c])
            nb = neighbour if g == last_group else 0
            ctx = (int(self.ctx[c]) + 2) * N_NEIGHBOUR + nb + 1
            slot = int(c) * N_CONTEXTS_V3 * N_NEIGHBOUR + ctx
            gslot = g * N_CONTEXTS_V3 * N_NEIGHBOUR + ctx
            own, grp = self.counts[slot], self.group_counts[gslot]
            probs = own * int(grp.sum()) + GROUP_WEIGHT * grp  # (integers: exact anywhere)
            sym = pay = None
            if q is not None:
                r = int(q[c] - self.prev[c])
                sym = [min(max(r + RESIDUAL_RANGE + 1, ESC_NEG), ESC_POS)]
                pay = [abs(r) - RESIDUAL_RANGE - 1]
            s_ = int(io.categorical(probs[None, :], sym)[0])
            r = s_ - RESIDUAL_RANGE - 1
            if q is not None:
                self.bits[c] += float(np.log2(probs.sum() / probs[s_]))
            if s_ in (ESC_NEG, ESC_POS):
                u = int(io.uniform(1, pay)[0])
                r = (1 if s_ == ESC_POS else -1) * (u + RESIDUAL_RANGE + 1)
                self.bits[c] += ESCAPE_BITS
            val = int(self.prev[c]) + r
            if abs(val) > self.q_limit[c]:
                raise MyofaceFormatError("corrupted stream: a parameter beyond its range")
            self._learn(self.counts, slot, s_)
            self._learn(self.group_counts, gslot, s_)
            self.prev[c] = val
            self.ctx[c] = min(max(r, -2), 2)
            out[k] = val
            neighbour, last_group = (r > 0) - (r < 0), g
        return out

    def _code(self, io: RangeIO, kind=None, measured=False, q=None, read=None):
        """The frame's symbols in order (see docs/codec-format.md, "Packet"); ``kind`` None:
        decode them."""
        bits = None if kind is None else np.array([kind, int(bool(measured))])
        kind, measured = (int(b) for b in self._binary(io, [BIN_KIND, BIN_MEASURED], bits))
        if kind == KIND_END:
            return None
        if not measured:
            held = self.last.copy()
            held.measured = False
            return held
        main = np.arange(self.n_main)
        self._residuals(io, main, q)
        rbits = None if q is None else np.array([int(bool(r)) for r in read])  # (q: encoding)
        read = self._binary(io, [BIN_EYE_L, BIN_EYE_R], rbits).astype(bool)
        eyes = [self.n_main + 2 * k + j for k in (0, 1) if read[k] for j in (0, 1)]
        if eyes:
            self._residuals(io, np.array(eyes), q)
        self.last = self.dequantise(self.prev, read)
        return self.last.copy()

    def encode_frame(self, io: RangeIO, p: FrameParams, appearance_of=None) -> FrameParams:
        """Code frame ``p``; returns the decoder's :class:`FrameParams` (dequantised).

        ``appearance_of``: a function of the decoder's parameters of the frame without
        appearance (its head pose, contractions and gaze as quantised) that gives the frame's
        appearance terms (the encoder's fit on the picture those render); None: ``p``'s own.
        """
        if not p.measured:
            return self._code(io, KIND_FRAME, False, None)
        read = np.isfinite(p.gaze).reshape(2, 2).all(axis=1)
        if appearance_of is not None and self.n_app:
            base = self.dequantise(self.quantise(p), read)
            base.appearance[:] = 0.0
            p = p.copy()
            p.appearance = np.asarray(appearance_of(base), dtype=np.float64).reshape(N_APPEARANCE)
        q = self.quantise(p)
        q[self.n_main :] = np.where(np.repeat(read, 2), q[self.n_main :], 0)
        return self._code(io, KIND_FRAME, True, q, read)

    def channel_bits(self) -> dict:
        """The bits each group of channels has cost so far (format version 3's models; the
        encoding side): the head's rotation and translation, the contractions, the appearance
        terms, the gaze."""
        groups = {"rotation": slice(0, 3), "translation": slice(3, 6),
                  "contractions": slice(6, self.i_app), "appearance": slice(self.i_app, self.n_main),
                  "gaze": slice(self.n_main, None)}  # fmt: skip
        return {k: float(self.bits[v].sum()) for k, v in groups.items()}

    def encode_end(self, io: RangeIO) -> None:
        self._code(io, KIND_END)

    def decode_frame(self, io: RangeIO) -> FrameParams | None:
        return self._code(io)


# ------------------------------------------------------------------ the identity (header)


def identity_order(triangles: np.ndarray, n_vertices: int) -> tuple[np.ndarray, list]:
    """The order the identity's vertices are coded in and, for each, its neighbours coded
    before it: breadth first over the mesh from vertex 0 (neighbours by increasing index;
    a vertex on no triangle starts a new search)."""
    nbrs: list[set] = [set() for _ in range(n_vertices)]
    for a, b, c in np.asarray(triangles, dtype=np.int64):
        nbrs[a] |= {b, c}
        nbrs[b] |= {a, c}
        nbrs[c] |= {a, b}
    seen = np.zeros(n_vertices, bool)
    order: list[int] = []
    for root in range(n_vertices):
        if seen[root]:
            continue
        seen[root] = True
        queue = [root]
        while queue:
            v = queue.pop(0)
            order.append(v)
            for u in sorted(nbrs[v]):
                if not seen[u]:
                    seen[u] = True
                    queue.append(u)
    pos = np.empty(n_vertices, np.int64)
    pos[order] = np.arange(n_vertices)
    before = [np.array(sorted(u for u in nbrs[v] if pos[u] < pos[v]), np.int64) for v in order]
    return np.array(order, np.int64), before


def code_identity(io: RangeIO, order: np.ndarray, before: list, q=None) -> np.ndarray:
    """Code the identity's integers ``q`` (V, 3) (None: decode them): each vertex predicted
    by the rounded mean of its neighbours coded before it (0 for the first), its x, y, z
    residuals coded as the packets' are, with an adaptive table per axis and context."""
    n = len(order)
    counts = np.tile(_prior(), (3 * N_CONTEXTS, 1))
    ctx = np.zeros(3, np.int64)
    out = np.zeros((n, 3), np.int64)
    for v, nb in zip(order, before, strict=True):
        if len(nb):
            s = out[nb].sum(axis=0)
            pred = (2 * s + len(nb)) // (2 * len(nb))  # (integer rounding: the same anywhere)
        else:
            pred = np.zeros(3, np.int64)
        slots = np.arange(3) * N_CONTEXTS + ctx
        syms = pay = None
        if q is not None:
            r = np.asarray(q[v], np.int64) - pred
            syms = np.clip(r + RESIDUAL_RANGE + 1, ESC_NEG, ESC_POS)
            big = (syms == ESC_NEG) | (syms == ESC_POS)
            pay = np.abs(r[big]) - RESIDUAL_RANGE - 1
        syms = io.categorical(counts[slots], syms)
        big = (syms == ESC_NEG) | (syms == ESC_POS)
        pay = io.uniform(int(big.sum()), pay)
        r = syms.astype(np.int64) - RESIDUAL_RANGE - 1
        r[big] = np.where(syms[big] == ESC_POS, 1, -1) * (pay.astype(np.int64) + RESIDUAL_RANGE + 1)
        val = pred + r
        if np.any(np.abs(val) > 32767):
            raise MyofaceFormatError("corrupted header: the identity's data")
        out[v] = val
        counts[slots, syms] += COUNT_STEP
        full = counts[slots].sum(axis=1) > COUNT_LIMIT
        if full.any():
            counts[slots[full]] = (counts[slots[full]] + 1) // 2
        ctx = np.minimum(np.abs(r), N_CONTEXTS - 1)
    return out
