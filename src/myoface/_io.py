"""Small I/O helpers shared by the library and the CLI.

A command's outputs are never half written and never lose a user's earlier results:

- one file: :func:`atomic_output` (a temporary name beside it, renamed when complete);
- a folder of results: :func:`output_transaction` (a fresh folder beside it, put in its place
  in one step when the run succeeds, or is interrupted with what it completed), which also
  holds the folder's lock (:func:`output_lock`: one writer per folder);
- no output on an input: :func:`check_not_input`.
"""

from __future__ import annotations

import contextlib
import errno
import fnmatch
import functools
import hashlib
import json
import os
import shutil
import sys
import tempfile
import threading
import warnings
from collections.abc import Iterable, Iterator
from pathlib import Path

from myoface.errors import MyofaceFileNotFoundError, MyofaceFormatError, MyofaceValueError


def _label(what: str) -> str:
    return f"{what}: " if what else ""


def check_output_path(path: str | os.PathLike, what: str = "") -> Path:
    """``path`` as a Path, once it is known to be a file name (not an existing folder) in a
    folder that exists and is writable (else a clear :class:`MyofaceValueError`, prefixed by
    ``what``, e.g. ``"-o"``), so long work can fail before it starts."""
    path = Path(path)
    if str(path) in ("", ".") or path.name in ("", ".", ".."):
        raise MyofaceValueError(f"{_label(what)}expected a file name; got {str(path)!r}")
    if path.is_dir():
        raise MyofaceValueError(f"{_label(what)}{path} is an existing folder; expected a file name")
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise MyofaceValueError(f"{_label(what)}output folder does not exist: {parent}")
    if not os.access(parent, os.W_OK):
        raise MyofaceValueError(f"{_label(what)}output folder is not writable: {parent}")
    return path


def check_output_dir(path: str | os.PathLike, what: str = "") -> Path:
    """``path`` as a Path, once it is known that it can be used as an output folder: an existing
    writable folder, or a new one whose nearest existing ancestor is a writable folder. Creates
    nothing (see :func:`output_dir`)."""
    path = Path(path)
    if path.exists():
        if not path.is_dir():
            raise MyofaceValueError(f"{_label(what)}{path} exists and is not a folder")
        if not os.access(path, os.W_OK):
            raise MyofaceValueError(f"{_label(what)}output folder is not writable: {path}")
        return path
    anc = path.absolute().parent
    while not anc.exists():
        anc = anc.parent
    if not anc.is_dir():
        raise MyofaceValueError(f"{_label(what)}cannot create {path}: {anc} is not a folder")
    if not os.access(anc, os.W_OK):
        raise MyofaceValueError(f"{_label(what)}cannot create {path}: {anc} is not writable")
    return path


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike, *, suffix: str | None = None) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it to ``path`` only if the block succeeds.

    A crash, an exception or Ctrl-C inside the block leaves no half-written ``path`` behind.
    The temporary name keeps ``path``'s suffix (or ``suffix``) so format-sniffing writers
    (imageio, matplotlib) still pick the right format.

    Raises
    ------
    MyofaceValueError
        If the parent folder does not exist or is not writable.
    """
    path = check_output_path(path)
    parent = path.parent
    sfx = suffix if suffix is not None else path.suffix
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".part{sfx}", dir=parent)
    os.close(fd)
    tmp_path = Path(tmp)
    # mkstemp makes the file private (0600); a finished output gets the usual permissions
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp_path, 0o666 & ~umask)
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def ensure_output_dir(path: str | os.PathLike, what: str = "") -> Path:
    """Create the output folder ``path`` (and parents) or fail with a clear message."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise MyofaceValueError(
            f"{_label(what)}cannot create output folder {path}: {exc.strerror}"
        ) from exc
    if not os.access(path, os.W_OK):
        raise MyofaceValueError(f"{_label(what)}output folder is not writable: {path}")
    return path


