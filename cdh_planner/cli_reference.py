"""The command-line reference (docs/cli.md), generated from the parser so that it cannot
disagree with ``--help``:

    python -m cdh_planner.cli_reference > docs/cli.md

(test_doc_examples checks that the file is current.)"""

import argparse
import io
import os
from contextlib import redirect_stdout

from cdh_planner.cli import COMMANDS, PROG, build_parser

HEADER = f"""# `{PROG}`: every subcommand

Generated from the parser (`python -m cdh_planner.cli_reference > docs/cli.md`); what each
command prints, the exit codes and the input limits: [command-line.md](command-line.md).
"""


def help_text(parser):
    """What ``--help`` prints for ``parser``, at a fixed width of 100 columns."""
    out = io.StringIO()
    with redirect_stdout(out):
        parser.print_help()
    return out.getvalue().rstrip()


def reference():
    """docs/cli.md's text: the top-level help, then each subcommand's."""
    os.environ["COLUMNS"] = "100"
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    parts = [HEADER, "```text", help_text(parser), "```"]
    for name in COMMANDS:
        if name in sub.choices:
            parts += ["", f"## `{PROG} {name}`", "", "```text", help_text(sub.choices[name]), "```"]
    return "\n".join(parts) + "\n"


if __name__ == "__main__":
    print(reference(), end="")
