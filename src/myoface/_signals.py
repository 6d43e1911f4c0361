"""The signals that stop a run (Ctrl-C's SIGINT, SIGTERM, SIGHUP): raised in the main thread
as :class:`Interrupted` where they land, and kept until the run has seen them.

Python raises a signal's exception at whatever bytecode the main thread is running. Where that
is a ``__del__``, a weak reference's callback or a generator being closed, the exception is
printed as "Exception ignored" and lost, and the run goes on as if nothing had happened: under
load, one ``myoface analyze`` in about seven CI runs finished a 3000-frame clip after its
SIGINT (2026-12-01). So the handler also notes the signal, and a long loop calls
:func:`raise_pending` at each step: a signal that was swallowed is raised there; one that was
caught calls :func:`clear_pending`.
"""

from __future__ import annotations

import contextlib
import signal

#: the signals a run stops on
STOP_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")

_pending: list[int] = []


class Interrupted(KeyboardInterrupt):
    """Raised in the main thread by a stop signal (:data:`STOP_SIGNALS`), as SIGINT raises
    KeyboardInterrupt, so the same clean-up (temporary outputs removed) runs; ``signum`` says
    which."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def _raise_interrupted(signum, frame):
    _pending.append(int(signum))
    raise Interrupted(signum)


@contextlib.contextmanager
def stop_signals():
    """In the block, the stop signals raise :class:`Interrupted` (main thread only; elsewhere
    the handlers are left alone)."""
    old = {}
    for name in STOP_SIGNALS:
        sig = getattr(signal, name, None)
        if sig is None:
            continue
        try:
            old[sig] = signal.signal(sig, _raise_interrupted)
        except ValueError:  # not the main thread
            break
    try:
        yield
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
        _pending.clear()


def raise_pending() -> None:
    """Raise :class:`Interrupted` for a stop signal that came and was not seen (swallowed
    where Python could not raise it)."""
    if _pending:
        signum = _pending[-1]
        _pending.clear()
        raise Interrupted(signum)


def clear_pending() -> None:
    """The stop signal was seen (its exception caught by the run)."""
    _pending.clear()
