"""The plan JSON of two checkouts, compared: identical, or every number equal to a tolerance.

    .venv/bin/python benchmarks/compare_plans.py OTHER_CHECKOUT [problem.yaml ...]
        [--tol 1e-12] [--timeout 20] [--strategies astar gbf] [--new-keys KEY ...]

Runs ``cdh-planner plan PROBLEM --json OUT --quiet`` once with this checkout first on
PYTHONPATH and once with OTHER_CHECKOUT's, for each problem (default: every
config/problems/*.yaml), and prints one line each: identical, equal to --tol (every number
within tol x max(1, |value|); the largest absolute difference), different (the first path
that differs), or skipped (either run took longer than --timeout s). ``--strategies``:
plan each problem with each of these (``plan --strategy``) instead of the file's own; the
six-cable check after m-cable changes is ``--strategies astar gbf`` over Table 1's rows but free
flight (robot1_qs_qg, robot1_qs1_qg, robot1_qs2_qg, robot2_q1_q2, robot2_q2_q3,
robot2_q2_q3_sigma_free) and robot2_pivot: 14 plans. The planning time
(``time_s``, a clock reading) is left out of the comparison, and so are keys that only
this checkout writes and ``--new-keys`` names (e.g. ``commanded_lengths`` against a
checkout from before it). Exit code 0 when none differs.
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CLOCK_KEYS = {"time_s"}


def plan_json(checkout, problem, timeout, strategy=None):
    """The plan's JSON (dict) with ``checkout`` first on PYTHONPATH, or None on time-out."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "plan.json"
        env = dict(os.environ, PYTHONPATH=str(checkout))
        try:
            subprocess.run([sys.executable, "-m", "cdh_planner.cli", "plan", str(problem), "--json",
                            str(out), "--quiet", *(["--strategy", strategy] if strategy else [])],
                           cwd=checkout, env=env, timeout=timeout,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        except subprocess.TimeoutExpired:
            return None
        return json.loads(out.read_text()) if out.exists() else {"no output": True}


def differences(a, b, path="", new_keys=()):
    """[(path, |a - b|, scale) of numbers that differ, (path, None, None) of anything else]
    over the two JSON values; keys of ``a`` named in ``new_keys`` that ``b`` lacks are left
    out."""
    if isinstance(a, dict) and isinstance(b, dict):
        a = {k: v for k, v in a.items() if k in b or k not in new_keys}
        if set(a) != set(b):
            return [(f"{path} keys {sorted(set(a) ^ set(b))}", None, None)]
        return [d for k in a if k not in CLOCK_KEYS
                for d in differences(a[k], b[k], f"{path}.{k}", new_keys)]
    if isinstance(a, list) and isinstance(b, list):
        if len(a) != len(b):
            return [(f"{path} length {len(a)} != {len(b)}", None, None)]
        return [d for i, (x, y) in enumerate(zip(a, b))
                for d in differences(x, y, f"{path}[{i}]", new_keys)]
    numbers = (int, float)
    if isinstance(a, numbers) and isinstance(b, numbers) and not isinstance(a, bool):
        if a == b or (math.isnan(a) and math.isnan(b)):
            return []
        return [(path, abs(a - b), max(1.0, abs(a), abs(b)))]
    return [] if a == b else [(f"{path}: {a!r} != {b!r}", None, None)]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("other", help="the other checkout (e.g. the main branch's)")
    ap.add_argument("problems", nargs="*", help="problem files (default: config/problems/*.yaml)")
    ap.add_argument("--tol", type=float, default=1e-12, help="largest number difference allowed")
    ap.add_argument("--timeout", type=float, default=20.0, help="s per plan; longer ones are skipped")
    ap.add_argument("--strategies", nargs="+", choices=("astar", "gbf"), default=[None],
                    help="plan each problem with each of these (default: the file's own)")
    ap.add_argument("--new-keys", nargs="+", default=(),
                    help="keys only this checkout writes, left out of the comparison")
    args = ap.parse_args(argv)
    problems = [Path(p).resolve() for p in args.problems] or sorted((ROOT / "config" / "problems").glob("*.yaml"))
    bad = 0
    for problem, strategy in ((p, s) for p in problems for s in args.strategies):
        ours = plan_json(ROOT, problem, args.timeout, strategy)
        theirs = plan_json(Path(args.other), problem, args.timeout, strategy)
        name = problem.name + (f" {strategy}" if strategy else "")
        if ours is None or theirs is None:
            print(f"{name}: skipped (over {args.timeout:g} s)", flush=True)
            continue
        diff = differences(ours, theirs, new_keys=set(args.new_keys))
        structural = [p for p, d, _ in diff if d is None]
        largest = max((d for _, d, _ in diff if d is not None), default=0.0)
        within = all(d <= args.tol * scale for _, d, scale in diff if d is not None)
        if not diff:
            verdict = "identical"
        elif not structural and within:
            verdict = f"equal to {args.tol:g} (largest difference {largest:.2e})"
        else:
            bad += 1
            first = structural[0] if structural else max(diff, key=lambda pd: pd[1] / pd[2])[0]
            verdict = f"DIFFERENT: {len(diff)} values, largest {largest:.2e}, e.g. {first}"
        print(f"{name}: {verdict}", flush=True)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
