"""Small I/O helpers shared by the library and the CLI."""

from __future__ import annotations

import contextlib
import hashlib
import os
import shutil
import tempfile
from collections.abc import Iterator
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
