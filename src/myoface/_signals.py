"""The signals that stop a run (Ctrl-C's SIGINT, SIGTERM, SIGHUP): raised in the main thread
as :class:`Interrupted` where they land, never lost, and held off where a step must not be cut
in two.

Python raises a signal's exception at whatever bytecode the main thread is running. Where that
is a ``__del__``, a weak reference's callback or a generator being closed, the exception is
printed as "Exception ignored" and lost, and the run goes on as if nothing had happened: under
load, one ``myoface analyze`` in about seven CI runs finished a 3000-frame clip after its
SIGINT (2026-12-01), and a SIGINT in ``--report``'s stage could be lost the same way. So, in
:func:`stop_signals`:

- a stop signal whose :class:`Interrupted` is swallowed so is delivered again
  (:data:`REDELIVER_S` later, once the main thread has left the finaliser: the
  ``sys.unraisablehook`` sees it go by), without the "Exception ignored" report; a long
  loop may also call :func:`raise_pending` at each step (a signal that was noted and not
  raised is raised there; one that was caught calls :func:`clear_pending`);
- in a :func:`deferred` block (a frame's outputs, the commit of an output folder) a stop
  signal is noted and raised when the block ends, so that a step is done whole or not at
  all; :func:`held` does the same and drops the signal (the run is stopping already);
- once the block is left, while the interpreter exits, a stop signal is ignored: the command
  has done its work and said so (a Ctrl-C there printed a traceback from an exit handler, or
  killed the process silently with status 130).
"""

from __future__ import annotations

import _thread
import contextlib
import signal
import sys
import threading
import time

#: the signals a run stops on
STOP_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")
#: how long after a stop signal was swallowed (printed as "Exception ignored" and lost) it is
#: delivered again, s: from another thread, so that the main thread has left the finaliser
#: it was lost in (a handler run inside the unraisable hook would be lost there too)
REDELIVER_S = 0.01

_pending: list[int] = []
#: bumped whenever the noted signals are seen or dropped (:func:`_forget`): a redelivery
#: started before that is stale and does not fire (in CI one fired 10 ms later into the next
#: run, which had noted a signal of its own, and stopped it with the wrong one)
_generation = 0
_defer_depth = 0  # deferred() blocks the main thread is in
_installed = 0  # stop_signals() blocks the main thread is in (with their handlers set)
_exit_hook_registered = False


class Interrupted(KeyboardInterrupt):
    """Raised in the main thread by a stop signal (:data:`STOP_SIGNALS`), as SIGINT raises
    KeyboardInterrupt, so the same clean-up (temporary outputs removed) runs; ``signum`` says
    which."""

    def __init__(self, signum: int):
        super().__init__(signum)
        self.signum = signum


