"""Work run ahead of its consumer on a thread of its own (decoding, detection, the anchored
flow's tracking)."""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Future

from myoface.errors import MyofaceValueError

_DONE = object()


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


def run_ahead_parallel(
    items: Iterable,
    works: list[Callable],
    depth: int = 4,
    name: str = "myoface-ahead",
    serial_until: Callable[[], bool] | None = None,
) -> Iterator:
    """``(item, work(item))`` for the items of ``items`` in order, as :func:`run_ahead`, but
    with one worker thread per entry of ``works`` (each its own callable: e.g. a detector of
    its own, for work that keeps no state from one item to the next, such as MediaPipe's
    face mesh in image mode), together up to ``depth`` items ahead of the consumer. The items
    are taken from ``items`` one at a time, under a lock (a generator that reads the results
    taken so far may stop early). While ``serial_until`` returns False, an item is worked on
    before the next is taken (e.g. until a first face is found: what is taken next may
    depend on it). Exceptions (of ``items`` or of a work) are raised here in order; closing
    the generator stops the workers, waits for them and closes ``items`` if it is a
    generator. With one work it is :func:`run_ahead`."""
    if depth < 1:
        raise MyofaceValueError(f"depth must be >= 1; got {depth}")
    if not works:
        raise MyofaceValueError("run_ahead_parallel needs at least one work")
    if len(works) == 1:
        yield from run_ahead(items, works[0], depth, name)
        return
    it = iter(items)
    take = threading.Lock()
    cond = threading.Condition()
    results: dict = {}  # index -> (ok, value)
    state = {"taken": 0, "consumed": 0, "end": None}  # end: the index after the last item
    stop = threading.Event()

    def publish(k: int, entry) -> None:
        with cond:
            results[k] = entry
            cond.notify_all()

    def worker(work: Callable) -> None:
        while not stop.is_set():
            with cond:  # no further ahead of the consumer than ``depth``
                while (
                    not stop.is_set()
                    and state["end"] is None
                    and state["taken"] - state["consumed"] >= depth
                ):
                    cond.wait(0.05)
            if stop.is_set():
                return
            take.acquire()
            held = True
            try:
                if state["end"] is not None:
                    return
                k = state["taken"]
                try:
                    item = next(it)
                except StopIteration:
                    with cond:
                        state["end"] = k
                        cond.notify_all()
                    return
                except BaseException as exc:  # handed to the consumer, in order
                    with cond:
                        state["end"] = k + 1
                    publish(k, (False, exc))
                    return
                state["taken"] = k + 1
                if serial_until is None or serial_until():
                    take.release()
                    held = False
                try:
                    out = (True, (item, work(item)))
                except BaseException as exc:  # handed to the consumer, in order
                    out = (False, exc)
                publish(k, out)
            finally:
                if held:
                    take.release()

    threads = [
        threading.Thread(target=worker, args=(w,), name=f"{name}-{i}", daemon=True)
        for i, w in enumerate(works)
    ]
    for t in threads:
        t.start()
    try:
        k = 0
        while True:
            with cond:
                while k not in results and (state["end"] is None or k < state["end"]):
                    if not any(t.is_alive() for t in threads) and k not in results:
                        break
                    cond.wait(0.05)
                entry = results.pop(k, None)
                if entry is None:
                    return  # the items ended
                state["consumed"] = k + 1
                cond.notify_all()
            ok, value = entry
            if not ok:
                raise value
            yield value
            k += 1
    finally:
        stop.set()
        with cond:
            cond.notify_all()
        for t in threads:
            t.join()
        close = getattr(it, "close", None)
        if close is not None:
            close()
