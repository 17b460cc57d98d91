"""``cdh-planner``: the single command-line entry point.

Subcommands live in ``cdh_planner.commands.<name>`` (see that package's docstring), each
declaring its place in --help (ORDER) and its one-line summary (SUMMARY) in its header.
This module only builds the top-level parser, collects the subcommands that exist
and holds the exit-code contract of every command:

    0  ok
    1  no path, or not feasible (the command's answer is "no"); for ``call`` and
       ``replay --requests`` also: no node answered (one line says so)
    2  bad input: arguments, input files (unreadable, not UTF-8, beyond the limits of
       ``cdh_planner.files``, wrong types or magnitudes, damaged), output paths that cannot
       be written or that name an input (checked before the work starts; a write that
       fails at the end, a full disk, is exit 2 too), ROS arguments and names that rcl
       refuses; the library exceptions only bad input raises (``INPUT_EXCEPTIONS``) too
    3  internal error: any other exception (a bug)
    130 interrupted (Ctrl-C); 141 stdout closed by its reader (``| head``), silently

Whatever happens, stderr gets one line (``cdh-planner: error: ...``), never a
traceback; ``cdh-planner --debug COMMAND ...`` prints the traceback as well.
"""
from __future__ import annotations

import argparse
import atexit
import functools
import gc
import importlib
import importlib.util
import os
import re
import sys
from pathlib import Path

from cdh_planner import __version__
from cdh_planner.errors import MAX_MESSAGE_CHARS, InputError, clip

PROG = 'cdh-planner'

COMMANDS_DIR = Path(__file__).parent / 'commands'


def declared_commands(folder=COMMANDS_DIR) -> dict[str, tuple[int, str]]:
    """{name: (ORDER, SUMMARY)} of the modules of ``cdh_planner.commands`` (``name.py`` or
    ``name/__init__.py``) that declare a SUMMARY at the top level: the commands. Read from
    their source (``SUMMARY = <a string literal, maybe continued on indented lines>``,
    ``ORDER = <an integer>``) without importing them: a run imports only the module of the
    command it runs (a module imports what its command needs, the planner, plotting, ROS: up
    to seconds), and a new command is its one file."""
    return _evaluated(_declarations(folder))


def _evaluated(declarations):
    """``_declarations``' entries with each SUMMARY literal evaluated."""
    import ast  # here: 4 ms of a start that only --help needs
    return {name: (order, ast.literal_eval(summary))
            for name, (order, summary) in declarations.items()}


def _declarations(folder=COMMANDS_DIR) -> dict[str, tuple[int, str]]:
    """``declared_commands`` with each SUMMARY as its source text (not yet evaluated)."""
    out = {}
    for path in sorted([*folder.glob('*.py'), *folder.glob('*/__init__.py')]):
        text = path.read_text(encoding='utf-8')
        summary = _SUMMARY.search(text)
        if summary:
            order = _ORDER.search(text)
            name = path.parent.name if path.name == '__init__.py' else path.stem
            out[name] = (int(order.group(1)) if order else 0, summary.group(1))
    return out


_SUMMARY = re.compile(r'^SUMMARY = (.*(?:\n[ \t]+.*)*)', re.M)
_ORDER = re.compile(r'^ORDER = (\d+)', re.M)
_DECLARED = _declarations()
COMMANDS = sorted(_DECLARED, key=lambda n: (_DECLARED[n][0], n))  # in the order of --help


def summaries() -> dict[str, str]:
    """{name: SUMMARY} of COMMANDS: the one-line summaries --help shows, their literals
    evaluated when asked for, not at every start (the files as read at import)."""
    declared = _evaluated(_DECLARED)
    return {name: declared[name][1] for name in COMMANDS if name in declared}


EXIT_OK = 0
EXIT_NO = 1  # no path, infeasible
EXIT_USAGE = 2  # bad input (arguments, files)
EXIT_INTERNAL = 3  # an unexpected exception
EXIT_INTERRUPTED = 130
EXIT_BROKEN_PIPE = 141  # 128 + SIGPIPE, as a shell reports a process killed by it

