"""``myoface batch``: many face videos analysed at once, here or on a Dask cluster."""

from __future__ import annotations

from myoface.commands._common import (
    add_analysis_arguments,
    add_face_argument,
    analysis_settings,
    integer,
    number,
)
from myoface.errors import MyofaceValueError

NAME = "batch"
HELP = "analyse many videos (files or glob patterns), on this machine or on a Dask cluster"
#: the most worker processes ``--workers`` starts
MAX_WORKERS = 1024
#: the longest ``--timeout``, s (a day: a cluster's workers may wait in a queue for hours)
MAX_TIMEOUT_S = 86400.0
DESCRIPTION = """Analyse many face videos as `myoface analyze` does, one result folder per video
under the output folder (named after the video; clip, clip-2, ... when names repeat), and
summarise them in OUT/summary.parquet and OUT/summary.csv: per video its path, status
(ok / failed / skipped), error, frames, measured fraction, frames per second, wall time and
the mean contraction of each muscle. The analysis options (--tracker, --init,
--calibration-frame, --max-frames, --sigma, --estimator, --refine, --flow, --photometric) are
those of `myoface analyze`, the same for every video.

Resumable: a folder holding a complete result (its done.json, written last, names the same
video and settings) is skipped. A video that fails is recorded with its error and the batch
goes on; the exit status is then 1.

Stopping: at Ctrl-C (SIGINT), SIGTERM or SIGHUP no video starts any more, those being
analysed stop (within about 2 s; each keeps what analyze keeps when stopped, and is analysed
again by the next run), the summary is written with every video finished (in this run or an
earlier one), and batch exits with status 128 + the signal's number.

--timeout bounds the whole wait for --scheduler: its answer and its first worker. A peer that
is not a Dask scheduler (e.g. an SSH server) is named as such.

Engines (pip install "myoface[batch]"):
  local  a pool of --workers processes on this machine (default)
  dask   a Dask LocalCluster of --workers single-threaded workers, or the running cluster
         whose scheduler is at --scheduler (e.g. started on SLURM by dask-jobqueue or on
         Kubernetes by dask-kubernetes; its workers need myoface and the same paths)

Quote glob patterns so that myoface expands them ("videos/**/*.mp4" spans folders)."""


def add_arguments(p):
    import argparse

    p.formatter_class = argparse.RawDescriptionHelpFormatter
    p.add_argument(
        "videos",
        nargs="+",
        metavar="VIDEO_OR_GLOB",
        help="video files, folders of images, or glob patterns",
    )
    p.add_argument("-o", "--output", required=True, help="output folder")
    p.add_argument(
        "--engine",
        choices=("local", "dask"),
        default=None,
        help="where the videos are analysed (default: local; dask with --scheduler)",
    )
    p.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="a running Dask scheduler to use (e.g. tcp://10.0.0.5:8786) instead of a LocalCluster",
    )
    p.add_argument(
        "--workers",
        type=integer(1, MAX_WORKERS),
        metavar="N",
        help="worker processes on this machine (default: the number of cores)",
    )
    p.add_argument(
        "--timeout",
        type=number(0.0, MAX_TIMEOUT_S, lo_open=True, unit=" s"),
        default=None,
        metavar="S",
        help="seconds to wait, in all, for --scheduler to answer and to have a worker (default 10)",
    )
    add_analysis_arguments(p.add_argument_group("the analysis of each video (as myoface analyze)"))
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_face_argument(p)


def run(args) -> int:
    import sys
    from collections import Counter
    from pathlib import Path

    from myoface.analysis.batch import SCHEDULER_TIMEOUT_S, run_batch

    engine = args.engine or ("dask" if args.scheduler else "local")
    if args.scheduler and engine != "dask":
        raise MyofaceValueError("--scheduler is for --engine dask")
    if args.scheduler and args.workers is not None:
        raise MyofaceValueError(
            "--workers sizes the cluster batch starts; with --scheduler the cluster's own "
            "workers are used"
        )
    # (--workers and --timeout are in their limits: the parser's types, exit status 2)
    timeout = SCHEDULER_TIMEOUT_S if args.timeout is None else args.timeout
    if args.timeout is not None and not args.scheduler:
        raise MyofaceValueError("--timeout is for --scheduler")
    settings = analysis_settings(args)
    rows = run_batch(
        args.videos,
        args.output,
        engine=engine,
        workers=args.workers,
        scheduler=args.scheduler,
        timeout=timeout,
        **settings,
        face=args.face,
        muscles=args.muscles,
        show_progress=not args.quiet,
    )
    n = Counter(r["status"] for r in rows)
    out = Path(args.output).resolve()
    print(
        f"{len(rows)} videos: {n['ok']} analysed, {n['skipped']} already done, "
        f"{n['failed']} failed; summary: {out / 'summary.parquet'}"
    )
    for r in rows:
        if r["status"] == "failed":
            err = r["error"] if r["error"].startswith(r["path"]) else f"{r['path']}: {r['error']}"
            print(f"myoface batch: failed: {err}", file=sys.stderr)
    return 1 if n["failed"] else 0
