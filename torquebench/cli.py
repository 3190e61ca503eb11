"""The ``torquebench`` command line.

Each subcommand is a module in ``torquebench.commands`` with::

    HELP = "one line for --help"
    def add_arguments(parser: argparse.ArgumentParser) -> None: ...
    def run(args: argparse.Namespace) -> int: ...          # returns the exit code

Modules are discovered, so adding a command never touches this file. Every subcommand gets
``--json`` (print one JSON object on stdout and nothing else). User errors (any of
``torquebench.errors.USER_ERRORS``) exit with code 2 and one line on stderr; heavy imports happen
inside ``run`` so ``torquebench --help`` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

import torquebench.commands
from torquebench.errors import USER_ERRORS


class _Parser(argparse.ArgumentParser):
    """argparse with the one-line error contract (exit 2, no usage block)."""

    def error(self, message: str):  # noqa: D401 - argparse API
        self.exit(2, f"{self.prog}: error: {message}\n")


def _commands() -> dict:
    names = sorted(m.name for m in pkgutil.iter_modules(torquebench.commands.__path__))
    return {n.replace("_", "-"): importlib.import_module(f"torquebench.commands.{n}") for n in names
            if not n.startswith("_")}


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="torquebench", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True
    for name, module in _commands().items():
        p = sub.add_parser(name, help=module.HELP, description=module.HELP)
        module.add_arguments(p)
        p.add_argument("--json", action="store_true",
                       help="print one JSON object (SI units) on stdout and nothing else")
        p.set_defaults(_run=module.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except USER_ERRORS as exc:
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        if isinstance(exc, OSError) and exc.filename and str(exc.filename) not in msg:
            msg = f"{exc.filename}: {exc.strerror}"
        print(f"torquebench {args.command}: error: {msg}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
