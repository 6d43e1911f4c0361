"""The ``myoface`` command: thin subcommands over the library.

Each subcommand lives in ``myoface.commands.<name>`` and defines ``NAME``, ``HELP``,
``add_arguments(parser)`` and ``run(args) -> int``, which checks the arguments and calls the
library (the work itself, e.g. :func:`myoface.analysis.outputs.analyze_to_folder` or
:func:`myoface.analysis.resynthesis.resynthesize`, is the library's; nothing below the
commands imports them or this module). The library is imported inside ``run``: importing the
renderer and the physics takes about 2 s, and ``myoface --help`` should not wait for it.
Exit codes: 0 success, 2 usage error (an unknown option, a number outside its limits, options
that do not go together: the parser's, or a :class:`~myoface.errors.MyofaceUsageError`), 1 a
:class:`~myoface.errors.MyofaceError` or an error of the machine (a full disk names the file
being written); one line on stderr, the traceback only with ``--debug``. SIGINT, SIGTERM and SIGHUP stop a command cleanly (its temporary outputs
removed, exit status 128 + the signal's number); warnings are one line each on stderr.
"""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import pkgutil
import signal
import sys
import warnings

import myoface
import myoface.commands
from myoface._signals import clear_pending, interrupt_in, stop_signal_of, stop_signals
from myoface.errors import MyofaceError, MyofaceUsageError, MyofaceWarning, user_message


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


class _Parser(argparse.ArgumentParser):
    """Usage errors in one line (exit status 2), pointing at ``--help``."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _one_line_warnings(prog: str):
    def show(message, category, filename, lineno, file=None, line=None):
        text = " ".join(str(message).split())
        kind = "warning" if issubclass(category, UserWarning) else category.__name__
        print(f"{prog}: {kind}: {text}", file=sys.stderr, flush=True)

    return show


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(
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
        _name_subcommands(p)
    return parser


def _name_subcommands(parser: argparse.ArgumentParser) -> None:
    """Each (sub)parser records its name (``myoface face maps``) for the error messages."""
    parser.set_defaults(_prog=parser.prog)
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                _name_subcommands(sub)


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # --help, --version (0) or a usage error (2), already printed
        return exc.code if isinstance(exc.code, int) else 2
    if getattr(args, "_run", None) is None:
        parser.print_help(sys.stderr)
        return 2
    debug = getattr(args, "debug", False)
    prog = getattr(args, "_prog", f"myoface {args.command}")
    # (SIGINT, SIGTERM and SIGHUP raise Interrupted, a KeyboardInterrupt: myoface._signals)
    with warnings.catch_warnings(), stop_signals():
        warnings.filterwarnings("default", category=MyofaceWarning)  # said, whatever -W says
        if not debug:
            warnings.showwarning = _one_line_warnings(prog)
        try:
            return int(args._run(args) or 0)
        except MyofaceUsageError as exc:  # as the parser's own: exit status 2
            if debug:
                raise
            print(f"{prog}: error: {_one_line(exc)} (see {prog} --help)", file=sys.stderr)
            return 2
        except MyofaceError as exc:
            if debug:
                raise
            print(f"{prog}: error: {_one_line(exc)}", file=sys.stderr)
            return 1
        except BaseException as err:
            # a stop signal, also one that came out of a library as another error: a
            # SystemError caused by the Interrupted (numba unpickling a compiled function) or
            # an error of a library cut by it (myoface._signals.stop_signal_of)
            signum = stop_signal_of(err)
            if signum is not None:
                clear_pending()  # (seen: not delivered again)
                name = signal.Signals(signum).name
                # what the command kept, if it says (e.g. analyze's measured rows)
                exc = interrupt_in(err) or err
                kept = "".join(f"; {_one_line(n)}" for n in getattr(exc, "__notes__", ()))
                print(f"{prog}: interrupted ({name}){kept}", file=sys.stderr)
                return 128 + int(signum)
            if debug or not isinstance(err, (OSError, MemoryError)):
                raise
            # the machine's, not the input's: no traceback
            what = "out of memory" if isinstance(err, MemoryError) else _os_error(err, args)
            print(f"{prog}: error: {what}", file=sys.stderr)
            return 1


def _one_line(exc: BaseException) -> str:
    return user_message(exc, limit=4000)


#: errors of a write that fails for want of room (no file name in them when a ``write`` or a
#: ``close`` fails): the full disk is the output's
_NO_ROOM = (errno.ENOSPC, errno.EDQUOT, errno.EFBIG)


def _os_error(exc: OSError, args) -> str:
    """An OSError as one line: its reason (no ``[Errno N]``) and the file it names; a full
    disk that names no file is the command's output's (``-o``)."""
    reason = exc.strerror or _one_line(exc)
    if exc.filename is not None:
        where = _name(exc.filename)
        if exc.filename2 is not None:
            where += f" -> {_name(exc.filename2)}"
        return f"{where}: {reason}"
    output = getattr(args, "output", None)
    if exc.errno in _NO_ROOM and output:
        return f"{reason} (writing {output})"
    return reason


def _name(filename) -> str:
    return os.fsdecode(filename) if isinstance(filename, str | bytes) else str(filename)


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
