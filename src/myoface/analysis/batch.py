"""Many videos analysed at once, on this machine or on a Dask cluster (``myoface batch``).

Each video gets a folder under the output folder, named from its stem (``clip``, then
``clip-2``, ... when stems repeat), holding what ``myoface analyze`` writes
(:func:`~myoface.analysis.outputs.analyze_to_folder`) and, written last, ``done.json``: the
video's identity (path, size, modification time), the settings and the video's summary row.
A folder whose ``done.json`` matches the video and the settings is complete: a second run
skips it. A video that fails is recorded with its error and never stops the others; its
folder is removed (or, if it existed, left without ``done.json``), so the next run tries it
again.

The output folder also gets ``summary.parquet`` and ``summary.csv``, one row per video of the
run (:data:`SUMMARY_COLUMNS`, then ``mean_<muscle>`` columns), each written whole (a
temporary file renamed).

A stop signal (Ctrl-C's SIGINT, SIGTERM, SIGHUP; in the main thread) stops the batch: no video
starts after it, the videos being analysed are stopped (within :data:`STOP_GRACE_S`; each
keeps what ``myoface analyze`` keeps when stopped, without done.json), the summary is written
with every video that finished (in this run, or in an earlier one: ``skipped``), and
:class:`~myoface._signals.Interrupted` is raised, noting what was kept.

Engines:

- ``"local"``: a pool of ``workers`` processes on this machine (plain calls in this process
  when ``workers`` is 1 or there is one video to analyse);
- ``"dask"``: a ``distributed.LocalCluster`` of ``workers`` single-threaded worker processes,
  or the existing cluster whose scheduler is at ``scheduler`` (or a ``client`` you made),
  e.g. one started on SLURM by dask-jobqueue or on Kubernetes by dask-kubernetes. Every
  worker needs myoface installed and must see the videos and the output folder at the same
  paths (a shared file system).

A worker process builds the face model once (:func:`cached_model`) and keeps it for every
video it analyses; the model is immutable and shared by the worker's threads.

The analysis settings (``tracker``, ``init``, ``calibration_frame``, ``max_frames``,
``refine``, ``sigma``, ``estimator``, ``flow``, ``photometric``) are those of ``myoface
analyze`` (:func:`~myoface.analysis.outputs.analyze_to_folder`), the same for every video.
"""

from __future__ import annotations

import concurrent.futures as cf
import contextlib
import glob
import importlib
import json
import math
import os
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

from myoface._io import atomic_output, ensure_output_dir, sha256_file
from myoface._signals import (
    STOP_SIGNALS,
    Interrupted,
    raise_pending,
    stop_signal_of,
    stop_signals,
)
from myoface.analysis.estimate import skin_response
from myoface.analysis.initfiles import load_init
from myoface.analysis.outputs import FolderResult, analyze_to_folder
from myoface.analysis.pipeline import resolve_photometric
from myoface.analysis.sections import PAPER_MUSCLES
from myoface.analysis.trackers.landmark_fit import LANDMARK_ESTIMATORS
from myoface.analysis.trackers.snakes import ESTIMATORS
from myoface.analysis.video import open_video
from myoface.errors import (
    MyofaceDependencyError,
    MyofaceError,
    MyofaceFileNotFoundError,
    MyofaceValueError,
)
from myoface.model import load_face_model
from myoface.render import progress

__all__ = [
    "ENGINES",
    "STOP_GRACE_S",
    "SUMMARY_COLUMNS",
    "FolderResult",
    "LocalPool",
    "analyze_to_folder",
    "cached_model",
    "expand_videos",
    "local_pool",
    "run_batch",
    "warm_model",
    "write_summary",
]

ENGINES = ("local", "dask")
STATUSES = ("ok", "failed", "skipped")
#: the marker of a complete result folder, written last
DONE_FILE = "done.json"
#: the summary's columns before the per-muscle means (``mean_<muscle id>``)
SUMMARY_COLUMNS = (
    "path",  # the video, resolved
    "folder",  # its result folder, relative to the output folder
    "status",  # ok / failed / skipped (complete from an earlier run, whose numbers it keeps)
    "error",  # why it failed (empty otherwise)
    "frames",  # frames analysed
    "measured_fraction",  # the fraction of them measured (quality "ok")
    "fps",  # frames analysed per second of wall time
    "wall_time_s",  # the video's analysis and outputs, s (the worker's model set-up excluded)
)
#: settings that done.json gained after its first version, with the value the analyses of an
#: older done.json had: its folders stay complete for a run with those values
_LATER_SETTINGS = {
    "calibration_frame": None,
    "refine": None,
    "sigma": None,
    "flow": False,
    "photometric": False,
}
#: how long (s) to wait for an existing Dask scheduler, and for it to have a worker
SCHEDULER_TIMEOUT_S = 10.0
_GLOB_CHARS = set("*?[")


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _require(module: str, feature: str):
    try:
        return importlib.import_module(module)
    except ImportError:
        raise MyofaceDependencyError(
            f'{feature} needs {module.split(".")[0]}: pip install "myoface[batch]"'
        ) from None


# ------------------------------------------------------------------------------ inputs


