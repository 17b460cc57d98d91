"""Subcommands of ``cdh-planner``, one module per subcommand: a new command is one file.

A command module declares in its header, above its first ``def``, ``class`` or decorator,
``ORDER`` (its place in ``cdh-planner --help``: 10, 20, ...) and ``SUMMARY`` (its one-line
help); ``cdh_planner.cli`` reads them from the source without importing the module
(``cli.declared_commands``: a module without SUMMARY, ``outputs.py``, is no command),
imports ``cdh_planner.commands.<name>`` of the command being run only (of every command
for the full parser) and calls its ``add_parser(subparsers)``: a module's imports are paid
by its own command only.
A module adds its own parser (``help=SUMMARY``) and sets ``func`` with ``set_defaults(func=run)``,
where ``run(args) -> int`` returns the process exit code (0 ok, 1 no path / not
feasible). Raise ``cdh_planner.errors.InputError`` for bad user input: the CLI prints it
as one line and exits 2, with no traceback; any other exception is exit 3 (internal
error), one line too (``cdh_planner.cli`` holds the contract). Check output paths before
the work with ``cdh_planner.commands.outputs.check_output``, giving it the command's input files
(and its other outputs) as ``inputs`` so that no output overwrites them, and write them
with its ``write_text`` / ``writing``.
A module may also declare ``QUICK_EXIT = True`` when its ``run`` closes everything it
writes and leaves no thread working: its process then ends without the interpreter's
teardown (``cli._quick_exit``: 13 ms of a large ``verify``).

Example::

    # cdh_planner/commands/verify.py, below its docstring
    ORDER = 10  # its place in `cdh-planner --help`
    SUMMARY = 'check a robot / problem file'

    def add_parser(subparsers):
        p = subparsers.add_parser('verify', help=SUMMARY)
        p.add_argument('file')
        p.set_defaults(func=run)

    def run(args) -> int:
        ...
        return 0
"""
