"""``cdh-planner recover``: complete the run file of a killed node.

    cdh-planner recover RUN.mcap [-o OUT.mcap]

A node killed by SIGKILL (or a power cut, an OOM kill) leaves its run file without the MCAP
summary and footer, perhaps with a torn last record: ``replay`` and the project's own reader
still read it, but rosbag2, rosbags and mcap's indexed reader refuse it. ``recover`` copies
every complete message to a complete file (default ``RUN.recovered.mcap`` next to it),
drops the torn tail, and renames the service-event schemas of files recorded with rosbag2's
names (``pkg/srv/S_Event``) to the names every reader decodes (``recording/ros_schemas.py``). The
output is written in full or not at all; the input is never changed. A complete file is
copied the same way. Do not point it at the file of a node still running: it copies what
is there so far.

Exit codes: 0 recovered; 2 bad input (not a recording, damaged data in a complete file (a
chunk CRC), no complete message, an output that exists, is the input or cannot be written).
"""

ORDER = 90  # its place in `cdh-planner --help`
SUMMARY = "complete the run file of a killed node (summary, indexes, footer)"

import argparse
from pathlib import Path


def add_parser(subparsers):
    p = subparsers.add_parser(
        "recover", help=SUMMARY,
        description="Copy every complete message of a run file whose node was killed (no "
                    "MCAP summary, maybe a torn last record) to a complete file that rosbag2, "
                    "rosbags and mcap's indexed reader open. The input is not changed.",
        epilog="example:\n  cdh-planner recover ~/.ros/cdh_planner/cdh_planner_20250101-120000_42.mcap",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("run", metavar="RUN.mcap", help="the run file (of a killed node)")
    p.add_argument("-o", "--output", metavar="OUT.mcap",
                   help="where to write the complete file (default: RUN.recovered.mcap; "
                        "must not exist)")
    p.set_defaults(func=run)


def default_output(path):
    path = Path(path)
    stem = path.name[:-5] if path.name.endswith(".mcap") else path.name
    return path.with_name(f"{stem}.recovered.mcap")


def run(args):
    from ..errors import InputError
    from ..recording.mcap_log import NotARecording, check_recording, recover
    from .outputs import check_output, writing
    src = Path(args.run)
    try:
        check_recording(src)
    except FileNotFoundError:
        raise InputError("RUN", str(src), "file not found") from None
    except NotARecording as exc:
        raise InputError("RUN", str(src), str(exc)) from None
    # the output, checked before the work
    out = check_output("--output", args.output if args.output else default_output(src),
                       inputs=[("the run file RUN", src)])
    if out.exists():
        raise InputError("--output", str(out), "exists already: give another -o, or remove "
                                               "it first")
    try:
        with writing("--output", out):
            result = recover(src, out)
    except NotARecording as exc:
        raise InputError("RUN", str(src), str(exc)) from None
    # the file tells a summary cut short (closing, a write failed) from none at all (a
    # kill, a power cut, or a write that failed before: no cause is certain)
    if result.complete:
        state = "it was complete already"
    elif result.summary_begun:
        state = (f"its summary was cut short: the recording was being closed when a write "
                 f"failed (a full disk?); {result.dropped_bytes} bytes after the last "
                 f"complete message dropped")
    else:
        state = (f"it had no summary: its recording did not end normally (the node killed, "
                 f"or a write failed, e.g. a full disk); {result.dropped_bytes} bytes after "
                 f"the last complete message dropped")
    print(f"{src}: {result.messages} messages on {result.topics} topics written to {out} "
          f"({state})")
    if result.renamed_schemas:
        print(f"  service-event schemas renamed to the names every reader decodes: "
              f"{', '.join(result.renamed_schemas)}")
    return 0