def expand_videos(patterns, exclude: str | os.PathLike | None = None) -> list[Path]:
    """The videos named by ``patterns``: paths (a movie file or a folder of images) and glob
    patterns (``*``, ``?``, ``[...]``; ``**`` spans folders), resolved, in the order given
    (a pattern's matches sorted), each once. Files inside ``exclude`` (the output folder, whose
    overlay videos a pattern may match) are left out.

    Raises
    ------
    MyofaceFileNotFoundError
        For a path that does not exist, or a pattern that matches no file.
    """
    ex = Path(exclude).resolve() if exclude is not None else None
    out: list[Path] = []
    seen: set[Path] = set()
    for pat in patterns:
        pat = os.fspath(pat)
        if Path(pat).exists():  # a file name may hold glob characters, e.g. "take[1].mp4"
            hits = [pat]
        elif _GLOB_CHARS & set(pat):
            hits = sorted(glob.glob(os.path.expanduser(pat), recursive=True))
            if not hits:
                raise MyofaceFileNotFoundError(f"no file matches {pat!r}")
        else:
            raise MyofaceFileNotFoundError(f"no such video: {pat}")
        for h in hits:
            p = Path(h).resolve()
            if ex is not None and (p == ex or ex in p.parents):
                continue
            if p not in seen:
                seen.add(p)
                out.append(p)
    if not out:
        raise MyofaceFileNotFoundError(
            f"no video to analyse: every match of {' '.join(map(str, patterns))} is inside {ex}"
        )
    return out


def _identity(video: Path) -> dict:
    st = video.stat()
    return {"video": str(video), "size": st.st_size, "mtime_ns": st.st_mtime_ns}


def _read_done(folder: Path) -> dict | None:
    try:
        doc = json.loads((folder / DONE_FILE).read_text())
    except (OSError, ValueError):
        return None
    return doc if isinstance(doc, dict) else None


def _is_done(folder: Path, video: Path, settings: dict) -> dict | None:
    """The summary row stored in ``folder``'s done.json when it holds this video's complete
    result with these settings, else None."""
    doc = _read_done(folder)
    stored = None if doc is None else doc.get("settings")
    if not isinstance(stored, dict) or {**_LATER_SETTINGS, **stored} != settings:
        return None
    row = doc.get("row")
    if not isinstance(row, dict) or not set(SUMMARY_COLUMNS) <= set(row):
        return None
    try:
        same = {k: doc.get(k) for k in ("video", "size", "mtime_ns")} == _identity(video)
    except OSError:
        return None
    return row if same else None


def result_folders(videos: list[Path], out: Path) -> list[str]:
    """A folder name under ``out`` for each video: its stem, or ``stem-2``, ``stem-3``, ...
    when stems repeat. A name whose folder holds another video's complete result (its
    done.json) is not reused, so names stay with their videos from run to run."""
    names = []
    taken: set[str] = set()
    for v in videos:
        stem = v.stem if v.is_file() else v.name
        stem = stem or "video"
        k = 1
        while True:
            name = stem if k == 1 else f"{stem}-{k}"
            if name not in taken:
                doc = _read_done(out / name)
                if doc is None or doc.get("video") == str(v):
                    break
            k += 1
        taken.add(name)
        names.append(name)
    return names


# ------------------------------------------------------------------------------ the task

# The face models this process has built, by the files they were loaded from. A worker process
# analyses many videos with one model, and building it (the lattice, its factorisations, the
# skin's responses) takes seconds, as long as a short clip's analysis; the job cannot carry it
# (a job is pickled to its worker for every video) and the model cannot own it (it is the
# model; per-model derived data lives in FaceModel.memo). So the process keeps it, for its
# lifetime. A path names its model for as long as the process lives, as it names the face in
# done.json's settings: after a face file is edited, use new workers (and a new output folder).
_MODELS: dict = {}
_MODELS_LOCK = threading.Lock()


def cached_model(face: str | None = None, muscles: str | None = None):
    """This process's face model for ``face`` (a path; None: the bundled face) and
    ``muscles``, built on first use and kept for the process' lifetime (immutable, safe to
    share between threads)."""
    key = (face, muscles)
    with _MODELS_LOCK:
        fm = _MODELS.get(key)
        if fm is None:
            fm = load_face_model(face, muscles=muscles)
            # the skin's responses to the estimated muscles (both trackers use them), memoised
            # on the model: computed here once rather than in the worker's first analysis.
            # A face without those muscles fails in the analysis itself, with its message.
            with contextlib.suppress(MyofaceError, KeyError):
                skin_response(fm, PAPER_MUSCLES)
            _MODELS[key] = fm
    return fm


def warm_model(face: str | None = None, muscles: str | None = None) -> None:
    """:func:`cached_model`, returning nothing (for ``client.run`` or a pool's initializer,
    which would otherwise send the model back)."""
    cached_model(face, muscles)


@dataclass
class _Job:
    """One video's work, sent to a worker (small: paths, settings and the init contours)."""

    video: str
    out: str
    folder: str
    settings: dict
    init: dict | None = field(default=None, repr=False)
    single_thread: bool = False


def _failed_row(job: _Job, error: str, wall_s: float = math.nan) -> dict:
    return {
        "path": job.video,
        "folder": job.folder,
        "status": "failed",
        "error": error,
        "frames": 0,
        "measured_fraction": math.nan,
        "fps": math.nan,
        "wall_time_s": wall_s,
        "means": {},
    }


def _error_text(exc: BaseException) -> str:
    msg = " ".join(str(exc).split())
    if isinstance(exc, MyofaceError):
        return msg or type(exc).__name__
    return f"{type(exc).__name__}: {msg}" if msg else type(exc).__name__


