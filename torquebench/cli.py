"""The torquebench command line: joint-torque-sensor design, calibration and contact estimation.

Each subcommand is a module in ``torquebench.commands`` with::

    HELP = "one line for --help"
    EXAMPLES = "torquebench CMD ...\n..."                 # shown as "Example:" under --help
    def add_arguments(parser: argparse.ArgumentParser) -> None: ...
    def run(args: argparse.Namespace) -> int: ...          # returns the exit code

Modules are discovered, so adding a command never touches this file. Every subcommand gets
``--json`` (print one JSON object on stdout and nothing else). Exit codes: 0 success, 2 user error
(one line on stderr), 130 interrupted (Ctrl-C), 1 a bug (one line; ``--debug`` shows the
traceback). Heavy imports happen inside ``run`` so ``torquebench --help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import sys

import torquebench
import torquebench.commands
from userio.errors import InputError

#: the user errors the CLI turns into exit code 2 and one line on stderr
USER_ERRORS = (InputError, FileNotFoundError, IsADirectoryError, NotADirectoryError, PermissionError)

DESCRIPTION = ("torquebench: design a strain-gauge joint torque sensor (flexure FEM, bridge and ADC),\n"
               "calibrate it, and estimate contacts on a robot leg with a momentum observer.")
EPILOG = """\
Start here:
  torquebench demo                         the whole chain on the paper's leg, no input needed
  torquebench COMMAND --help               options (with units and defaults) and an example
  torquebench estimate examples/leg_poke/leg_poke.csv
"""


class _Parser(argparse.ArgumentParser):
    """argparse with the one-line error contract (exit 2, no usage block)."""

    def error(self, message: str):  # noqa: D401 - argparse API
        self.exit(2, f"{self.prog}: error: {message}\n")


def _commands() -> dict:
    names = sorted(m.name for m in pkgutil.iter_modules(torquebench.commands.__path__))
    return {n.replace("_", "-"): importlib.import_module(f"torquebench.commands.{n}") for n in names
            if not n.startswith("_")}


def _epilog(module) -> str | None:
    examples = getattr(module, "EXAMPLES", "").strip()
    if not examples:
        return None
    return "Example:\n" + "\n".join(f"  {line}" for line in examples.splitlines())


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="torquebench", description=DESCRIPTION, epilog=EPILOG,
                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--version", action="version", version=f"torquebench {torquebench.__version__}")
    parser.add_argument("--debug", action="store_true",
                        help="show the full traceback when the program fails on a bug")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser,
                                title="commands")
    for name, module in _commands().items():
        p = sub.add_parser(name, help=module.HELP, description=module.HELP, epilog=_epilog(module),
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        module.add_arguments(p)
        p.add_argument("--json", action="store_true",
                       help="print one JSON object (SI units) on stdout and nothing else")
        p.set_defaults(_run=module.run)
    return parser


def _one_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _quiet_broken_pipe() -> int:
    """The reader went away (``torquebench estimate LOG | head -1``): stop quietly."""
    try:  # point stdout at /dev/null so the interpreter's final flush does not fail again
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError):
        pass
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run one command; Ctrl-C anywhere (parsing, imports, the work, the cleanup) is exit 130.

    Called as the program (``argv`` None), Ctrl-C is ignored once the command has returned: the
    interpreter's shutdown (joining worker threads, atexit handlers) runs with the default SIGINT
    action, which would end the process by the signal with no message."""
    try:
        code = _main(argv)
    except KeyboardInterrupt:
        code = _interrupted("torquebench")
    if argv is None:
        _ignore_sigint()
    return code


def _ignore_sigint() -> None:
    import signal

    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    except (ValueError, OSError):          # not the main thread
        pass


def _interrupted(where: str, note: str = "") -> int:
    """One line, exit 130; a second Ctrl-C during the shutdown is ignored (no traceback)."""
    import signal

    try:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    except (ValueError, OSError):          # not the main thread
        pass
    print(f"{where}: interrupted; " + (f"{note}; " if note else "")
          + "files already written are complete, nothing was half-written", file=sys.stderr)
    return 130


def _main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv:  # a bare call: show what there is to run
        parser.print_usage(sys.stderr)
        print(parser.format_help().split("\n\n", 1)[1].rstrip(), file=sys.stderr)
        return 2
    args = parser.parse_args(argv)
    if args.command is None:
        parser.error("a command is required (see torquebench --help)")
    where = f"torquebench {args.command}"
    from userio import outputs

    try:
        with _warnings_as_lines(), outputs.required():     # every write through the command's plan
            return int(args._run(args) or 0)
    except KeyboardInterrupt as exc:
        return _interrupted(where, str(exc))
    except BrokenPipeError:
        return _quiet_broken_pipe()
    except USER_ERRORS as exc:
        print(f"{where}: error: {_user_message(exc)}", file=sys.stderr)
        return 2
    except OSError as exc:  # the environment: read-only or full file system, a device, a network
        print(f"{where}: error: {_os_message(exc)}", file=sys.stderr)
        return 2
    except MemoryError:
        print(f"{where}: error: out of memory: the input or an option is too large for this machine "
              "(see the command's --help for the options that size the work)", file=sys.stderr)
        return 2
    except UnicodeError as exc:  # UnicodeDecodeError: a binary or non-UTF-8 file given as text
        print(f"{where}: error: an input file is not UTF-8 text ({_one_line(exc)})", file=sys.stderr)
        return 2
    except RecursionError as exc:
        return _bug(where, exc, args.debug)
    except Exception as exc:  # noqa: BLE001 - the last line of defence
        return _bug(where, exc, args.debug)


def _user_message(exc: BaseException) -> str:
    msg = _one_line(exc)
    if isinstance(exc, OSError) and exc.filename and str(exc.filename) not in msg:
        msg = f"{exc.filename}: {exc.strerror}"
    return msg


def _os_message(exc: OSError) -> str:
    """'PATH: cannot …: cause' for an OSError (the path when it has one)."""
    import errno

    cause = exc.strerror or _one_line(exc)
    if exc.errno == errno.ENOSPC:
        cause += " (the file system is full)"
    elif exc.errno == errno.EROFS:
        cause += " (mounted read-only)"
    if exc.filename:
        return f"{exc.filename}: {cause}"
    return cause


class _warnings_as_lines:
    """Python warnings (PlausibilityWarning, …) as ``warning: MESSAGE`` lines on stderr, one line
    each, without the source line Python adds. They are held until the command ends: printed when
    it succeeds, dropped when it fails (an error is ONE line, not the warnings that led to it)."""

    def __enter__(self):
        import warnings

        self._cm = warnings.catch_warnings()
        self._cm.__enter__()
        self.held: list[str] = []

        def show(message, category, filename, lineno, file=None, line=None):
            text = " ".join(str(message).split())
            if text not in self.held:
                self.held.append(text)

        warnings.showwarning = show
        return self

    def __exit__(self, exc_type, exc, tb):
        self._cm.__exit__(exc_type, exc, tb)
        if exc_type is None:
            for text in self.held:
                print(f"warning: {text}", file=sys.stderr)
        return False


def _bug(where: str, exc: BaseException, debug: bool) -> int:
    if debug:
        raise exc
    print(f"{where}: internal error (a bug, please report it): {type(exc).__name__}: {_one_line(exc)}; "
          f"rerun with 'torquebench --debug {where.split()[-1]} ...' for the traceback", file=sys.stderr)
    return 1


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
