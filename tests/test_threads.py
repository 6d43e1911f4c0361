"""run_ahead: work on a thread of its own, ahead of its consumer (decoding, detection)."""

import pytest

from myoface._threads import run_ahead
from myoface.errors import MyofaceValueError


def ahead(items, work, depth=2):
    return run_ahead(items, work, depth, name="myoface-test-ahead")


def _detect_threads():
    import threading

    return [t for t in threading.enumerate() if t.name == "myoface-test-ahead"]


def test_run_ahead_runs_in_order_and_stops_its_thread():
    """The work (a detector) runs on a worker thread, in order, ahead of the consumer; the results come
    in order; stopping early (closing the generator), an exception in the detector or in the
    source all end the thread (joined, none left) and close the source."""
    import threading

    seen, closed = [], []

    def source(n):
        try:
            yield from range(n)
        finally:
            closed.append(True)

    def detect(k):
        seen.append((k, threading.current_thread().name))
        if k == 13:
            raise ValueError("no such frame")
        return 10 * k

    assert list(ahead(source(5), detect, depth=2)) == [(k, 10 * k) for k in range(5)]
    assert [name for _, name in seen] == ["myoface-test-ahead"] * 5 and closed == [True]
    assert not _detect_threads()
    # stopped early: the thread, blocked on a full queue, sees the stop and ends
    gen = ahead(source(1000), detect, depth=3)
    assert next(gen) == (0, 0)
    gen.close()
    assert not _detect_threads() and len(closed) == 2 and len(seen) < 5 + 10
    # the detector's exception is raised in the consumer, in order, and the thread ends
    out = []
    with pytest.raises(ValueError, match="no such frame"):
        for item in ahead(source(20), lambda k: detect(k + 10), depth=2):
            out.append(item)
    assert [k for k, _ in out] == [0, 1, 2] and not _detect_threads()

    def broken():
        yield 1
        raise RuntimeError("cannot decode")

    with pytest.raises(RuntimeError, match="cannot decode"):
        list(ahead(broken(), detect))
    assert not _detect_threads()
    with pytest.raises(MyofaceValueError, match="depth"):
        next(ahead([], detect, depth=0))


def test_run_ahead_without_work_yields_the_items():
    assert list(run_ahead(iter(range(7)), depth=1)) == list(range(7))


def test_ordered_worker_runs_in_order_and_stops():
    """OrderedWorker: jobs run one after another in the order submitted, on a daemon thread;
    an exception is the job's future's; closing cancels what has not started and stops the
    thread."""
    import threading

    from myoface._threads import OrderedWorker

    order, gate = [], threading.Event()
    w = OrderedWorker("myoface-test-worker")
    futs = [w.submit(lambda k=k: (order.append(k), k * k)[1]) for k in range(5)]
    assert [f.result(timeout=10) for f in futs] == [0, 1, 4, 9, 16] and order == list(range(5))
    bad = w.submit(lambda: 1 / 0)
    with pytest.raises(ZeroDivisionError):
        bad.result(timeout=10)
    blocked = w.submit(gate.wait)
    later = w.submit(order.append, 99)
    gate.set()
    blocked.result(timeout=10)
    w.close(timeout=10)
    assert later.done() and (later.cancelled() or order[-1] == 99)
    assert not [t for t in threading.enumerate() if t.name == "myoface-test-worker"]
    w2 = OrderedWorker("myoface-test-worker")
    w2.submit(gate.clear)
    w2.submit(gate.wait, 0.5)
    pending = w2.submit(order.append, 100)
    w2.close(timeout=10)
    assert pending.cancelled() or pending.done()