def _thread_lock_for_bars() -> None:
    """tqdm's lock in this worker process, unless it has one: a thread lock. Its default is
    also a named semaphore, which a worker killed by the batch's stop (its Dask cluster closed,
    its video past :data:`STOP_GRACE_S`) leaves behind, and which multiprocessing's resource
    tracker then reports ("leaked semaphore objects") as the batch exits; a worker's progress
    bars are off."""
    import tqdm

    if not hasattr(tqdm.tqdm, "_lock"):
        tqdm.tqdm.set_lock(threading.RLock())


def analyze_job(job: _Job) -> dict:
    """Analyse one video into its folder and return its summary row; never raises for a bad
    video (the row says why it failed), only for an interruption (KeyboardInterrupt, after
    which the folder has no done.json). Runs on a worker."""
    if job.single_thread:
        # one video per worker thread: the numba kernels use this thread only
        import numba

        numba.set_num_threads(1)
        _thread_lock_for_bars()

    s = job.settings
    t0 = time.perf_counter()
    try:
        video = open_video(job.video)  # a broken file fails before the model is built
        model = cached_model(s["face"], s["muscles"])
        folder = Path(job.out) / job.folder
        (folder / DONE_FILE).unlink(missing_ok=True)  # an older result is no longer complete
        t0 = time.perf_counter()
        res = analyze_to_folder(
            video,
            folder,
            model=model,
            tracker=s["tracker"],
            init=job.init,
            calibration_frame=s["calibration_frame"],
            max_frames=s["max_frames"],
            refine=s["refine"],
            sigma=s["sigma"],
            estimator=s["estimator"],
            face=s["face"],
            flow=s["flow"],
            photometric=s["photometric"],
        )
        wall = time.perf_counter() - t0
        row = {
            "path": job.video,
            "folder": job.folder,
            "status": "ok",
            "error": "",
            "frames": len(res.frames),
            "measured_fraction": res.measured_fraction,
            "fps": len(res.frames) / wall if wall > 0 else math.nan,
            "wall_time_s": wall,
            "means": res.mean_contractions(),
        }
        doc = {**_identity(Path(job.video)), "settings": s, "row": row}
        with atomic_output(folder / DONE_FILE) as tmp:
            tmp.write_text(json.dumps(doc, indent=1))
        return row
    except Exception as exc:  # a bad video is recorded, never raised
        signum = stop_signal_of(exc)
        if signum is not None:  # (a stop signal that broke a library: not a bad video)
            raise Interrupted(signum) from exc
        return _failed_row(job, _error_text(exc), time.perf_counter() - t0)


# ------------------------------------------------------------------------------ stopping

# A stop signal (SIGINT, SIGTERM, SIGHUP: myoface._signals.STOP_SIGNALS) stops a batch so:
# no video starts after it; the videos being analysed are stopped (each keeps what analyze
# keeps when interrupted, and gets no done.json: the next run analyses it again); the
# summary of every finished video is written; Interrupted is raised (myoface prints one line
# and exits with 128 + the signal's number).
#
# - The process that schedules the videos must not have the signal raised where it lands (in
#   a pool's submit, which starts a worker process, or in the summary being written): there
#   it is only noted (_noted_stop_signals), and the scheduling loops look at it between their
#   short waits (_POLL_S).
# - A video analysed in this process (one worker) runs under _signals.stop_signals, as
#   analyze's does: the signal raises Interrupted in it, except in the steps the analysis
#   holds it off.
# - A local pool's workers start with the stop signals blocked (the terminal's Ctrl-C goes
#   to the whole process group: a second signal sent to them would cut the first one's
#   clean-up); they take SIGTERM only, which this process sends once (LocalPool), and which
#   stops a video as above. A Dask LocalCluster's workers keep SIGINT and SIGHUP blocked:
#   closing the cluster stops them.

#: how long (s) the videos being analysed get to stop after a stop signal, before their
#: worker processes are killed (a video stops at its next frame, then writes what it kept)
STOP_GRACE_S = 2.0
#: how often (s) the loops that wait (for a video, for a scheduler) look for a stop signal
_POLL_S = 0.1
_STOP_SIGNALS = tuple(getattr(signal, n) for n in STOP_SIGNALS if hasattr(signal, n))
#: the stop signals a terminal sends to every process of its foreground group
_TERMINAL_SIGNALS = tuple(s for s in _STOP_SIGNALS if s != getattr(signal, "SIGTERM", None))


class _Stop:
    """A batch's stop: the number of its first stop signal, or None."""

    signum: int | None = None


_NOTED: list[_Stop] = []  # the batch whose stop signals this process notes (main thread)
_WORKER_SIGNAL_AT = [-math.inf]  # in a pool worker: when a stop signal last came


def _note_stop_signal(signum, frame):
    """The stop signals' handler while a batch schedules its videos: the signal is noted."""
    for stop in _NOTED[-1:]:
        if stop.signum is None:
            stop.signum = int(signum)


def _on_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


@contextlib.contextmanager
def _noted_stop_signals():
    """A :class:`_Stop` whose ``signum`` the stop signals set in the block (main thread; a
    signal the caller ignores or leaves to the system's default is left alone)."""
    stop = _Stop()
    if not _on_main_thread():  # (signals are the main thread's)
        yield stop
        return
    raise_pending()  # a stop signal that came before and was not raised
    old = {}
    _NOTED.append(stop)
    try:
        for sig in _STOP_SIGNALS:
            if callable(signal.getsignal(sig)):  # it raises (KeyboardInterrupt, Interrupted)
                old[sig] = signal.signal(sig, _note_stop_signal)
        yield stop
    finally:
        for sig, handler in old.items():
            signal.signal(sig, handler)
        _NOTED.remove(stop)


