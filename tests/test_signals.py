"""Stop signals are never lost (myoface._signals): one Python swallows in a finaliser is
delivered again, a step in ``deferred`` is done whole, and a second signal in ``held`` waits."""

import os
import signal
import sys
import time

import pytest

from myoface import _signals


def _spin(seconds: float = 0.0) -> None:
    """Run bytecode (the handler runs at the next one) for at least ``seconds``."""
    t_end = time.monotonic() + seconds
    while True:
        for _ in range(1000):
            pass
        if time.monotonic() >= t_end:
            return


class _Swallows:
    """Sends ``signum`` to this process from its ``__del__``, where Python cannot raise the
    handler's exception: it prints it as "Exception ignored" and goes on."""

    def __init__(self, signum):
        self.signum = signum

    def __del__(self):
        os.kill(os.getpid(), self.signum)
        for _ in range(1000):  # (the handler runs here, inside __del__)
            pass


def test_a_swallowed_signal_is_delivered_again_outside_the_finaliser():
    seen = []
    hook, sys.unraisablehook = sys.unraisablehook, seen.append
    try:
        with _signals.stop_signals():
            with pytest.raises(_signals.Interrupted) as exc:
                obj = _Swallows(signal.SIGTERM)
                del obj  # swallowed in __del__ ...
                _spin(2.0)  # ... and raised here, without any raise_pending()
            assert exc.value.signum == signal.SIGTERM
            _signals.clear_pending()
            _spin(3 * _signals.REDELIVER_S)
            _signals.raise_pending()  # (seen once: nothing left)
        assert seen == []  # not reported as "Exception ignored"
    finally:
        sys.unraisablehook = hook


def test_a_swallowed_signal_is_raised_at_the_next_check_once():
    with _signals.stop_signals():
        obj = _Swallows(signal.SIGHUP)
        with pytest.raises(_signals.Interrupted) as exc:
            del obj
            _signals.raise_pending()  # before it is delivered again
        assert exc.value.signum == signal.SIGHUP
        _signals.clear_pending()
        _spin(5 * _signals.REDELIVER_S)  # and it is not delivered a second time


def test_a_redelivery_of_a_signal_seen_since_does_not_fire(monkeypatch):
    """A swallowed signal that is seen (cleared) before its redelivery fires is not sent again,
    even when another signal is noted by then (in CI a stale SIGHUP stopped the next test's
    SIGTERM run: 129 for 143)."""
    monkeypatch.setattr(_signals, "REDELIVER_S", 0.2)  # (wide, so the steps below fit in it)
    with _signals.stop_signals():
        obj = _Swallows(signal.SIGHUP)
        del obj  # swallowed: its redelivery starts
        _signals.clear_pending()  # and it is seen before that fires
        with pytest.raises(_signals.Interrupted) as exc:
            with _signals.deferred():
                os.kill(os.getpid(), signal.SIGTERM)
                _spin(2 * _signals.REDELIVER_S)  # the stale redelivery's time goes by
        assert exc.value.signum == signal.SIGTERM
        assert _signals.pending() is None


def test_a_caught_signal_is_not_raised_again():
    with _signals.stop_signals():
        try:
            os.kill(os.getpid(), signal.SIGINT)
            _spin()
        except KeyboardInterrupt as exc:
            assert isinstance(exc, _signals.Interrupted) and exc.signum == signal.SIGINT
            _signals.clear_pending()
        _signals.raise_pending()  # nothing pending


def test_a_deferred_step_is_done_whole_then_interrupted():
    done = []
    with _signals.stop_signals():
        with pytest.raises(_signals.Interrupted) as exc:
            with _signals.deferred():
                os.kill(os.getpid(), signal.SIGTERM)
                _spin(0.05)  # the handler ran: noted, not raised
                done.append("step")
            done.append("after")  # not reached
        assert exc.value.signum == signal.SIGTERM and done == ["step"]
        _signals.clear_pending()