def _first_missing(path: Path) -> Path | None:
    """The outermost folder of ``path`` that does not exist yet (None if ``path`` exists)."""
    top = None
    for p in (path.absolute(), *path.absolute().parents):
        if p.exists():
            break
        top = p
    return top


@contextlib.contextmanager
def output_dir(path: str | os.PathLike, what: str = "") -> Iterator[Path]:
    """Create the output folder ``path`` (and its missing parents) for the block; if the block
    fails, remove the folders this call created, with their content. Folders that existed
    before are left in place."""
    path = Path(path)
    top = _first_missing(path)
    out = ensure_output_dir(path, what)
    try:
        yield out
    except BaseException:
        if top is not None:
            shutil.rmtree(top, ignore_errors=True)
        raise


class OutputSet:
    """The outputs a command writes, so that a failure removes those it created.

    >>> with OutputSet() as outs:           # doctest: +SKIP
    ...     write_image(outs.add(path), img)
    """

    def __init__(self) -> None:
        self._new: list[Path] = []

    def add(self, path: str | os.PathLike) -> Path:
        """Register ``path`` before writing it; returns it as a Path."""
        p = Path(path)
        top = _first_missing(p)
        if top is not None:
            self._new.append(top)
        return p

    def __enter__(self) -> OutputSet:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            return
        for p in reversed(self._new):
            if p.is_dir() and not p.is_symlink():
                shutil.rmtree(p, ignore_errors=True)
            elif p.exists() or p.is_symlink():
                with contextlib.suppress(OSError):
                    p.unlink()


def read_text(path: str | os.PathLike, what: str = "file") -> str:
    """The UTF-8 text of ``path``; a :class:`MyofaceFormatError` naming the file (and ``what``
    it should be) when it is not UTF-8 text, a :class:`MyofaceFileNotFoundError` when it is
    missing."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        raise MyofaceFileNotFoundError(f"no such {what}: {p}") from None
    except IsADirectoryError:
        raise MyofaceValueError(f"{what} {p} is a folder; expected a file") from None
    except OSError as exc:
        raise MyofaceValueError(f"cannot read {what} {p}: {exc.strerror}") from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        raise MyofaceFormatError(
            f"{p}: not UTF-8 text (byte 0x{data[exc.start]:02x} at offset {exc.start}); "
            f"expected a UTF-8 {what}"
        ) from None
    if "\x00" in text:
        raise MyofaceFormatError(f"{p}: a binary file (NUL bytes); expected a UTF-8 {what}")
    return text


def parse_json(text: str, source: str):
    """``json.loads(text)``; any failure (bad syntax, an integer of thousands of digits, nesting
    too deep) is a :class:`MyofaceFormatError` naming ``source``."""
    import json

    try:
        return json.loads(text)
    except (ValueError, RecursionError) as exc:
        raise MyofaceFormatError(f"{source}: cannot parse: not valid JSON: {_short(exc)}") from None


def parse_toml(text: str, source: str) -> dict:
    """``tomllib.loads(text)``; any failure is a :class:`MyofaceFormatError` naming ``source``."""
    import tomllib

    try:
        return tomllib.loads(text)
    except (ValueError, RecursionError) as exc:
        raise MyofaceFormatError(
            f"{source}: cannot parse: not a valid TOML file: {_short(exc)}"
        ) from None


def _short(exc: BaseException, n: int = 200) -> str:
    text = " ".join(str(exc).split())
    return text if len(text) <= n else text[: n - 3] + "..."


def sha256_file(path: str | os.PathLike) -> str:
    """SHA-256 (hex) of a file's bytes, read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


# ------------------------------------------------------------------ outputs that are inputs


class OutputConflictError(MyofaceValueError):
    """An output that cannot be written as asked: it is one of the command's inputs, lies
    inside an input folder, or another run is writing the folder. A usage error: the commands
    say it in one line and exit with :attr:`exit_status` 2, before any work."""

    exit_status = 2