@contextlib.contextmanager
def _signals_blocked(signals=_STOP_SIGNALS):
    """``signals`` blocked in this thread for the block: a process started in it starts with
    them blocked (as multiprocessing's resource tracker starts), as do the threads started in
    it (the Dask cluster's event loop, which starts the cluster's workers)."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    from multiprocessing import resource_tracker

    # the tracker, started by the first process or lock of multiprocessing, unblocks SIGINT
    # and SIGTERM in the thread that starts it: started here first
    resource_tracker.ensure_running()
    old = signal.pthread_sigmask(signal.SIG_BLOCK, signals)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


# ------------------------------------------------------------------------------ engines


class LocalPool(cf.ProcessPoolExecutor):
    """The local engine's pool of worker processes (:func:`local_pool`), which a batch stops
    at a stop signal: its workers start with the stop signals blocked and then take SIGTERM
    only, which stops the video a worker is analysing and is noted between videos."""

    def submit(self, fn, /, *args, **kwargs):
        with _signals_blocked():  # (submit starts the worker processes)
            return super().submit(fn, *args, **kwargs)

    def _signal_workers(self, signum: int | None) -> None:
        """Send ``signum`` to each worker process (None: kill them)."""
        for proc in list((self._processes or {}).values()):  # (the base class's processes)
            with contextlib.suppress(OSError, ValueError, AttributeError):
                if signum is None:
                    proc.kill()
                elif proc.is_alive():
                    os.kill(proc.pid, signum)


def _note_worker_signal(signum, frame):
    """A pool worker's SIGTERM handler between videos: noted (:func:`_pool_job`)."""
    _WORKER_SIGNAL_AT[0] = time.monotonic()


def _start_worker(initializer=None, initargs=()) -> None:
    """A local pool worker's start (:class:`LocalPool`): SIGTERM noted and unblocked (the
    terminal's signals stay blocked), then the pool's ``initializer(*initargs)``."""
    term = getattr(signal, "SIGTERM", None)
    if term is not None:
        signal.signal(term, _note_worker_signal)
        if hasattr(signal, "pthread_sigmask"):
            signal.pthread_sigmask(signal.SIG_UNBLOCK, [term])
    if initializer is not None:
        initializer(*initargs)


def local_pool(workers: int, initializer=None, initargs=()) -> LocalPool:
    """A pool of ``workers`` processes for the local engine (spawned, not forked: this process
    may hold numba's and OpenMP's threads); ``initializer(*initargs)`` runs in each as it
    starts (e.g. :func:`warm_model`, to build the model before the first video). A batch's
    stop signal stops the videos its workers are analysing (:class:`LocalPool`)."""
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")
    return LocalPool(
        max_workers=workers,
        mp_context=ctx,
        initializer=_start_worker,
        initargs=(initializer, initargs),
    )


def _pool_job(job: _Job) -> dict | None:
    """:func:`analyze_job` in a pool's worker; None when a stop signal stopped the video, or
    came (to the worker, between videos) in the last :data:`STOP_GRACE_S` s: it was sent as
    this video was, to stop the batch that sent it."""
    if _on_main_thread() and time.monotonic() - _WORKER_SIGNAL_AT[0] < STOP_GRACE_S:
        return None
    try:
        with stop_signals():
            row = analyze_job(job)
            raise_pending()  # (a stop signal whose Interrupted a library made an error)
            return row
    except KeyboardInterrupt:
        return None


def _pool_row(fut, job: _Job) -> dict | None:
    try:
        return fut.result()
    except KeyboardInterrupt:  # a worker of a pool not made by local_pool got a SIGINT
        return None
    except Exception as exc:  # the worker process died
        return _failed_row(job, _error_text(exc))


def _run_local(jobs: list[_Job], workers: int, record, stop: _Stop, closing, executor=None) -> None:
    """Run ``jobs`` (on ``executor``, a pool of ``workers`` processes, or in this process
    when that is 1), calling ``record(k, row)`` as job ``k`` finishes, until ``stop`` has a
    stop signal (see "stopping" above). The pool this call starts is shut down by
    ``closing`` (an ExitStack), after the summary is written (its workers take a second or
    two to exit)."""
    if executor is None and (workers <= 1 or len(jobs) <= 1):
        for k, job in enumerate(jobs):
            if stop.signum is not None:
                return
            try:
                with stop_signals():  # (the video is stopped as analyze's is)
                    row = analyze_job(job)
                    raise_pending()  # (a stop signal whose Interrupted a library made an error)
            except KeyboardInterrupt as exc:
                stop.signum = stop.signum or getattr(exc, "signum", signal.SIGINT)
                return
            record(k, row)
        return
    for job in jobs:
        job.single_thread = True
    own = executor is None
    if own:
        executor = local_pool(min(workers, len(jobs)))
        closing.callback(executor.shutdown, wait=True, cancel_futures=True)
    # as many videos sent as there are workers to start them: the others are still here
    # when a stop signal comes, and never start
    slots = min(getattr(executor, "_max_workers", None) or workers, len(jobs))
    waiting = list(range(len(jobs)))[::-1]
    running: dict = {}
    stop_by = None  # when the videos being analysed must have stopped
    try:
        while waiting or running:
            if stop.signum is not None and stop_by is None:
                waiting.clear()
                stop_by = time.monotonic() + STOP_GRACE_S
                if isinstance(executor, LocalPool):
                    executor._signal_workers(signal.SIGTERM)
            if stop_by is not None and time.monotonic() > stop_by:
                break
            while waiting and len(running) < slots:
                k = waiting.pop()
                try:
                    running[executor.submit(_pool_job, jobs[k])] = k
                except cf.BrokenExecutor as exc:  # a worker died: the pool takes no more
                    for j in (k, *waiting[::-1]):
                        record(j, _failed_row(jobs[j], _error_text(exc)))
                    waiting.clear()
            done, _ = cf.wait(running, timeout=_POLL_S, return_when=cf.FIRST_COMPLETED)
            for fut in done:
                k = running.pop(fut)
                row = _pool_row(fut, jobs[k])
                if row is None and stop.signum is None:
                    row = _failed_row(jobs[k], "interrupted: its worker got a stop signal")
                if row is not None and stop.signum is not None and row["status"] != "ok":
                    # (a video being analysed when the stop came and not finished: stopped,
                    # not failed; its folder has no done.json and the next run analyses it)
                    row = None
                if row is not None:
                    record(k, row)
    finally:
        for fut in running:
            fut.cancel()
        if own and running:  # still analysing after STOP_GRACE_S (or an error here)
            executor._signal_workers(None)
        if own and stop_by is not None:  # the workers exit (a second or two) as the summary
            executor.shutdown(wait=False, cancel_futures=True)  # is written


