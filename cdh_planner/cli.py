"""``cdh-planner``: the single command-line entry point.

Subcommands live in ``cdh_planner.commands.<name>`` (see that package's docstring).
This module only builds the top-level parser, collects the subcommands that exist
and turns user errors into a one-line message and an exit code.
"""
from __future__ import annotations

import argparse
import importlib
import importlib.util
import sys

from cdh_planner import __version__
from cdh_planner.errors import InputError

PROG = 'cdh-planner'

# Order here is the order in --help. A name whose module does not exist yet is skipped.
COMMANDS = ['verify', 'slice', 'plan', 'node', 'call', 'replay', 'demo']

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130


def _command_module(name: str):
    """Import ``cdh_planner.commands.<name>``, or return None if there is no such module."""
    modname = f'cdh_planner.commands.{name}'
    if modname not in sys.modules:
        try:
            if importlib.util.find_spec(modname) is None:
                return None
        except (ImportError, ValueError):
            return None
    return importlib.import_module(modname)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog=PROG,
        description='Wrench-feasible path planning for cable-driven hexapods.',
    )
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    subparsers = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')
    for name in COMMANDS:
        module = _command_module(name)
        if module is not None:
            module.add_parser(subparsers)
    return parser


def _error(message: str) -> int:
    print(f'{PROG}: error: {message}', file=sys.stderr)
    return EXIT_USAGE


def main(argv: list[str] | None = None) -> int:
    """Run ``cdh-planner`` with ``argv`` (default: ``sys.argv[1:]``); return the exit code."""
    if argv is None:
        argv = sys.argv[1:]
    try:
        parser = build_parser()
        try:
            args = parser.parse_args(argv)
        except SystemExit as exc:  # --help, --version, usage errors: argparse already printed
            return exc.code if isinstance(exc.code, int) else EXIT_USAGE
        func = getattr(args, 'func', None)
        if func is None:  # a subcommand module that forgot set_defaults(func=run)
            return _error(f'command {args.command!r} has no handler')
        rc = func(args)
        return 0 if rc is None else int(rc)
    except InputError as exc:
        return _error(str(exc))
    except FileNotFoundError as exc:
        path = exc.filename if exc.filename is not None else str(exc)
        return _error(f'file not found: {path}')
    except KeyboardInterrupt:
        print(f'{PROG}: interrupted', file=sys.stderr)
        return EXIT_INTERRUPTED


if __name__ == '__main__':  # python -m cdh_planner.cli
    sys.exit(main())
