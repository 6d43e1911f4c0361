"""``myoface bench``: measure myoface on this machine."""

from __future__ import annotations

import json
import sys

from myoface._io import atomic_output
from myoface.errors import MyofaceValueError

NAME = "bench"
HELP = "run the benchmarks and print a table (see BENCHMARKS.md)"


def detail_path(json_path):
    """Where ``--json FILE`` puts the benchmarks' breakdowns: ``FILE`` with ``.detail.json``."""
    from pathlib import Path

    p = Path(json_path)
    return p.with_name(p.stem + ".detail.json")


def add_arguments(p):
    p.add_argument("--quick", action="store_true", help="smaller sizes / fewer repeats (< 60 s)")
    p.add_argument("--only", metavar="PREFIX", help="only benchmarks whose name starts with PREFIX")
    p.add_argument("--json", metavar="FILE", help="also write the records as JSON to FILE")
    p.add_argument("--list", action="store_true", help="list the benchmark names and exit")


def _fmt(v):
    if v is None:
        return "-"
    return f"{v:.4g}"


def run(args) -> int:
    from myoface import bench
    from myoface._io import check_output_path

    if args.json:  # before the run, not after it
        check_output_path(args.json, "--json")
        check_output_path(detail_path(args.json), "--json")
    reg = bench.load_all()
    if args.list:
        for name in sorted(reg):
            b = reg[name]
            print(f"{name:32s} {b.unit:12s} peer={b.peer or '-'}")
        return 0
    if args.only and not any(n.startswith(args.only) for n in reg):
        raise MyofaceValueError(
            f"--only {args.only!r} matches no benchmark; names: {', '.join(sorted(reg))}"
        )
    print(f"{'name':32s} {'value':>10s} {'unit':8s} {'peer':>10s} {'ratio':>8s}  n   peer name")
    records = []

    def progress(name):
        print(f"  running {name} ...", file=sys.stderr, flush=True)

    for rec in bench.run(args.only, quick=args.quick, progress=progress):
        records.append(rec)
        ratio = None
        if rec.peer_value:
            ratio = (
                rec.value / rec.peer_value if rec.higher_is_better else rec.peer_value / rec.value
            )
        print(
            f"{rec.name:32s} {_fmt(rec.value):>10s} {rec.unit:8s} {_fmt(rec.peer_value):>10s} "
            f"{_fmt(ratio) + 'x' if ratio else '-':>8s}  {rec.n:<3d} {rec.peer or ''}",
            flush=True,
        )
    if args.json:
        with atomic_output(args.json) as tmp:
            tmp.write_text(json.dumps([r.to_dict() for r in records], indent=2) + "\n")
        print(f"wrote {args.json}")
        details = {r.name: r.detail for r in records if r.detail}
        if details:  # breakdowns (e.g. per muscle) beside the records, outside their schema
            side = detail_path(args.json)
            with atomic_output(side) as tmp:
                tmp.write_text(json.dumps(details, indent=2) + "\n")
            print(f"wrote {side}")
    return 0