class OutputBusyError(OutputConflictError):
    """Another run holds the output folder's lock (:func:`output_lock`); ``holder`` is what
    its lock file says (pid, host, command, started)."""

    def __init__(self, message: str, holder: dict | None = None):
        super().__init__(message)
        self.holder = dict(holder or {})


def _real(path) -> Path:
    return Path(os.path.realpath(os.fspath(path)))


def _same_file(a: Path, b: Path) -> bool:
    if a == b:
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def check_not_input(output, inputs: dict, what: str = "-o", *, names: Iterable[str] = ()) -> None:
    """Refuse (:class:`OutputConflictError`) an output that would be written over one of the
    command's inputs or into one: ``output`` is an input (the same path once links are
    resolved, or the same file), lies inside an input folder (its files would be read as
    input), or, for an output folder that the run writes the files ``names`` into, one of
    those files is an input.

    Parameters
    ----------
    output : the output file or folder (``-o``).
    inputs : ``{what it is: path}``, e.g. ``{"the input video": "clip.mp4"}``; None paths
        are skipped.
    what : the option's name, which the message starts with.
    names : the file names the run writes into the output folder.
    """
    out = _real(output)
    shown = f"{what} {os.fspath(output)}" if what else os.fspath(output)
    for label, given in inputs.items():
        if given is None:
            continue
        src = _real(given)
        if _same_file(out, src):
            raise OutputConflictError(
                f"{shown} is {label} ({os.fspath(given)}); a command never writes over its "
                "input: give another output"
            )
        if src.is_dir() and src in out.parents:
            raise OutputConflictError(
                f"{shown} is inside {label} ({os.fspath(given)}): outputs never go inside "
                "the input (they would be read as input); give a folder outside it"
            )
        for name in names:
            if _same_file(out / name, src):
                raise OutputConflictError(
                    f"{shown}: its {name} would be written over {label} "
                    f"({os.fspath(given)}); give another output folder"
                )


# ------------------------------------------------------------------ one writer per folder

#: the lock file an output folder holds while a run writes it (:func:`output_lock`)
LOCK_NAME = ".myoface.lock"

_held_locks: dict[tuple, list] = {}  # this process's: (real folder, thread) -> [lock, depth]


class OutputLock:
    """A held output folder lock (:func:`acquire_lock`): ``path`` the lock file, ``holder``
    what it says."""

    def __init__(self, folder: Path, path: Path, holder: dict, fd: int):
        self.folder, self.path, self.holder, self._fd = folder, path, holder, fd

    def _write(self) -> None:
        data = json.dumps(self.holder).encode()
        os.ftruncate(self._fd, 0)
        os.pwrite(self._fd, data, 0)

    def note(self, **items) -> None:
        """Add ``items`` to what the lock file says (e.g. the folder being written into)."""
        self.holder.update(items)
        with contextlib.suppress(OSError):
            self._write()


def _holder_record(command: str | None) -> dict:
    import datetime
    import shlex
    import socket

    if command is None:
        command = shlex.join([Path(sys.argv[0]).name or "python", *sys.argv[1:]])
    return {
        "pid": os.getpid(),
        "host": socket.gethostname(),
        "command": command,
        "started": datetime.datetime.now().astimezone().isoformat(timespec="seconds"),
    }


def _read_holder(fd: int) -> dict:
    try:
        data = os.pread(fd, 1 << 16, 0)
        doc = json.loads(data.decode("utf-8"))
    except (OSError, ValueError):
        return {}
    return doc if isinstance(doc, dict) else {}


def _describe_holder(h: dict) -> str:
    if not h:
        return "a run whose lock file cannot be read"
    return (
        f"pid {h.get('pid', '?')} on {h.get('host', '?')}, {h.get('command', '?')!r}, "
        f"since {h.get('started', '?')}"
    )


