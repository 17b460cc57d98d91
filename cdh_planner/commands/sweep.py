"""``cdh-planner sweep``: compare robot designs, the workspace (and queries) of each.

    cdh-planner sweep SWEEP.yaml --out DIR [--resume] [--workers N | --no-ray]
                      [--ray-address HOST:PORT] [--quiet]

SWEEP.yaml names a robot file, the robot keys to vary (their cartesian product is the set of
designs), the workspace settings and optional problem files to plan on every design
(``studies.sweep``: the format). Writes DIR/design_NNNN.json, DIR/results.csv (one row per
design) and DIR/sweep.png, one design at a time; ``--resume`` skips the designs already done.
Exit 0 when every design is done, 2 for bad input (the whole file is checked first), 130 when
interrupted (the designs done are kept).
"""

ORDER = 50  # its place in `cdh-planner --help`
SUMMARY = "compare robot designs: the workspace (and queries) of each, to a CSV"

import os
from pathlib import Path

from ..errors import InputError
from .outputs import writing
from ..studies import sweep as sw
from ..studies.executors import make_executor
from ..studies.progress import count_progress


def add_parser(subparsers):
    """Register ``sweep`` on the top-level subparsers."""
    p = subparsers.add_parser(
        "sweep", help=SUMMARY,
        description="Run the workspace analysis (and plan the queries) on every design of the "
                    "cartesian product of the SWEEP file's varied robot keys; write one JSON "
                    "per design, results.csv and sweep.png to DIR. Exit 0 when done, 2 for bad "
                    "input, 130 when interrupted (rerun with --resume).")
    p.add_argument("sweep", help="SWEEP file (YAML: robot, vary, workspace, queries)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (created if missing)")
    p.add_argument("--resume", action="store_true", help="skip the designs already done in DIR")
    p.add_argument("--workers", type=int, metavar="N", help="Ray workers (default: the cores)")
    p.add_argument("--ray-address", metavar="HOST:PORT", help="attach to a running Ray cluster")
    p.add_argument("--no-ray", action="store_true", help="run in this process, without Ray")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=run)


def run(args):
    sweep = sw.load_sweep(args.sweep)
    out = check_out_dir(args.out)
    if args.workers is not None and not 1 <= args.workers <= 4096:
        raise InputError("--workers", args.workers, "must be between 1 and 4096")
    if args.no_ray and (args.workers not in (None, 1) or args.ray_address):
        raise InputError("--no-ray", "", "runs in this process: no --workers above 1, no --ray-address")
    sw.design_spec(sweep, sweep.designs[0])  # the workspace settings, checked before any run
    print(f"sweep {sweep.source}: {len(sweep.designs)} designs over {', '.join(sweep.keys)}"
          f"{f', {len(sweep.queries)} queries each' if sweep.queries else ''}", flush=True)
    executor = make_executor(args.workers, args.ray_address, ray=not args.no_ray)
    try:
        with count_progress(args.quiet) as update, writing("--out", out):
            docs = sw.run_sweep(sweep, out, executor, resume=args.resume, progress=update,
                                on_design=_print_design)
    finally:
        executor.close()
    from ..studies.plots import plot_sweep
    with writing("--out", out / "sweep.png"):
        tmp = out / f".sweep.{os.getpid()}.png"
        plot_sweep(tmp, [sw.design_label(d["values"]) for d in docs], _plotted(docs),
                   f"{Path(sweep.source).name}: {len(docs)} designs")
        os.replace(tmp, out / "sweep.png")
    print(f"wrote {out / 'results.csv'}, {out / 'sweep.png'} and {len(docs)} design JSONs")
    return 0


def _plotted(docs):
    names = ["feasible_fraction", "reachable_fraction"]
    return {n: [d["metrics"][n] for d in docs] for n in names
            if any(d["metrics"].get(n) is not None for d in docs)}


def _print_design(doc, skipped):
    m = doc["metrics"]
    how = "done before, kept" if skipped else f"{m['seconds']:.1f} s"
    reach = "" if m["reachable_fraction"] is None else f", reachable {100 * m['reachable_fraction']:.1f} %"
    print(f"design {doc['index']} ({sw.design_label(doc['values'])}): feasible "
          f"{100 * m['feasible_fraction']:.1f} %{reach} ({how})", flush=True)


def check_out_dir(text):
    """DIR as a Path: created if missing (its parent must exist), writable, a folder."""
    out = Path(text)
    try:
        if out.exists() and not out.is_dir():
            raise InputError("--out", text, "is a file: give a folder")
        if not out.exists():
            if not out.parent.is_dir():
                raise InputError("--out", text, "parent folder does not exist")
            out.mkdir()
        if not os.access(out, os.W_OK | os.X_OK):
            raise InputError("--out", text, "folder is not writable")
    except OSError as exc:
        raise InputError("--out", text, f"cannot create: {exc.strerror or exc}") from None
    return out
