"""Work run ahead of its consumer on a thread of its own (decoding, detection)."""

from __future__ import annotations

import queue
import threading
from collections.abc import Callable, Iterable, Iterator

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
