"""Small I/O helpers shared by the library and the CLI."""

from __future__ import annotations

import contextlib
import hashlib
import os
import tempfile
from collections.abc import Iterator
from pathlib import Path

from myoface.errors import MyofaceValueError


def check_output_path(path: str | os.PathLike) -> Path:
    """``path`` as a Path, once its folder is known to exist and be writable (else a clear
    :class:`MyofaceValueError`), so long work can fail before it starts."""
    path = Path(path)
    parent = path.parent if str(path.parent) else Path(".")
    if not parent.is_dir():
        raise MyofaceValueError(f"output folder does not exist: {parent}")
    if not os.access(parent, os.W_OK):
        raise MyofaceValueError(f"output folder is not writable: {parent}")
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


def ensure_output_dir(path: str | os.PathLike) -> Path:
    """Create the output folder ``path`` (and parents) or fail with a clear message."""
    path = Path(path)
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise MyofaceValueError(f"cannot create output folder {path}: {exc.strerror}") from exc
    if not os.access(path, os.W_OK):
        raise MyofaceValueError(f"output folder is not writable: {path}")
    return path


def sha256_file(path: str | os.PathLike) -> str:
    """SHA-256 (hex) of a file's bytes, read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