def interrupt_in(exc: BaseException | None) -> KeyboardInterrupt | None:
    """``exc`` if it is a KeyboardInterrupt, else the first one among its causes and contexts
    (None if there is none): a stop signal that lands inside a C extension's callback (numba
    unpickling a compiled function, seen in CI) comes out as a SystemError caused by the
    :class:`Interrupted`, and is still an interruption."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


def stop_signal_of(exc: BaseException | None) -> int | None:
    """The stop signal that ``exc`` comes from, or None: the signal of the
    :class:`Interrupted` among its causes (:func:`interrupt_in`; a plain KeyboardInterrupt is
    SIGINT), or, for an ordinary error raised while a stop signal is noted and not yet raised
    (:func:`pending`), that signal. The latter is a signal that landed inside a library and
    broke it there: numba cut in the middle of compiling a function, its cache then failing
    with "no compiled object yet" (a RuntimeError with no trace of the signal, seen in CI
    2026-12-04); the user stopped the run, and that is what it says."""
    interrupt = interrupt_in(exc)
    if interrupt is not None:
        return int(getattr(interrupt, "signum", signal.SIGINT))
    if isinstance(exc, Exception) and _pending:
        return _pending[-1]
    return None


def _forget() -> None:
    """The noted stop signals were seen or dropped: cleared, and any redelivery of them
    started before now cancelled."""
    global _generation
    _pending.clear()
    _generation += 1


def _signals() -> list[int]:
    return [getattr(signal, n) for n in STOP_SIGNALS if hasattr(signal, n)]


def _on_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def _raise_interrupted(signum, frame):
    _pending.append(int(signum))
    if _defer_depth:  # in a step that must be done whole: raised at its end
        return
    raise Interrupted(signum)


def _unraisable_hook(previous):
    def hook(unraisable) -> None:
        exc = unraisable.exc_value
        if isinstance(exc, Interrupted) and _installed:
            _redeliver(exc.signum)  # lost where Python could not raise it: again, later
            return
        previous(unraisable)

    hook.previous = previous
    return hook


def _redeliver(signum: int) -> None:
    """Deliver the swallowed stop signal ``signum`` to the main thread again, from another
    thread after :data:`REDELIVER_S` (unless :func:`raise_pending` has raised it meanwhile)."""
    if not _pending:
        _pending.append(int(signum))
    generation = _generation

    def later() -> None:
        time.sleep(REDELIVER_S)
        if _pending and _installed and _generation == generation:
            _thread.interrupt_main(int(signum))

    threading.Thread(target=later, name="myoface-signal", daemon=True).start()


def _ignore_at_exit() -> None:
    for sig in _signals():
        with contextlib.suppress(ValueError, OSError):
            signal.signal(sig, signal.SIG_IGN)


@contextlib.contextmanager
def stop_signals():
    """In the block, the stop signals raise :class:`Interrupted` (main thread only; elsewhere
    the handlers are left alone), and one swallowed in a finaliser is sent again (see the
    module). The handlers are restored after the block; when the interpreter exits after it,
    the stop signals are ignored."""
    global _installed, _exit_hook_registered
    if not _on_main_thread():
        yield
        return
    old = {}
    for sig in _signals():
        try:
            old[sig] = signal.signal(sig, _raise_interrupted)
        except ValueError:  # (not the main interpreter)
            break
    hook = None
    if old:
        _installed += 1
        hook = sys.unraisablehook = _unraisable_hook(sys.unraisablehook)
    try:
        yield
    finally:
        global _defer_depth
        _defer_depth += 1  # a signal while the handlers are restored is not raised here
        try:
            for sig, handler in old.items():
                signal.signal(sig, handler)
            if hook is not None:
                if sys.unraisablehook is hook:
                    sys.unraisablehook = hook.previous
                _installed -= 1
                if not _installed and not _exit_hook_registered:
                    import atexit

                    atexit.register(_ignore_at_exit)  # (runs first: registered last)
                    _exit_hook_registered = True
        finally:
            _defer_depth -= 1
            _forget()


def raise_pending() -> None:
    """Raise :class:`Interrupted` for a stop signal that came and was not seen (swallowed
    where Python could not raise it, or held off by :func:`deferred`)."""
    if _pending and not _defer_depth:
        signum = _pending[-1]
        _forget()
        raise Interrupted(signum)


def clear_pending() -> None:
    """The stop signal was seen (its exception caught by the run)."""
    _forget()


def pending() -> int | None:
    """The stop signal noted and not yet raised or cleared, or None."""
    return _pending[-1] if _pending else None


@contextlib.contextmanager
def _noting_sigint():
    """Outside :func:`stop_signals` (the library used from a script), Ctrl-C's SIGINT noted by
    this module's handler for the block, where Python's own handler raises
    KeyboardInterrupt; other handlers are left alone."""
    if _installed or signal.getsignal(signal.SIGINT) is not signal.default_int_handler:
        yield
        return
    signal.signal(signal.SIGINT, _raise_interrupted)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, signal.default_int_handler)


@contextlib.contextmanager
def _deferring(drop: bool):
    """The block of :func:`deferred` and :func:`held` (main thread only): stop signals noted,
    not raised; with ``drop`` those noted are dropped when the outermost such block ends."""
    global _defer_depth
    if not _on_main_thread():
        yield
        return
    with _noting_sigint():
        _defer_depth += 1
        try:
            yield
        finally:
            _defer_depth -= 1
            if drop and not _defer_depth:
                _forget()


@contextlib.contextmanager
def deferred():
    """A step done whole or not at all: a stop signal in the block is noted and raised as
    :class:`Interrupted` when the block ends (main thread; elsewhere signals are not raised
    anyway). Keep the block short (it delays the stop by its length)."""
    with _deferring(drop=False):
        yield
    if _on_main_thread():
        raise_pending()


@contextlib.contextmanager
def held():
    """As :func:`deferred`, but a stop signal in the block is dropped: for the work that
    completes a run that is stopping already (its kept frames, its commit), so that a second
    Ctrl-C does not cut it short."""
    with _deferring(drop=True):
        yield
