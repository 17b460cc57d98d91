"""Subcommands of ``cdh-planner``, one module per subcommand.

``cdh_planner.cli`` imports ``cdh_planner.commands.<name>`` of the command being run (of
each name in ``cdh_planner.cli.COMMANDS`` for the full parser; ``--help`` lists them from
``cli.SUMMARIES`` without importing any) and calls its ``add_parser(subparsers)``: a
module's imports are paid by its own command only.
A module adds its own parser and sets ``func`` with ``set_defaults(func=run)``,
where ``run(args) -> int`` returns the process exit code (0 ok, 1 no path / not
feasible). Raise ``cdh_planner.errors.InputError`` for bad user input: the CLI prints it
as one line and exits 2, with no traceback; any other exception is exit 3 (internal
error), one line too (``cdh_planner.cli`` holds the contract). Check output paths before
the work with ``cdh_planner.commands.outputs.check_output``, giving it the command's input files
(and its other outputs) as ``inputs`` so that no output overwrites them, and write them
with its ``write_text`` / ``writing``.

Example::

    def add_parser(subparsers):
        p = subparsers.add_parser('verify', help='check a robot / problem file')
        p.add_argument('file')
        p.set_defaults(func=run)

    def run(args) -> int:
        ...
        return 0
"""