# Exception types of the libraries that only bad input raises (a name given on the command
# line or read from a file, a damaged file's bytes), by qualified name: the commands turn
# them into InputErrors where they arise; one that escapes is still exit 2, not 3.
INPUT_EXCEPTIONS = frozenset({
    'rclpy.exceptions.NameValidationException',   # topic, service, node, namespace names
    # mcap's reading errors (not McapError, the base of its writers' errors too)
    'mcap.exceptions.InvalidMagic', 'mcap.exceptions.EndOfFile',
    'mcap.exceptions.RecordLengthLimitExceeded', 'mcap.exceptions.UnsupportedCompressionError',
    'mcap.exceptions.DecoderNotFoundError', 'mcap_ros2.decoder.McapROS2DecodeError',
    'mcap.stream_reader.CRCValidationError',       # a damaged chunk
})


def _command_module(name: str, load: bool = True):
    """Import ``cdh_planner.commands.<name>`` (with ``load`` False: only find it), or return
    None if there is no such module."""
    modname = f'cdh_planner.commands.{name}'
    if modname not in sys.modules:
        try:
            if importlib.util.find_spec(modname) is None:
                return None
        except (ImportError, ValueError):
            return None
    return importlib.import_module(modname) if load else modname


def requested_command(argv: list[str]) -> str | None:
    """The command ``argv`` runs: its first argument that is not an option, if that is a
    command and no --help / --version comes before it; else None."""
    for arg in argv:
        if arg in ('-h', '--help', '--version'):
            return None
        if not arg.startswith('-'):
            return arg if arg in COMMANDS else None
    return None


class OneLineErrors(argparse.ArgumentParser):
    """argparse's parser whose usage errors are one line too (argparse prints the usage
    text first: 13 lines for ``plan --max-cable-speed fast``), pointing at --help; the
    subcommands' parsers are of this class as well (``add_subparsers`` uses the parent's).
    Its help formatters are given their width (``help_width``): argparse makes one at every
    add_argument and, without a width, imports shutil for it (with bz2 and lzma: 3 ms of
    every start)."""

    def __init__(self, *args, formatter_class=argparse.HelpFormatter, **kwargs):
        super().__init__(*args, formatter_class=functools.partial(formatter_class,
                                                                  width=help_width()), **kwargs)

    def error(self, message):
        hint = f" (see {self.prog} --help)"
        text = clip(message, max(20, MAX_MESSAGE_CHARS - len(hint))) + hint
        self.exit(EXIT_USAGE, f'{PROG}: error: {text}\n')


def help_width() -> int:
    """The width argparse gives help text by default: the terminal's columns less 2, the
    columns as shutil.get_terminal_size finds them (COLUMNS if a positive integer, else
    those of the terminal on stdout, else 80)."""
    try:
        columns = int(os.environ['COLUMNS'])
    except (KeyError, ValueError):
        columns = 0
    if columns <= 0:
        try:
            columns = os.get_terminal_size(sys.__stdout__.fileno()).columns
        except (AttributeError, ValueError, OSError):  # no stdout, or not a terminal
            columns = 0
        columns = columns or 80
    return columns - 2


def build_parser(commands: list[str] | None = None, others: bool = True) -> argparse.ArgumentParser:
    """The parser with the full subparsers of ``commands`` (default: every command; their
    modules are imported) and, for the others, a one-line entry (not imported) if
    ``others`` (--help lists them; a run parses only its command's arguments: their
    13 parsers were 2 ms of its start)."""
    parser = OneLineErrors(
        prog=PROG,
        description='Wrench-feasible path planning for cable-driven hexapods.',
    )
    parser.add_argument('--version', action='version', version=f'%(prog)s {__version__}')
    parser.add_argument('--debug', action='store_true',
                        help='on an error, also print the traceback (exit codes: 0 ok, 1 no '
                             'path / infeasible, 2 bad input, 3 internal error)')
    subparsers = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')
    help_texts = summaries() if others else {}
    for name in COMMANDS:
        full = commands is None or name in commands
        if not (full or others):
            continue
        module = _command_module(name, load=full)
        if module is None:
            continue
        if full:
            module.add_parser(subparsers)
        else:
            subparsers.add_parser(name, help=help_texts.get(name), add_help=False)
    return parser


def _error(message: str, code: int = EXIT_USAGE, debug: bool = False) -> int:
    """Print ``message`` as one line on stderr (and the traceback being handled when
    ``debug``); return ``code``."""
    if debug:
        import traceback  # here: 5 ms of every start otherwise
        traceback.print_exc()
    print(f'{PROG}: error: {clip(message, MAX_MESSAGE_CHARS)}', file=sys.stderr)
    return code


