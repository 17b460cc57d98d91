"""Ray's start-up (target: under 3 s): ``ray.init`` of a local Ray and the first answer of
every actor, per set of options, each in a fresh process, the variants interleaved round by
round (loads vary on a shared machine), medians printed.

    python benchmarks/ray_startup.py [--rounds 5] [--workers 2] [--variants all]

Variants, each adding to the one before (``OPTIONS``): "before" the options of the first
version (no usage-stats switch), "usage" RAY_USAGE_STATS_ENABLED=0, "store" a 100 MB object
store, "metrics" no metrics collection, "noprestart" no idle workers started with the
raylet (the actors start after ``ray.init``), "lean" no autoscaler monitor and no log monitor
(two Python processes fewer; Ray's private RayParams, patched here only), "shipped" the executor's own start
(``executors.start_local_ray``, what the commands run). Prints numbers only (machines differ).
"""

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

BASE = dict(include_dashboard=False, logging_level="ERROR", log_to_driver=False)
OPTIONS = {  # name: (ray.init keywords, environment)
    "before": (BASE, {}),
    "usage": (BASE, {"RAY_USAGE_STATS_ENABLED": "0"}),
    "store": ({**BASE, "object_store_memory": 100 * 2 ** 20}, {"RAY_USAGE_STATS_ENABLED": "0"}),
    "metrics": ({**BASE, "object_store_memory": 100 * 2 ** 20,
                 "_system_config": {"enable_metrics_collection": False}},
                {"RAY_USAGE_STATS_ENABLED": "0"}),
    "noprestart": ({**BASE, "object_store_memory": 100 * 2 ** 20,
                    "_system_config": {"enable_metrics_collection": False,
                                       "enable_worker_prestart": False}},
                   {"RAY_USAGE_STATS_ENABLED": "0"}),
    "lean": ({**BASE, "object_store_memory": 100 * 2 ** 20,
              "_system_config": {"enable_metrics_collection": False}, "lean": True},
             {"RAY_USAGE_STATS_ENABLED": "0"}),
    "shipped": (None, {}),
}

CHILD = r"""
import json, os, sys, time
t0 = time.perf_counter()
import ray
t1 = time.perf_counter()
kw, workers = json.loads(sys.argv[1]), int(sys.argv[2])
if kw is None:
    from cdh_planner.studies.executors import start_local_ray
    t1 = time.perf_counter()  # the command has imported it already
    start_local_ray(workers)
else:
    if kw.pop("lean", False):  # Ray's private parameters: no autoscaler monitor, no log monitor
        import ray._private.parameter as parameter
        original = parameter.RayParams.__init__
        def lean(self, *args, **kwargs):
            original(self, *args, **kwargs)
            self.no_monitor, self.include_log_monitor = True, False
        parameter.RayParams.__init__ = lean
    ray.init(address="local", num_cpus=workers, **kw)
t2 = time.perf_counter()

@ray.remote(num_cpus=1)
class Probe:
    def pid(self):
        return os.getpid()

actors = [Probe.remote() for _ in range(workers)]
ray.get([a.pid.remote() for a in actors])
t3 = time.perf_counter()
ray.shutdown()
t4 = time.perf_counter()
print(json.dumps({"import": t1 - t0, "init": t2 - t1, "actors": t3 - t2, "shutdown": t4 - t3}))
"""


def run_once(name, workers):
    kw, env = OPTIONS[name]
    env = {**os.environ, "PYTHONPATH": str(ROOT), **env}
    out = subprocess.run([sys.executable, "-c", CHILD, json.dumps(kw), str(workers)],
                         capture_output=True, text=True, env=env, timeout=120, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--variants", nargs="+", default=list(OPTIONS), choices=list(OPTIONS))
    args = ap.parse_args(argv)
    times = {name: [] for name in args.variants}
    for _ in range(args.rounds):
        for name in args.variants:  # interleaved: each round sees the same load
            times[name].append(run_once(name, args.workers))
    print(f"load average {os.getloadavg()[0]:.2f} (1 min) at the end; {args.rounds} rounds, "
          f"{args.workers} CPUs; medians, s (min - max of init + actors)")
    for name, runs in times.items():
        med = {k: statistics.median(r[k] for r in runs) for k in runs[0]}
        total = [r["init"] + r["actors"] for r in runs]
        print(f"  {name:8s} import {med['import']:.2f}  init {med['init']:.2f}  "
              f"actors {med['actors']:.2f}  init+actors {statistics.median(total):.2f} "
              f"({min(total):.2f} - {max(total):.2f})  shutdown {med['shutdown']:.2f}")


if __name__ == "__main__":
    main()
