"""``myoface bench``: user-facing benchmarks, with stable names, units and a JSON record
(:class:`BenchRecord`), so that runs on different machines and releases can be compared.

Each module ``myoface.bench.<area>`` registers benchmarks with :func:`benchmark`. A benchmark
function takes ``quick: bool`` and returns a :class:`Measurement`. Set-up (models, meshes, JIT
compilation) happens inside the function but *outside* the timed region: use :func:`time_median`,
which runs one untimed warm-up call first.

The benchmark modules import what they measure inside their functions: ``myoface bench``
imports every module to list the benchmarks, and ``--only`` then imports the library for the
ones that run (the analysis alone takes 0.85 s to import; a peer such as Warp or scikit-image
is optional).
"""

from __future__ import annotations

import importlib
import os
import pkgutil
import platform
import statistics
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass


@dataclass
class Measurement:
    """What a benchmark function returns: medians of ``n`` repeats."""

    value: float
    n: int
    peer_value: float | None = None
    #: optional breakdown (JSON-serialisable), e.g. per-muscle errors; shown in BENCHMARKS.md
    detail: dict | None = None


@dataclass
class BenchRecord:
    """One row of ``myoface bench --json``: the benchmark's name, its median ``value`` over
    ``n`` repeats in ``unit``, which way is better, the peer measured in the same run (if
    any) and its median, the machine, and the versions of the libraries the numbers rest on
    (:func:`software_description`)."""

    name: str
    value: float
    unit: str
    higher_is_better: bool
    peer: str | None
    peer_value: float | None
    n: int
    machine: str
    detail: dict | None = None
    software: str = ""

    def to_dict(self) -> dict:
        """The record as ``--json`` writes it (the breakdown ``detail`` goes to its own file)."""
        d = asdict(self)
        d.pop("detail")
        return d


@dataclass
class Benchmark:
    name: str
    unit: str
    higher_is_better: bool
    peer: str | None
    func: Callable[[bool], Measurement]
    doc: str


REGISTRY: dict[str, Benchmark] = {}


def benchmark(name: str, unit: str, higher_is_better: bool, peer: str | None = None):
    """Register ``func(quick) -> Measurement`` as benchmark ``name``."""

    def deco(func: Callable[[bool], Measurement]):
        REGISTRY[name] = Benchmark(
            name, unit, higher_is_better, peer, func, (func.__doc__ or "").strip()
        )
        return func

    return deco


def time_median(fn: Callable[[], object], n: int, *, warmup: int = 1) -> float:
    """Median wall time of ``fn()`` in seconds over ``n`` timed calls after ``warmup`` untimed ones."""
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def machine_description() -> str:
    """A one-line description of this machine: CPU model, core count, OS, Python."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return (
        f"{cpu}, {os.cpu_count()} cores, {platform.system()} {platform.release()}, "
        f"Python {platform.python_version()}"
    )


#: the distributions whose versions :func:`software_description` names: those whose numerics
#: the benchmarks' numbers pass through (the detector, the image and video libraries, the
#: compiler of the hot loops, the linear algebra). The analysis' numbers are sensitive to
#: them: on 2026-12-07 the same commit on a new install (a new machine, the versions pip
#: chose that day) read the head-motion renders' camera seed 0 with a worst correlation of
#: 0.11 where the run before had 0.76 (see BENCHMARKS.md's history in git)
SOFTWARE = ("numpy", "scipy", "numba", "opencv-contrib-python", "mediapipe", "av", "pillow",
            "trimesh")  # fmt: skip


def software_description() -> str:
    """The versions of :data:`SOFTWARE` installed here, ``name version`` comma-separated
    (``name -`` for one not installed)."""
    from importlib.metadata import PackageNotFoundError, version

    out = []
    for name in SOFTWARE:
        try:
            out.append(f"{name} {version(name)}")
        except PackageNotFoundError:
            out.append(f"{name} -")
    return ", ".join(out)


def load_all() -> dict[str, Benchmark]:
    """Import every ``myoface.bench.<area>`` module so its benchmarks register."""
    import myoface.bench as pkg

    for info in pkgutil.iter_modules(pkg.__path__):
        if not info.name.startswith("_"):
            importlib.import_module(f"myoface.bench.{info.name}")
    return REGISTRY


def run(
    prefix: str | None = None, quick: bool = False, progress: Callable[[str], None] | None = None
) -> list[BenchRecord]:
    """Run the registered benchmarks whose name starts with ``prefix`` (all if None)."""
    reg = load_all()
    machine = machine_description()
    software = software_description()
    out = []
    for name in sorted(reg):
        if prefix and not name.startswith(prefix):
            continue
        b = reg[name]
        if progress:
            progress(name)
        m = b.func(quick)
        out.append(
            BenchRecord(
                name,
                float(m.value),
                b.unit,
                b.higher_is_better,
                b.peer,
                None if m.peer_value is None else float(m.peer_value),
                int(m.n),
                machine,
                m.detail,
                software,
            )
        )
    return out
