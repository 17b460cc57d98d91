"""Old run files pruned by count and age: only the node's own run files, oldest
first, never the one being written; the node's RunLog prunes when it opens a file."""

import os
import time

from cdh_planner.ros.core.run_log import RunLog, log_limits
from cdh_planner.ros.core.run_pruning import DAY_S, prune, run_files

NOW = 1_800_000_000.0


def _make(folder, names_ages, now=NOW):
    """Files named ``name`` last written ``age`` days before ``now``."""
    for name, age in names_ages:
        path = folder / name
        path.write_bytes(b"x")
        os.utime(path, (now - age * DAY_S, now - age * DAY_S))


RUNS = [(f"cdh_planner_20260101-00000{i}_42.mcap", 10 - i) for i in range(5)]   # ages 10..6
OTHERS = [("cdh_planner_20260101-000000_42.recovered.mcap", 50), ("notes.mcap", 50),
          ("cdh_planner_x.mcap", 50)]


def test_count_keeps_the_newest_and_touches_nothing_else(tmp_path):
    _make(tmp_path, RUNS + OTHERS)
    removed, failed = prune(tmp_path, max_files=2, now=NOW)
    assert failed == [] and sorted(p.name for p in removed) == sorted(n for n, _ in RUNS[:3])
    assert [p.name for p in run_files(tmp_path)] == [RUNS[4][0], RUNS[3][0]]
    assert all((tmp_path / n).exists() for n, _ in OTHERS)


def test_age_removes_the_old_ones_and_never_the_current_file(tmp_path):
    _make(tmp_path, RUNS)
    current = tmp_path / RUNS[0][0]                     # the oldest, but being written
    removed, _ = prune(tmp_path, max_age_days=7.5, current=current, now=NOW)
    assert sorted(p.name for p in removed) == sorted(n for n, _ in RUNS[1:3])   # ages 9, 8
    assert current.exists()


def test_no_limits_remove_nothing(tmp_path):
    _make(tmp_path, RUNS)
    assert prune(tmp_path, now=NOW) == ([], [])
    assert len(run_files(tmp_path)) == len(RUNS)


def test_the_run_log_prunes_when_it_opens_a_file(tmp_path):
    old = [(name, 10.0 + i) for i, (name, _) in enumerate(RUNS)]
    _make(tmp_path, old, now=time.time())
    lines = []
    limits = log_limits({"log_max_files": 3, "log_max_age_days": 0.0})
    log = RunLog(str(tmp_path), True, warn=lines.append, info=lines.append, **limits)
    try:
        path = log.open()
        kept = [p.name for p in run_files(tmp_path)]
        assert len(kept) == 3 and os.path.basename(path) in kept
        assert any("removed 3 old run file(s)" in line for line in lines), lines
    finally:
        log.close()