def _pid_alive(pid) -> bool:
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return False
    except (PermissionError, OverflowError):
        return True  # (someone else's process)
    except (TypeError, ValueError):
        return False
    return True


def _flock(fd: int) -> bool | None:
    """Lock the open file ``fd`` (``flock``, exclusive, without waiting): True, False when
    another open file holds it, None where the file system cannot lock."""
    import fcntl

    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        return False
    except OSError as exc:
        if exc.errno in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOTSUP, errno.EINVAL, errno.ENOSYS):
            return None
        raise
    return True


def acquire_lock(folder, command: str | None = None, what: str = "-o", *, shown=None) -> OutputLock:
    """Take the lock of the output folder ``folder`` (it must exist) for this process: the
    file :data:`LOCK_NAME` in it, saying who holds it (pid, host, ``command`` -- default this
    process's command line -- and start time), locked (``flock``) while the run lasts, so
    the kernel frees it when the holder dies however it dies. The same thread may take it
    again (it is counted); :func:`release_lock` gives it back.

    A lock left by a run that is gone (the lock free, and its pid dead on this host) is taken
    over with a :class:`~myoface.errors.MyofaceWarning`. Where the file system cannot
    ``flock``, the pid alone says it (and two runs taking over the same dead run's lock at
    the same instant may both get it). The messages name the folder as ``shown`` (default
    ``folder``), prefixed by ``what``.

    Raises
    ------
    OutputBusyError
        When another run holds it (the message names it), or its lock cannot be checked
        (another host's run, a lock file that cannot be read): the message says which file to
        delete if that run is over.
    """
    import socket

    from myoface.errors import MyofaceWarning

    real = _real(folder)
    key = (real, threading.get_ident())
    held = _held_locks.get(key)
    if held is not None:
        held[1] += 1
        return held[0]
    path = real / LOCK_NAME
    folder = Path(folder if shown is None else shown)
    shown = folder / LOCK_NAME
    me = _holder_record(command)
    data = json.dumps(me).encode()
    host = socket.gethostname()
    for _ in range(50):
        # a complete lock file appears under its name in one step (written, locked, linked)
        fd, tmp = tempfile.mkstemp(prefix=f"{LOCK_NAME}.", suffix=".part", dir=real)
        linked = False
        try:
            os.write(fd, data)
            _flock(fd)
            try:
                os.link(tmp, path)
                linked = True
            except FileExistsError:
                pass
            except OSError:  # no hard links here: an exclusive create
                os.close(fd)
                fd = -1
                with contextlib.suppress(FileExistsError):
                    fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o644)
                    _flock(fd)
                    os.write(fd, data)
                    linked = True
        except BaseException:
            if fd >= 0:
                os.close(fd)
            raise
        finally:
            os.unlink(tmp)
        if linked:
            lock = OutputLock(real, path, me, fd)
            _held_locks[key] = [lock, 1]
            return lock
        if fd >= 0:
            os.close(fd)
        try:  # someone's lock: held, or left by a run that is gone
            fd = os.open(path, os.O_RDWR)
        except FileNotFoundError:
            continue  # given back meanwhile
        free = _flock(fd)
        holder = _read_holder(fd)
        if free is False:
            os.close(fd)
            raise OutputBusyError(
                f"{what} {folder}: another run is writing this folder "
                f"({_describe_holder(holder)}); wait for it to finish or give another folder",
                holder,
            )
        try:
            current = os.stat(path).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            current = False
        if not current:  # given back and taken again meanwhile: look again
            os.close(fd)
            continue
        if holder:
            gone = holder.get("host") == host and not _pid_alive(holder.get("pid"))
        else:  # (unreadable: a run killed as it wrote it, if the lock is free)
            gone = free is True
        if not gone:
            os.close(fd)
            if not holder:
                why = "a lock file that cannot be read"
            elif holder.get("host") != host:
                why = f"the lock of a run on another host ({_describe_holder(holder)})"
            else:
                why = f"the lock of a process that runs ({_describe_holder(holder)})"
            raise OutputBusyError(
                f"{what} {folder}: it holds {why}; if no run is writing it, delete {shown}",
                holder,
            )
        lock = OutputLock(real, path, me, fd)
        lock._write()
        _held_locks[key] = [lock, 1]
        warnings.warn(
            f"{shown}: took over the lock of a run that is gone ({_describe_holder(holder)})",
            MyofaceWarning,
            stacklevel=2,
        )
        return lock
    raise OutputBusyError(f"{what} {folder}: its lock keeps changing hands; try again")


