"""Work run ahead of its consumer on a thread of its own (decoding, detection, the anchored
flow's tracking)."""

from __future__ import annotations

import contextlib
import queue
import sys
import threading
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future

from myoface.errors import MyofaceValueError

_DONE = object()

#: the interpreter's thread switch interval (s) while work runs ahead on threads that
#: release the GIL (:func:`short_switch_interval`)
SWITCH_INTERVAL_S = 0.0005
_switch_lock = threading.Lock()
_switch_users = 0
_switch_saved = 0.005


@contextlib.contextmanager
def short_switch_interval(seconds: float = SWITCH_INTERVAL_S):
    """Python's thread switch interval shortened (``sys.setswitchinterval``; 5 ms by default)
    while the block runs, then put back (the first to enter sets it, the last to leave puts
    it back). A thread that releases the GIL for native work (MediaPipe's graph, PyAV's
    decoder) waits up to the interval to take it back while another thread computes in
    Python: measured 2026-12-03 on the 2-core machine, MediaPipe's face mesh detecting
    single_face.mp4's frames beside a thread busy in Python took 14.5 ms a frame at 5 ms,
    9.5 at 1 ms, 8.8 at 0.5 ms and 8.1 at 0.2 ms (7.2-8.1 alone), the busy thread doing
    0.85-0.87 of its work alone in each."""
    global _switch_users, _switch_saved
    with _switch_lock:
        if _switch_users == 0:
            _switch_saved = sys.getswitchinterval()
            sys.setswitchinterval(min(float(seconds), _switch_saved))
        _switch_users += 1
    try:
        yield
    finally:
        with _switch_lock:
            _switch_users -= 1
            if _switch_users == 0:
                sys.setswitchinterval(_switch_saved)


def run_ahead(
    items: Iterable, work: Callable | None = None, depth: int = 2, name: str = "myoface-ahead"
) -> Iterator:
    """The items of ``items`` in order, produced on a worker thread up to ``depth`` items
    ahead of the consumer; with ``work``, ``(item, work(item))`` (the thread calls it in
    order: a detector in video mode tracks from one frame to the next). The thread's
    exceptions are raised here, in order. Closing this generator (stopping early, an
    exception in the consumer) stops the thread, waits for it and closes ``items`` if it is
    a generator. Worth it where the work releases the GIL (PyAV's decoding, MediaPipe's
    graph): a second core does it meanwhile."""
    if depth < 1:
        raise MyofaceValueError(f"depth must be >= 1; got {depth}")
    q: queue.Queue = queue.Queue(maxsize=depth)
    stop = threading.Event()

    def put(entry) -> bool:
        while not stop.is_set():
            try:
                q.put(entry, timeout=0.05)
                return True
            except queue.Full:
                continue
        return False

    def produce():
        it = iter(items)
        try:
            for item in it:
                out = item if work is None else (item, work(item))
                if stop.is_set() or not put((True, out)):
                    return
            put((True, _DONE))
        except BaseException as exc:  # handed to the consumer
            put((False, exc))
        finally:
            close = getattr(it, "close", None)
            if close is not None:
                close()

    worker = threading.Thread(target=produce, name=name, daemon=True)
    worker.start()
    try:
        while True:
            ok, entry = q.get()
            if not ok:
                raise entry
            if entry is _DONE:
                return
            yield entry
    finally:
        stop.set()
        worker.join()


class OrderedWorker:
    """Calls run in the order submitted on one daemon thread of their own, each result a
    :class:`concurrent.futures.Future` (its exception raised by ``result()``). A daemon, so
    that work still waiting at the interpreter's exit (a job blocked on something that will
    not come) does not hold it; :meth:`close` stops it (the jobs not started are cancelled)."""

    def __init__(self, name: str = "myoface-worker"):
        self._q: queue.Queue = queue.Queue()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while True:
            job = self._q.get()
            if job is None:
                return
            fut, fn, args = job
            if not fut.set_running_or_notify_cancel():
                continue
            try:
                fut.set_result(fn(*args))
            except BaseException as exc:  # handed to whoever takes the result
                fut.set_exception(exc)

    def submit(self, fn: Callable, *args) -> Future:
        """``fn(*args)`` after the jobs submitted before it."""
        fut: Future = Future()
        self._q.put((fut, fn, args))
        return fut

    def close(self, timeout: float | None = None) -> None:
        """Cancel the jobs not started, let the running one end (``timeout`` s at most) and
        stop the thread."""
        while True:
            try:
                job = self._q.get_nowait()
            except queue.Empty:
                break
            if job is not None:
                job[0].cancel()
        self._q.put(None)
        if self._thread is not threading.current_thread():
            self._thread.join(timeout)
