"""Project exceptions.

Every error myoface raises on bad input subclasses :class:`MyofaceError` *and* the matching
builtin, so callers can catch either ``MyofaceError`` or e.g. ``ValueError``.
"""

from __future__ import annotations


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