def release_lock(lock: OutputLock) -> None:
    """Give back a lock of :func:`acquire_lock` (the file is removed when this process took
    it as often as it gives it back)."""
    key = (lock.folder, threading.get_ident())
    held = _held_locks.get(key)
    if held is None or held[0] is not lock:
        return
    held[1] -= 1
    if held[1] > 0:
        return
    del _held_locks[key]
    try:
        with contextlib.suppress(FileNotFoundError):
            if os.stat(lock.path).st_ino == os.fstat(lock._fd).st_ino:
                os.unlink(lock.path)
    finally:
        os.close(lock._fd)


def live_folder(folder) -> Path | None:
    """Where a run of :func:`output_transaction` writing the output folder ``folder`` is
    writing its files now (its temporary folder, named in the folder's lock file), or None
    when no run is: e.g. to follow a long analysis' contractions.csv as its rows come."""
    try:
        doc = json.loads((Path(folder) / LOCK_NAME).read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    where = doc.get("writing") if isinstance(doc, dict) else None
    return Path(where) if isinstance(where, str) and Path(where).is_dir() else None


@contextlib.contextmanager
def output_lock(folder, command: str | None = None, what: str = "-o") -> Iterator[OutputLock]:
    """The lock of the output folder ``folder`` for the block (:func:`acquire_lock`)."""
    lock = acquire_lock(folder, command, what)
    try:
        yield lock
    finally:
        release_lock(lock)


# ------------------------------------------------------------------ a folder as one transaction

#: the temporary folders of :func:`output_transaction`: ``.NAME.myoface-run-XXXXXXXX`` beside
#: the output folder ``NAME`` (or ``.myoface-run-XXXXXXXX`` inside it, where its parent is
#: not writable)
STAGING_MARK = ".myoface-run-"
_AT_FDCWD = -100
_RENAME_EXCHANGE = 2


@functools.cache
def _renameat2():
    """libc's ``renameat2`` (Linux), or None."""
    if not sys.platform.startswith("linux"):
        return None
    import ctypes

    try:
        fn = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint]
    fn.restype = ctypes.c_int
    return fn


def exchange_paths(a, b) -> None:
    """Swap what the names ``a`` and ``b`` (on one file system) refer to, in one step: no
    moment, not even a crash, sees neither or both (Linux's ``renameat2(RENAME_EXCHANGE)``).
    An :class:`OSError` where that is not supported (``ENOSYS`` off Linux)."""
    import ctypes

    fn = _renameat2()
    if fn is None:
        raise OSError(errno.ENOSYS, "renameat2 is not available", os.fspath(a))
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) != 0:
        code = ctypes.get_errno()
        raise OSError(code, os.strerror(code), os.fspath(a), None, os.fspath(b))


_exchange_works: dict[int, bool] = {}  # st_dev -> whether exchange_paths works there