def connect(scheduler: str, timeout: float = SCHEDULER_TIMEOUT_S, *, _stop: _Stop | None = None):
    """A ``distributed.Client`` of the scheduler at ``scheduler`` (e.g. ``tcp://host:8786``),
    once it has at least one worker; a :class:`MyofaceValueError` after ``timeout`` s
    (the whole wait: the scheduler's answer and its first worker) rather than a hang, and
    one that names a peer that is not a Dask scheduler."""
    distributed = _require("distributed", "the dask engine")
    from distributed.comm import parse_address, parse_host_port

    stop = _stop or _Stop()
    deadline = time.monotonic() + timeout
    try:
        scheme, loc = parse_address(scheduler)
        host_port = parse_host_port(loc) if scheme == "tcp" else None
    except ValueError as exc:
        raise MyofaceValueError(f"--scheduler: not a scheduler address: {exc}") from None
    if host_port is not None:
        _probe_scheduler(scheduler, host_port, timeout, deadline, stop)

    # distributed.Client has no bound on its handshake's read (a peer that accepts and says
    # nothing holds it for good): it is made in a thread, left behind at the deadline
    box: dict = {"phase": "connect"}
    lock = threading.Lock()

    def make():
        client = None
        try:
            client = distributed.Client(
                scheduler, timeout=max(deadline - time.monotonic(), _POLL_S)
            )
            with lock:
                box["phase"] = "workers"
            client.wait_for_workers(1, timeout=max(deadline - time.monotonic(), _POLL_S))
        except BaseException as exc:
            with lock:
                box["error"] = exc
        with lock:
            if "error" not in box and not box.get("abandoned"):
                box["client"] = client
                return
        if client is not None:
            with contextlib.suppress(Exception):
                client.close()

    t = threading.Thread(target=make, name="myoface-batch-connect", daemon=True)
    t.start()
    while t.is_alive() and time.monotonic() < deadline and stop.signum is None:
        t.join(min(_POLL_S, max(deadline - time.monotonic(), 0)))
    with lock:
        if t.is_alive():
            box["abandoned"] = True
        phase, exc, client = box["phase"], box.get("error"), box.get("client")
    if stop.signum is not None:
        if client is not None:
            with contextlib.suppress(Exception):
                client.close()
        raise Interrupted(stop.signum)
    if client is not None:
        return client
    if phase == "workers" and (exc is None or isinstance(exc, TimeoutError)):
        raise MyofaceValueError(
            f"--scheduler: the Dask scheduler at {scheduler} has no worker after {timeout:g} s"
        )
    if exc is None:  # still waiting for its answer at the deadline
        raise MyofaceValueError(
            f"--scheduler: no Dask scheduler answered at {scheduler} within {timeout:g} s"
        )
    if phase == "workers":
        raise MyofaceValueError(
            f"--scheduler: the Dask scheduler at {scheduler} failed as batch waited for a "
            f"worker ({_error_text(exc)})"
        ) from None
    if isinstance(exc, ValueError):
        raise MyofaceValueError(f"--scheduler: not a scheduler address: {exc}") from None
    if isinstance(exc, MemoryError):  # a length read from another protocol's bytes
        raise MyofaceValueError(
            f"--scheduler: {scheduler} is not a Dask scheduler (its answer is not Dask's)"
        ) from None
    raise MyofaceValueError(
        f"--scheduler: no Dask scheduler answered at {scheduler} within {timeout:g} s "
        f"({_error_text(exc)})"
    ) from None


#: the most bytes a Dask scheduler's first message (its handshake) may announce: it is a few
#: hundred bytes; another protocol's greeting read as Dask's length is much more (an SSH
#: banner's "SSH-2.0-" reads as 3e18 bytes: distributed fails with MemoryError)
_MAX_HANDSHAKE_BYTES = 1 << 20


