"""Stop signals are not lost where Python swallows their exception (myoface._signals)."""

import os
import signal
import sys

import pytest

from myoface import _signals


def test_a_swallowed_signal_is_raised_at_the_next_check():
    class Swallows:
        def __del__(self):
            os.kill(os.getpid(), signal.SIGTERM)  # raised inside __del__: printed, then lost

    seen = []
    hook, sys.unraisablehook = sys.unraisablehook, seen.append
    try:
        with _signals.stop_signals():
            obj = Swallows()
            del obj
            for _ in range(1000):  # (the handler runs at the next bytecode: in __del__)
                pass
            assert seen and isinstance(seen[0].exc_value, _signals.Interrupted)
            with pytest.raises(_signals.Interrupted) as exc:
                _signals.raise_pending()
            assert exc.value.signum == signal.SIGTERM
            _signals.raise_pending()  # (seen once: nothing left)
    finally:
        sys.unraisablehook = hook


def test_a_caught_signal_is_not_raised_again():
    with _signals.stop_signals():
        try:
            os.kill(os.getpid(), signal.SIGINT)
            for _ in range(1000):  # (the handler runs at the next bytecode)
                pass
        except KeyboardInterrupt as exc:
            assert isinstance(exc, _signals.Interrupted) and exc.signum == signal.SIGINT
            _signals.clear_pending()
        _signals.raise_pending()  # nothing pending


def test_the_handlers_are_restored_after_the_block():
    before = signal.getsignal(signal.SIGINT)
    with _signals.stop_signals():
        assert signal.getsignal(signal.SIGINT) is not before
    assert signal.getsignal(signal.SIGINT) is before