def _can_exchange(folder: Path) -> bool:
    """Whether the output folder ``folder`` (resolved) can be replaced by one beside it in one
    step: its parent writable, on the same file system (not a mount point), folders
    exchangeable there, and not this process's working folder or above it (a shell in it
    would be left in a removed folder)."""
    parent = folder.parent
    if parent == folder or not os.access(parent, os.W_OK | os.X_OK):
        return False
    try:
        dev = os.stat(folder).st_dev
        if os.stat(parent).st_dev != dev:
            return False
        cwd = Path(os.getcwd())
    except OSError:
        return False
    if cwd == folder or folder in cwd.parents:
        return False
    if dev not in _exchange_works:
        a = b = None
        try:
            a = tempfile.mkdtemp(prefix=f".{folder.name}{STAGING_MARK}", dir=parent)
            b = tempfile.mkdtemp(prefix=f".{folder.name}{STAGING_MARK}", dir=parent)
            exchange_paths(a, b)
            _exchange_works[dev] = True
        except OSError:
            _exchange_works[dev] = False
        finally:
            for p in (a, b):
                if p is not None:
                    with contextlib.suppress(OSError):
                        os.rmdir(p)
    return _exchange_works[dev]


def _owned_patterns(owned: Iterable[str]) -> tuple[str, ...]:
    """The names of ``owned`` and their temporaries (:func:`atomic_output`'s ``.STEM.*.part*``)."""
    pats = []
    for name in owned:
        pats.append(name)
        stem = Path(name).stem
        pats.append(f".{stem}.*.part*")
    return tuple(pats)


def _is_ours(name: str) -> bool:
    """A name a run of :func:`output_transaction` uses for itself in a folder (the lock, its
    temporaries, an in-place staging folder)."""
    return (
        name == LOCK_NAME
        or (name.startswith(f"{LOCK_NAME}.") and name.endswith(".part"))
        or name.startswith(STAGING_MARK)
    )


def _remove(path: Path) -> None:
    if path.is_dir() and not path.is_symlink():
        shutil.rmtree(path)
    else:
        with contextlib.suppress(FileNotFoundError):
            path.unlink()


def _rescue(old: Path, folder: Path, patterns) -> None:
    """Move from the folder ``old`` (a staging folder, or the earlier folder after the
    exchange) into ``folder`` every entry that is the user's (not a run's output, not the
    lock) and is not in ``folder`` already; then remove ``old``."""
    with contextlib.suppress(FileNotFoundError):
        for name in os.listdir(old):
            if _is_ours(name) or any(fnmatch.fnmatchcase(name, p) for p in patterns):
                continue
            if not os.path.lexists(folder / name):
                with contextlib.suppress(OSError):
                    os.rename(old / name, folder / name)
    shutil.rmtree(old, ignore_errors=True)


def clean_leftovers(folder, owned: Iterable[str]) -> list[Path]:
    """Remove what runs of :func:`output_transaction` on ``folder`` left when they were killed
    (SIGKILL, a power cut): their staging folders beside it (``.NAME.myoface-run-*``) and in
    it, and lock temporaries. A user's file found in one (moved there in the instant before
    the killed run's exchange) is put back in ``folder`` first. Call it holding the folder's
    lock (:func:`output_transaction` does). Returns the paths removed."""
    real = _real(folder)
    patterns = _owned_patterns(owned)
    gone = []
    prefix = f".{real.name}{STAGING_MARK}"
    with contextlib.suppress(FileNotFoundError):
        for name in os.listdir(real.parent):
            p = real.parent / name
            if name.startswith(prefix) and p.is_dir() and not p.is_symlink():
                _rescue(p, real, patterns)
                gone.append(p)
    with contextlib.suppress(FileNotFoundError):
        for name in os.listdir(real):
            if _is_ours(name) and name != LOCK_NAME:
                _remove(real / name)
                gone.append(real / name)
    return gone