def _probe_scheduler(scheduler, host_port, timeout, deadline, stop) -> None:
    """Check, by ``deadline``, that the peer at ``host_port`` speaks first as a Dask
    scheduler does: on a new connection it sends its handshake, which starts with the
    8-byte little-endian length of what follows. A refused connection is tried again (the
    scheduler may be starting)."""
    import socket

    def left() -> float:
        return deadline - time.monotonic()

    def check_stop() -> None:
        if stop.signum is not None:
            raise Interrupted(stop.signum)

    why = ""
    while True:
        check_stop()
        if left() <= 0:
            raise MyofaceValueError(
                f"--scheduler: no Dask scheduler answered at {scheduler} within {timeout:g} s"
                f"{f' ({why})' if why else ''}"
            )
        try:
            sock = socket.create_connection(host_port, timeout=min(left(), 1.0))
            break
        except OSError as exc:  # refused, unreachable, a name not found, timed out
            why = " ".join((exc.strerror or str(exc) or type(exc).__name__).split())
            time.sleep(max(min(_POLL_S * 2, left()), 0))
    with sock:
        data = b""
        while len(data) < 8:
            check_stop()
            if left() <= 0:
                raise MyofaceValueError(
                    f"--scheduler: no Dask scheduler answered at {scheduler} within "
                    f"{timeout:g} s (it accepted the connection and sent nothing"
                    f"{f' but {data!r}' if data else ''})"
                )
            sock.settimeout(max(min(_POLL_S, left()), 0.001))
            try:
                chunk = sock.recv(256)
            except TimeoutError:
                continue
            except OSError as exc:
                raise MyofaceValueError(
                    f"--scheduler: {scheduler} is not a Dask scheduler (the connection "
                    f"failed before its answer: {exc.strerror or exc})"
                ) from None
            if not chunk:
                raise MyofaceValueError(
                    f"--scheduler: {scheduler} is not a Dask scheduler (it closed the "
                    f"connection{f' after sending {data!r}' if data else ' without a word'})"
                )
            data += chunk
        if int.from_bytes(data[:8], "little") > _MAX_HANDSHAKE_BYTES:
            sock.settimeout(0.05)  # the rest of a greeting line, to show it whole
            with contextlib.suppress(OSError):
                while len(data) < 80 and b"\n" not in data:
                    chunk = sock.recv(256)
                    if not chunk:
                        break
                    data += chunk
            shown = data[:80] + (b"..." if len(data) > 80 else b"")
            raise MyofaceValueError(
                f"--scheduler: {scheduler} is not a Dask scheduler (it answered {shown!r})"
            )


def start_local_cluster(workers: int):
    """A ``distributed.LocalCluster`` of ``workers`` single-threaded worker processes (its
    dashboard on a free port) and its client. Its processes start with SIGINT and SIGHUP
    blocked: a terminal's Ctrl-C and hang-up, sent to all of them, would print Dask's
    tracebacks; a stopped batch closes the cluster (:func:`_close_now`)."""
    import logging

    distributed = _require("distributed", "the dask engine")
    import dask

    # one video a worker at a time: Dask's default (worker-saturation 1.1) sends a worker of
    # one thread its next task while it runs one, and a task sent is one a stop may not cancel
    # in time; a video is seconds to minutes, so the scheduler's round trip costs nothing
    with (
        _signals_blocked(_TERMINAL_SIGNALS),
        dask.config.set({"distributed.scheduler.worker-saturation": 1.0}),
    ):
        cluster = distributed.LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",
            silence_logs=logging.CRITICAL,  # (its failures are in the rows; a stop is no error)
        )
        return cluster, distributed.Client(cluster)


async def _close_workers(workers, timeout: float) -> None:
    import asyncio

    await asyncio.gather(*(w.close(timeout=timeout) for w in workers), return_exceptions=True)


def _close_now(cluster) -> None:
    """Close the workers of ``cluster`` (a LocalCluster of a stopped batch) giving their
    tasks :data:`STOP_GRACE_S` to end, not the 4 s of Dask's default, before they are killed
    (a Dask task cannot be stopped)."""
    cluster.sync(_close_workers, list(cluster.workers.values()), STOP_GRACE_S)


def _run_dask(jobs: list[_Job], client, record, stop: _Stop) -> None:
    """Run ``jobs`` on the cluster of ``client``, calling ``record(k, row)`` as job ``k``
    finishes, until ``stop`` has a stop signal: then the videos not finished
    are cancelled (Dask does not stop a task that has started: on a cluster of the caller's,
    its video goes on and is complete for the next run)."""
    import uuid

    if stop.signum is not None:  # (it came as the cluster started)
        return
    for job in jobs:
        job.single_thread = True
    tag = uuid.uuid4().hex[:8]
    futs = {
        client.submit(analyze_job, job, key=f"myoface-batch-{tag}-{i}", pure=False, retries=0): i
        for i, job in enumerate(jobs)
    }
    pending = dict(futs)
    try:
        while pending and stop.signum is None:
            done = [f for f in pending if f.done()]
            if not done:
                time.sleep(_POLL_S)
            for fut in done:
                k = pending.pop(fut)
                if fut.status == "finished":
                    row = fut.result()
                else:  # the worker died (KilledWorker), myoface is missing there, ...
                    try:
                        exc = fut.exception()
                    except Exception as err:  # cancelled (e.g. by the cluster's owner)
                        exc = err
                    row = _failed_row(jobs[k], _error_text(exc))
                fut.release()
                if stop.signum is not None and row["status"] != "ok":
                    continue  # (stopped as the batch was, not failed: as _run_local)
                record(k, row)
    finally:
        if pending:
            client.cancel(list(pending))


# ------------------------------------------------------------------------------ summary


def _muscle_ids(rows: list[dict]) -> list[str]:
    ids: list[str] = []
    for r in rows:
        for k in r.get("means", {}):
            if k not in ids:
                ids.append(k)
    return ids


