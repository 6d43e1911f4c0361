"""The stream reader fuzzed (hypothesis): whatever the bytes, it ends in the frames or a
MyofaceFormatError, never another exception, never a hang (each example has a deadline; the
reader reads from memory, so it never waits)."""

from __future__ import annotations

import functools

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from myoface.codec.stream import BytesSource, StreamReader
from myoface.errors import MyofaceFormatError
from tests.codec._streams import header, stream

FUZZ = settings(
    max_examples=120,
    deadline=3000,  # ms: a hang fails the example
    suppress_health_check=[HealthCheck.too_slow],
    derandomize=True,
)


@functools.cache
def _valid() -> tuple[bytes, int, tuple]:
    data, decoded, _ = stream(40, seed=7)
    return data, len(header().to_bytes()), tuple(decoded)


def _decode(data: bytes):
    """Every frame, or the MyofaceFormatError it ended in (anything else fails the test)."""
    out = []
    try:
        for p in StreamReader(BytesSource(data, name="fuzz")):
            out.append(p)
    except MyofaceFormatError as exc:
        assert "\n" not in str(exc)
        return out, exc
    return out, None


def _check_prefix(out):
    _, _, decoded = _valid()
    for a, b in zip(out, decoded, strict=False):
        if not (np.array_equal(a.contractions, b.contractions) and a.measured == b.measured):
            return False
    return True


@FUZZ
@given(st.binary(max_size=3000))
def test_arbitrary_bytes(data):
    _decode(data)


@FUZZ
@given(st.binary(max_size=400))
def test_a_valid_header_then_arbitrary_bytes(tail):
    data, hb, _ = _valid()
    out, err = _decode(data[:hb] + tail)
    assert err is not None or out == []  # (random bytes are not a stream's body)


@FUZZ
@given(st.data())
def test_a_valid_stream_with_bytes_changed(draw):
    data, hb, decoded = _valid()
    bad = bytearray(data)
    n = draw.draw(st.integers(1, 4))
    for _ in range(n):
        at = draw.draw(st.integers(0, len(bad) - 1))
        bad[at] = draw.draw(st.integers(0, 255))
    out, err = _decode(bytes(bad))
    if bytes(bad) == data:
        assert err is None and len(out) == len(decoded)
    else:
        assert err is not None  # every change is caught (the checks, the trailer's CRC)


@FUZZ
@given(st.data())
def test_a_valid_stream_cut_or_with_bytes_inserted(draw):
    data, hb, decoded = _valid()
    cut = draw.draw(st.integers(0, len(data) - 1))
    insert = draw.draw(st.binary(max_size=8))
    mutated = data[:cut] + insert + (data[cut:] if insert else b"")
    out, err = _decode(mutated)
    if mutated != data:
        assert err is not None
    if insert == b"":  # a stream cut short: the frames before the cut are the stream's
        assert _check_prefix(out)