class OutputTransaction:
    """An output folder being written as one transaction (:func:`output_transaction`).

    Attributes
    ----------
    target : Path -- the output folder, as given.
    path : Path -- the fresh folder to write the run's files into.
    committed : bool -- whether :meth:`commit` put them in place.
    exchange : bool -- whether the commit is one step (else file by file, see
        :func:`output_transaction`).
    """

    def __init__(self, target: Path, real: Path, owned, lock: OutputLock):
        self.target = target
        self._real = real
        self._patterns = _owned_patterns(owned)
        self._lock = lock
        self.committed = False
        self.exchange = _can_exchange(real)
        if self.exchange:
            self.path = Path(
                tempfile.mkdtemp(prefix=f".{real.name}{STAGING_MARK}", dir=real.parent)
            )
        else:
            self.path = Path(tempfile.mkdtemp(prefix=STAGING_MARK, dir=real))
        lock.note(writing=str(self.path))

    def final(self, path) -> Path:
        """Where ``path`` (in :attr:`path`) is once committed (in :attr:`target`)."""
        return self.target / Path(path).relative_to(self.path)

    def _owned(self, name: str) -> bool:
        return any(fnmatch.fnmatchcase(name, p) for p in self._patterns)

    def commit(self) -> None:
        """Put the files written into :attr:`path` in place of the earlier run's: those of the
        owned names it did not write are removed, every other file of the folder stays. Once
        only; stop signals wait until it is done (:func:`myoface._signals.deferred`)."""
        from myoface._signals import deferred

        if self.committed:
            raise MyofaceValueError(f"{self.target}: the outputs were committed already")
        with deferred():
            if self.exchange:
                try:
                    os.link(self._real / LOCK_NAME, self.path / LOCK_NAME)
                except OSError:  # no hard links here (or no lock file): file by file
                    self.exchange = False
            if self.exchange:
                self._commit_exchange()
            else:
                self._commit_in_place()
            self.committed = True

    def _commit_exchange(self) -> None:
        new, folder = self.path, self._real
        made = set(os.listdir(new))
        moved = []
        try:
            # the user's files come along: hard links (the same files), folders moved
            for name in os.listdir(folder):
                if name in made or _is_ours(name) or self._owned(name):
                    continue
                src, dst = folder / name, new / name
                try:
                    if src.is_dir() and not src.is_symlink():
                        os.rename(src, dst)
                        moved.append(name)
                        continue
                    try:
                        os.link(src, dst, follow_symlinks=False)
                    except OSError as exc:
                        if exc.errno == errno.ENOENT:
                            raise
                        os.rename(src, dst)  # (a link refused: the file itself)
                        moved.append(name)
                except FileNotFoundError:
                    continue  # (removed meanwhile)
            with contextlib.suppress(OSError):
                shutil.copystat(folder, new)  # the folder's permissions, times, attributes
                st = os.stat(folder)
                if (st.st_uid, st.st_gid) != (os.stat(new).st_uid, os.stat(new).st_gid):
                    os.chown(new, st.st_uid, st.st_gid)
            exchange_paths(new, folder)  # the commit
        except BaseException:
            for name in moved:
                with contextlib.suppress(OSError):
                    os.rename(new / name, folder / name)
            raise
        # ``new`` names the earlier folder now: what the user put there meanwhile comes over
        _rescue(new, folder, self._patterns)

    def _commit_in_place(self) -> None:
        new, folder = self.path, self._real
        made = os.listdir(new)
        for name in made:
            dst = folder / name
            if dst.is_dir() and not dst.is_symlink():
                shutil.rmtree(dst)
            os.replace(new / name, dst)
        for name in os.listdir(folder):
            if name not in made and not _is_ours(name) and self._owned(name):
                _remove(folder / name)
        shutil.rmtree(new, ignore_errors=True)

    def _discard(self) -> None:
        shutil.rmtree(self.path, ignore_errors=True)