def test_a_signal_in_held_is_dropped():
    with _signals.stop_signals():
        with _signals.held():
            os.kill(os.getpid(), signal.SIGINT)
            _spin(0.05)
        _signals.raise_pending()  # dropped
        assert _signals.pending() is None


def test_the_handlers_are_restored_after_the_block():
    before = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    hook = sys.unraisablehook
    with _signals.stop_signals():
        assert signal.getsignal(signal.SIGINT) is not before[signal.SIGINT]
        assert sys.unraisablehook is not hook
    assert {s: signal.getsignal(s) for s in before} == before
    assert sys.unraisablehook is hook


def test_deferred_works_without_stop_signals_too():
    """Used from a script (Python's own SIGINT handler), a deferred step is done whole too,
    then KeyboardInterrupt is raised; the handler is Python's again after it."""
    # (Python's own handler, as a script has it: in the whole suite an earlier test in this
    # process left SIGINT ignored; which one is not found yet, 2026-12-02)
    before = signal.signal(signal.SIGINT, signal.default_int_handler)
    done = []
    with pytest.raises(KeyboardInterrupt):
        with _signals.deferred():
            os.kill(os.getpid(), signal.SIGINT)
            _spin(0.05)
            done.append("step")
    assert done == ["step"]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    signal.signal(signal.SIGINT, before)


def test_an_interrupt_inside_a_c_callback_is_still_an_interrupt():
    """A stop signal that lands inside a C extension's callback (numba unpickling a compiled
    function, seen in CI) comes out as a SystemError caused by the Interrupted: the CLI reads
    the interrupt from the chain (exit 128 + the signal), anything else stays an error."""
    from myoface._signals import Interrupted
    from myoface._signals import interrupt_in as _interrupt_in

    inner = Interrupted(signal.SIGINT)
    try:
        try:
            raise inner
        except KeyboardInterrupt as e:
            raise SystemError("returned a result with an exception set") from e
    except SystemError as outer:
        assert _interrupt_in(outer) is inner
    assert _interrupt_in(SystemError("other")) is None


def test_an_error_of_a_library_cut_by_a_signal_is_the_signal():
    """A stop signal that lands inside a library can break it there and come out as another
    error with no trace of the signal (numba cut while compiling: its cache then raised
    "RuntimeError: no compiled object yet", seen in CI): while the signal is noted and not
    yet raised, that error is the stop; once it was seen, an error is an error again."""
    with _signals.stop_signals():
        obj = _Swallows(signal.SIGHUP)
        del obj  # noted, swallowed; the library goes on and fails
        err = RuntimeError("no compiled object yet")
        assert _signals.stop_signal_of(err) == signal.SIGHUP
        _signals.clear_pending()
        assert _signals.stop_signal_of(err) is None
        assert _signals.stop_signal_of(_signals.Interrupted(signal.SIGTERM)) == signal.SIGTERM
        assert _signals.stop_signal_of(KeyboardInterrupt()) == signal.SIGINT


def test_the_cli_says_interrupted_for_an_error_a_signal_caused(monkeypatch, capsys):
    """``myoface`` exits with 128 + the signal and one line when the command fails with an
    ordinary error after a stop signal broke a library under it."""
    from myoface import cli

    def run(args):
        obj = _Swallows(signal.SIGTERM)
        del obj
        raise RuntimeError("no compiled object yet for <Library '_extrapolate'>")

    parser = cli.build_parser()
    monkeypatch.setattr(cli, "build_parser", lambda: parser)
    args = parser.parse_args(["demo"])
    monkeypatch.setattr(parser, "parse_args", lambda argv=None: args)
    monkeypatch.setattr(args, "_run", run)
    assert cli.main(["demo"]) == 128 + signal.SIGTERM
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"{args._prog}: interrupted (SIGTERM)"], err
    # an error with no signal behind it stays an error
    monkeypatch.setattr(args, "_run", lambda a: (_ for _ in ()).throw(RuntimeError("bug")))
    with pytest.raises(RuntimeError, match="bug"):
        cli.main(["demo"])
