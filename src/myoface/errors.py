"""Project exceptions.

Every error myoface raises on bad input subclasses :class:`MyofaceError` *and* the matching
builtin, so callers can catch either ``MyofaceError`` or e.g. ``ValueError``; a
:class:`MyofaceUsageError` is the command line's usage error (exit status 2).
:func:`user_message` is the one line an exception's text becomes for a user, and
:func:`writing` makes a full disk's error name the output being written.
"""

from __future__ import annotations

import contextlib
import os
import re


class MyofaceError(Exception):
    """Base class of every error raised by myoface on bad input or failed work."""


class MyofaceValueError(MyofaceError, ValueError):
    """An argument has the wrong shape, type or value."""


class MyofaceFileNotFoundError(MyofaceError, FileNotFoundError):
    """A file the user named does not exist."""


class MyofaceFormatError(MyofaceError, ValueError):
    """A file exists but its content cannot be read as the expected format."""


class MyofaceSimulationError(MyofaceError, RuntimeError):
    """A simulation produced NaN/Inf or otherwise broke down."""


class MyofaceDependencyError(MyofaceError, ImportError):
    """An optional dependency needed by the requested feature is missing."""


class MyofaceWarning(UserWarning):
    """Input myoface accepts but doubts (e.g. a mesh far from millimetres, a cropped video
    frame); the command line prints it as one line on stderr."""


class MyofaceUsageError(MyofaceValueError):
    """The command line's options do not go together, or a value is outside its limits, in a
    way the argument parser cannot see by itself (e.g. ``--intensity`` without
    ``--expression``): the command line reports it as a usage error, exit status 2."""


#: Python's refusal of a huge integer literal (``int("1" * 5000)``, ``json.loads``,
#: ``tomllib.loads``): "Exceeds the limit (4300 digits) for integer string conversion: value
#: has 5000 digits; use sys.set_int_max_str_digits() to increase the limit"
_INT_DIGITS = re.compile(
    r"Exceeds the limit \((\d+) digits\) for integer string conversion(?:: value has (\d+) "
    r"digits)?(?:; use sys\.set_int_max_str_digits\(\) to increase the limit)?"
)
#: the ``[Errno N] `` prefix of an OSError's text, and PyAV's, whose numbers are FFmpeg's
#: (e.g. 1094995529, AVERROR_INVALIDDATA) and mean nothing to a user
_ERRNO = re.compile(r"\[Errno -?\d+\] ")


def user_message(exc: BaseException, limit: int = 300) -> str:
    """The text of ``exc`` as one line a user can read: whitespace folded; Python's and
    FFmpeg's internals said plainly (a huge integer: "a number of 5000 digits (at most
    4300)"; no ``[Errno N]`` prefixes); at most ``limit`` characters."""

    def digits(m: re.Match) -> str:
        n = f"{m.group(2)} digits" if m.group(2) else "more digits"
        return f"a number of {n} (at most {m.group(1)})"

    text = " ".join(str(exc).split())
    text = _INT_DIGITS.sub(digits, text)
    text = _ERRNO.sub("", text) or type(exc).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


@contextlib.contextmanager
def writing(path):
    """Inside the block, an :class:`OSError` that names no file (a full disk, ``ENOSPC``,
    raised by a ``write`` or a ``close``; a quota; an I/O error) is raised again naming
    ``path``, the output being written, so that its one line says where."""
    try:
        yield
    except OSError as exc:
        if exc.filename is not None or exc.errno is None:
            raise
        raise OSError(exc.errno, exc.strerror or str(exc), os.fspath(path)) from exc