def main(argv: list[str] | None = None) -> int:
    """Run ``cdh-planner`` with ``argv`` (default: ``sys.argv[1:]``); return the exit code
    (the contract in this module's docstring)."""
    own = argv is None  # the process's own command (the console script, python -m)
    if own:
        argv = sys.argv[1:]
        # The modules it imports (numpy, the planner: some 100,000 objects, hardly any
        # garbage) live to its end: the cycle collector is off while they load, then they are
        # frozen out of it, and so is all that lives at exit (the interpreter's finalization
        # then does not walk it again before freeing it). The collector's passes over them
        # were ~25 ms of a plan's process.
        gc.disable()
        atexit.register(gc.freeze)
    # One BLAS thread, set before numpy loads OpenBLAS: planning runs its many small solves
    # on one thread anyway (planner.py), and starting the pool costs 30 ms of every start.
    os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')
    debug = '--debug' in argv  # until the arguments are parsed
    try:
        command = requested_command(argv)
        parser = build_parser([command] if command else [], others=not command)
        if own:
            gc.freeze()
            gc.enable()
        try:
            args = parser.parse_args(argv)
        except SystemExit as exc:  # --help, --version, usage errors: argparse already printed
            return exc.code if isinstance(exc.code, int) else EXIT_USAGE
        debug = bool(getattr(args, 'debug', False))
        func = getattr(args, 'func', None)
        if func is None:  # a subcommand module that forgot set_defaults(func=run)
            return _error(f'command {args.command!r} has no handler', EXIT_INTERNAL)
        rc = func(args)
        rc = 0 if rc is None else int(rc)
        if own and getattr(sys.modules.get(func.__module__), 'QUICK_EXIT', False):
            _quick_exit(rc)
        return rc
    except InputError as exc:
        return _error(str(exc), EXIT_USAGE, debug)
    except BrokenPipeError:  # stdout closed by its reader (`| head`): stop quietly
        try:
            sys.stdout = open(os.devnull, 'w')  # so that the exit's flush does not fail again
        except OSError:
            pass
        return EXIT_BROKEN_PIPE
    except FileNotFoundError as exc:
        path = exc.filename if exc.filename is not None else str(exc)
        return _error(f'file not found: {path}', EXIT_USAGE, debug)
    except OSError as exc:  # a file the command could not read or write (EIO, ENOSPC, EISDIR)
        where = f': {exc.filename}' if exc.filename is not None else ''
        return _error(f'{exc.strerror or type(exc).__name__}{where}', EXIT_USAGE, debug)
    except KeyboardInterrupt:
        print(f'{PROG}: interrupted', file=sys.stderr)
        return EXIT_INTERRUPTED
    except (Exception, RecursionError, MemoryError) as exc:
        if _caused_by_input(exc):
            return _error(_text(exc), EXIT_USAGE, debug)
        return _error(f'internal error: {type(exc).__name__}: {_text(exc)} (run with --debug '
                      'for the traceback)', EXIT_INTERNAL, debug)


def _quick_exit(rc: int):
    """End the process with ``rc`` now, once stdout and stderr are written (a closed stdout
    raises BrokenPipeError here, as at any print), without the interpreter's teardown: for
    a command that declares ``QUICK_EXIT = True``, whose run closes whatever it writes and
    leaves no thread working. The teardown frees every object and runs the cycle collector
    over what is left: nothing a file or a reader of the output would see, and 13 ms of a
    CoGiRo ``verify`` of 20,000 poses (strace: the process gone 6 - 10 ms after its last
    line, against 19 - 26 ms)."""
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(rc)


def _caused_by_input(exc) -> bool:
    """Whether ``exc`` is of one of INPUT_EXCEPTIONS (or derived from one)."""
    return any(f'{c.__module__}.{c.__qualname__}' in INPUT_EXCEPTIONS for c in type(exc).__mro__)


def _text(exc) -> str:
    """str(exc), or '?' if even that fails."""
    try:
        return str(exc)
    except Exception:
        return '?'


if __name__ == '__main__':  # python -m cdh_planner.cli
    sys.exit(main())