def write_summary(rows: list[dict], out: str | os.PathLike) -> tuple[Path, Path]:
    """``summary.parquet`` (pyarrow) and ``summary.csv`` in ``out``: one row per video,
    :data:`SUMMARY_COLUMNS` then ``mean_<muscle>``; each file written whole (a temporary name
    renamed). Returns their paths."""
    import csv

    pa = _require("pyarrow", "the batch summary")
    pq = _require("pyarrow.parquet", "the batch summary")

    out = Path(out)
    ids = _muscle_ids(rows)
    cols: dict[str, list] = {c: [r[c] for r in rows] for c in SUMMARY_COLUMNS}
    for k in ids:
        cols[f"mean_{k}"] = [r.get("means", {}).get(k, math.nan) for r in rows]
    types = {"frames": pa.int64()}
    for c in ("path", "folder", "status", "error"):
        types[c] = pa.string()
    table = pa.table(
        {c: pa.array(v, type=types.get(c, pa.float64())) for c, v in cols.items()},
        metadata={"myoface": "batch summary: one row per video"},
    )
    pq_path, csv_path = out / "summary.parquet", out / "summary.csv"
    with atomic_output(pq_path) as tmp:
        pq.write_table(table, tmp)
    with atomic_output(csv_path) as tmp:
        with open(tmp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(list(cols))
            for j in range(len(rows)):
                w.writerow([_csv_cell(cols[c][j]) for c in cols])
    return pq_path, csv_path


def _csv_cell(v) -> str:
    if isinstance(v, float):
        return "" if not math.isfinite(v) else f"{v:.6g}"
    return str(v)


# ------------------------------------------------------------------------------ the batch


def run_batch(
    videos,
    out: str | os.PathLike,
    *,
    engine: str = "local",
    workers: int | None = None,
    scheduler: str | None = None,
    client=None,
    executor=None,
    timeout: float = SCHEDULER_TIMEOUT_S,
    tracker: str = "snakes",
    init=None,
    calibration_frame: int | None = None,
    max_frames: int | None = None,
    refine: int | None = None,
    sigma: float | None = None,
    estimator: str | None = None,
    flow: bool = False,
    photometric: bool | None = None,
    face: str | os.PathLike | None = None,
    muscles: str | os.PathLike | None = None,
    show_progress: bool = False,
) -> list[dict]:
    """Analyse every video of ``videos`` (paths or glob patterns, see :func:`expand_videos`)
    into its folder under ``out`` and write the summary (module docstring).

    Parameters
    ----------
    engine : ``"local"`` or ``"dask"``.
    workers : processes (local) or LocalCluster workers (dask); default: the cores of this
        machine. Not used with ``scheduler`` or ``client``.
    scheduler : the address of a running Dask scheduler (``tcp://host:8786``) to use instead
        of a LocalCluster; ``timeout`` s, in all, for it to answer and have a worker.
    client : a ``distributed.Client`` to use (left open).
    executor : for the local engine, a ``concurrent.futures`` executor to use (left open),
        e.g. a :func:`local_pool` kept for several batches.
    tracker, init, calibration_frame, max_frames, refine, sigma, estimator, flow, photometric :
        as for ``myoface analyze`` (:func:`~myoface.analysis.outputs.analyze_to_folder`), the
        same for every video (``init``: one contour file or {section: (K, 2)} on the calibration
        frame, e.g. videos from one fixed camera).
    face, muscles : the face model (default: the bundled one); paths the workers can read.
    show_progress : a progress bar over the videos on stderr.

    Returns
    -------
    list of dict — the summary rows, in the order of ``videos``: the keys of
    :data:`SUMMARY_COLUMNS` and ``means`` ({muscle: mean contraction}).

    Raises
    ------
    Interrupted
        (a KeyboardInterrupt) after a stop signal, once the summary of the videos that
        finished is written (module docstring); its note says what was kept.
    MyofaceValueError
        For a bad argument, and for a ``scheduler`` that does not answer, is not a Dask
        scheduler or has no worker within ``timeout`` s (nothing is written then).
    """
    if engine not in ENGINES:
        raise MyofaceValueError(f"engine must be one of {ENGINES}; got {engine!r}")
    if tracker not in ("snakes", "landmarks"):
        raise MyofaceValueError(f"tracker must be 'snakes' or 'landmarks'; got {tracker!r}")
    if tracker == "snakes":
        allowed = ESTIMATORS
    else:  # the landmarks' own, or the snakes' names for their counterparts
        allowed = (*LANDMARK_ESTIMATORS, *ESTIMATORS)
    if estimator is not None and estimator not in allowed:
        raise MyofaceValueError(
            f"the {tracker} tracker's estimator must be one of {allowed}; got {estimator!r}"
        )
    if max_frames is not None and not (_is_int(max_frames) and max_frames >= 1):
        raise MyofaceValueError(f"max_frames must be an integer >= 1; got {max_frames!r}")
    if calibration_frame is not None and not (
        _is_int(calibration_frame) and calibration_frame >= 0
    ):
        raise MyofaceValueError(
            f"calibration_frame must be an integer >= 0; got {calibration_frame!r}"
        )
    if refine is not None and not (_is_int(refine) and refine >= 0):
        raise MyofaceValueError(f"refine must be an integer >= 0; got {refine!r}")
    if sigma is not None and not (
        isinstance(sigma, int | float) and not isinstance(sigma, bool) and 0 < sigma < math.inf
    ):
        raise MyofaceValueError(f"sigma must be a number of pixels > 0; got {sigma!r}")
    if not isinstance(flow, bool):
        raise MyofaceValueError(f"flow must be True or False; got {flow!r}")
    # what make_analyzer refuses, refused before any video is analysed
    if flow and tracker != "landmarks":
        raise MyofaceValueError(
            "--flow refines the landmark tracker's points; use it with --tracker landmarks"
        )
    if flow and estimator in ("paper", "fiducials"):
        raise MyofaceValueError("--flow is for the 3-D fit, not --estimator paper")
    # (resolved here: done.json records what ran)
    photometric = resolve_photometric(photometric, tracker, estimator)
    if workers is None:
        workers = os.cpu_count() or 1
    if not (_is_int(workers) and workers >= 1):
        raise MyofaceValueError(f"workers must be an integer >= 1; got {workers!r}")
    if not (
        isinstance(timeout, int | float)
        and not isinstance(timeout, bool)
        and 0 < timeout < math.inf
    ):
        raise MyofaceValueError(f"timeout must be a number of seconds > 0; got {timeout!r}")
    if (scheduler is not None or client is not None) and engine != "dask":
        raise MyofaceValueError("a Dask scheduler or client needs engine='dask'")
    if executor is not None and engine != "local":
        raise MyofaceValueError("an executor is for engine='local'")
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise MyofaceValueError(f"-o: {out} exists and is not a folder")
    _require("pyarrow.parquet", "the batch summary")  # (loaded now: not when a stop is due)
    if engine == "dask":
        _require("distributed", "the dask engine")
    if muscles is not None and face is None:
        raise MyofaceValueError("muscles needs face (the bundled face has its own muscles)")
    for what, p in (("face", face), ("muscles", muscles)):
        if p is not None and str(p) != "default" and not Path(p).exists():
            raise MyofaceFileNotFoundError(f"no such {what} file: {p}")
    face_s = None if face is None or str(face) == "default" else str(Path(face).resolve())
    muscles_s = None if muscles is None else str(Path(muscles).resolve())
    init_sha = None
    if init is not None:
        if tracker == "landmarks":
            raise MyofaceValueError("--init is for the snakes; the landmark tracker needs none")
        if isinstance(init, str | os.PathLike):
            init_sha = sha256_file(init) if Path(init).is_file() else None
            init = load_init(init)
        else:
            import hashlib

            import numpy as np

            h = hashlib.sha256()
            for k in sorted(init):
                h.update(k.encode() + np.ascontiguousarray(init[k], dtype=np.float64).tobytes())
            init_sha = h.hexdigest()
    settings = {
        "tracker": tracker,
        "estimator": estimator,
        "max_frames": max_frames,
        "init_sha256": init_sha,
        "face": face_s,
        "muscles": muscles_s,
        "calibration_frame": calibration_frame,
        "refine": refine,
        "sigma": None if sigma is None else float(sigma),
        "flow": flow,
        "photometric": photometric,
    }

    paths = expand_videos([videos] if isinstance(videos, str | os.PathLike) else videos, out)
    own: list = []  # the client / cluster this call opened, closed at the end
    cluster = None
    rows: dict[int, dict] = {}
    with _noted_stop_signals() as stop, contextlib.ExitStack() as closing:
        closing.callback(lambda: [thing.close() for thing in reversed(own)])
        if engine == "dask" and client is None and scheduler is not None:
            # fail (or stop) before anything is written
            client = connect(scheduler, timeout, _stop=stop)
            own.append(client)
        out = ensure_output_dir(out)
        names = result_folders(paths, out)
        todo: list[tuple[int, _Job]] = []
        for i, (p, name) in enumerate(zip(paths, names, strict=True)):
            done = _is_done(out / name, p, settings)
            if done is not None:
                rows[i] = {**done, "path": str(p), "folder": name, "status": "skipped"}
            else:
                todo.append((i, _Job(str(p), str(out), name, settings, init)))
        bar = progress(None, len(paths), desc="videos", enabled=show_progress, unit="video")
        bar.update(len(rows))  # the skipped ones

        def record(k: int, row: dict) -> None:
            rows[todo[k][0]] = row
            bar.update()

        try:
            jobs = [j for _, j in todo]
            if jobs and stop.signum is None and engine == "local":
                _run_local(jobs, workers, record, stop, closing, executor)
            elif jobs and stop.signum is None:
                if client is None:
                    cluster, client = start_local_cluster(min(workers, len(jobs)))
                    own += [cluster, client]
                _run_dask(jobs, client, record, stop)
        finally:
            bar.close()
            signum = stop.signum
            if signum is not None:
                # a stop signal: the cluster this call started goes first (its workers
                # killed), then every video that finished is summarised, those whose row
                # did not come back (killed once finished) from their done.json
                for thing in reversed(own):
                    with contextlib.suppress(Exception):
                        if thing is cluster:
                            _close_now(cluster)
                        thing.close()
                own.clear()
                for i, (p, name) in enumerate(zip(paths, names, strict=True)):
                    if i not in rows and (row := _is_done(out / name, p, settings)) is not None:
                        rows[i] = {**row, "path": str(p), "folder": name}
            # what is known so far (all of it, unless interrupted)
            write_summary([rows[i] for i in sorted(rows)], out)
        if signum is not None:
            n = {s: sum(r["status"] == s for r in rows.values()) for s in STATUSES}
            exc = Interrupted(signum)
            exc.add_note(
                f"{len(paths)} videos: {n['ok']} analysed, {n['skipped']} already done, "
                f"{n['failed']} failed, {len(paths) - len(rows)} not finished (run the same "
                f"command again to resume); summary: {out.resolve() / 'summary.csv'}"
            )
            raise exc
    return [rows[i] for i in range(len(paths))]