def _retarget(exc: BaseException, staging: Path, target: Path) -> BaseException | None:
    """Make the message of ``exc`` (raised while writing into ``staging``) name ``target``,
    where the user looks for the files, instead of the temporary folder: ``exc`` changed, or
    (an OSError whose file names cannot be set, e.g. PyAV's) a new OSError to raise instead."""
    from myoface.errors import MyofaceError

    old, new = str(staging), str(target)

    def moved(v):
        if isinstance(v, str) and (v == old or v.startswith(old + os.sep)):
            return new + v[len(old) :]
        return v

    if isinstance(exc, OSError):
        names = (exc.filename, exc.filename2)
        fixed = tuple(moved(v) for v in names)
        if fixed == names:
            return None
        try:
            exc.filename, exc.filename2 = fixed
        except (AttributeError, TypeError):
            return OSError(exc.errno, exc.strerror or str(exc), fixed[0], None, fixed[1])
    elif isinstance(exc, MyofaceError) and len(exc.args) == 1 and isinstance(exc.args[0], str):
        exc.args = (exc.args[0].replace(old, new),)
    return None


@contextlib.contextmanager
def output_transaction(
    folder,
    owned: Iterable[str],
    *,
    what: str = "-o",
    inputs: dict | None = None,
    command: str | None = None,
) -> Iterator[OutputTransaction]:
    """Write a run's files into the output folder ``folder`` as one transaction.

    The block writes into ``tx.path``, a fresh folder beside ``folder`` (the same file
    system). When the block ends without an error, its files replace the earlier run's in
    one step (:meth:`OutputTransaction.commit`; the block may call it itself, e.g. to keep
    what an interrupted run completed before it raises the interruption again): of the names
    ``owned`` (every file such a run may write), those the run wrote replace the earlier
    ones and the others are removed, so the folder describes one run; every other file in
    the folder (the user's) stays as it is. When the block fails (an error, an interruption
    it did not commit), nothing in ``folder`` changes: the earlier results stay byte for
    byte, and the folders this call created are removed.

    While the block runs, the folder's lock (:func:`output_lock`) says who writes it, and a
    second run is refused; what runs killed outright left beside the folder is cleaned up
    first (:func:`clean_leftovers`), so a leftover temporary folder lasts until the next run
    into the same folder.

    One step: on Linux the new folder and the old are exchanged (``renameat2``) after the
    user's files are hard-linked (folders: moved) into the new one; a crash at any moment
    leaves the old results or the new ones, never a mix. Where that cannot be done (another
    system or file system, a parent folder that is not writable, a mount point, hard links
    refused, or ``folder`` is the working folder, which a shell may be in), the files are
    moved in one by one: a failure still changes nothing, but a crash in that moment (well
    under a second) can leave a mix.

    Parameters
    ----------
    folder : the output folder; created with its parents when missing.
    owned : the file names a run of this kind writes into it.
    what : the option that named it (``"-o"``), for the messages.
    inputs : ``{what it is: path}`` of the run's inputs: an output folder that is one of
        them, inside one, or whose ``owned`` files would write over one is refused
        (:func:`check_not_input`).
    command : the command line the lock file names (default: this process's).

    Raises
    ------
    OutputConflictError
        For an input as the output (see above); :class:`OutputBusyError` when another run
        holds the folder.
    MyofaceValueError
        When ``folder`` is a file or cannot be created.
    """
    target = Path(folder)
    if inputs:
        check_not_input(target, inputs, what, names=owned)
    check_output_dir(target, what)
    real = _real(target)
    top = _first_missing(real)
    ensure_output_dir(real, what)
    tx = None
    try:
        lock = acquire_lock(real, command, what, shown=target)
    except BaseException:
        if top is not None:
            shutil.rmtree(top, ignore_errors=True)
        raise
    try:
        clean_leftovers(real, owned)
        tx = OutputTransaction(target, real, owned, lock)
        try:
            yield tx
            if not tx.committed:
                tx.commit()
        except BaseException as exc:
            again = _retarget(exc, tx.path, target)
            if again is not None:
                raise again from exc
            raise
    finally:
        try:
            if tx is not None and not tx.committed:
                tx._discard()
            if top is not None and (tx is None or not tx.committed):
                shutil.rmtree(top, ignore_errors=True)  # (its lock file with it)
        finally:
            release_lock(lock)
