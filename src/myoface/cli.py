"""The ``myoface`` command: thin subcommands over the library.

Each subcommand lives in ``myoface.commands.<name>`` and defines ``NAME``, ``HELP``,
``add_arguments(parser)`` and ``run(args) -> int``. Exit codes (GUIDE §4): 0 success,
2 usage error, 1 a :class:`~myoface.errors.MyofaceError` (one line on stderr; the traceback
only with ``--debug``).
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

import myoface
import myoface.commands
from myoface.errors import MyofaceError


def _command_modules():
    mods = []
    for info in sorted(pkgutil.iter_modules(myoface.commands.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        mod = importlib.import_module(f"myoface.commands.{info.name}")
        if hasattr(mod, "NAME") and hasattr(mod, "run"):
            mods.append(mod)
    order = getattr(myoface.commands, "ORDER", [])
    mods.sort(key=lambda m: (order.index(m.NAME) if m.NAME in order else len(order), m.NAME))
    return mods


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="myoface",
        description="Physics-based facial animation and face-video analysis "
        "(Terzopoulos & Waters 1993).",
    )
    parser.add_argument("--version", action="version", version=f"myoface {myoface.__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks on errors")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for mod in _command_modules():
        p = sub.add_parser(
            mod.NAME, help=mod.HELP, description=getattr(mod, "DESCRIPTION", mod.HELP)
        )
        p.add_argument(
            "--debug",
            action="store_true",
            default=argparse.SUPPRESS,
            help="show tracebacks on errors",
        )
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if getattr(args, "_run", None) is None:
        parser.print_help()
        return 2
    try:
        return int(args._run(args) or 0)
    except MyofaceError as exc:
        if getattr(args, "debug", False):
            raise
        print(f"myoface {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("myoface: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
