"""Pruning old run files: a bound on what the node's recording leaves in ``log_dir``.

Only the node's own run files are ever removed (``cdh_planner_<YYYYmmdd-HHMMSS>_<pid>.mcap``
and their rotations ``..._<n>.mcap``; recovered copies, other MCAP files and anything else
are left alone), oldest first by modification time, never the file being written:

- ``max_files`` (> 0): at most this many run files are kept (the newest);
- ``max_age_days`` (> 0): run files last written longer ago than this are removed.

0 for either means no such limit. No rclpy.
"""

import re
import time
from pathlib import Path

RUN_FILE = re.compile(r"cdh_planner_\d{8}-\d{6}_\d+(_\d+)?\.mcap")
DAY_S = 86400.0


def run_files(log_dir):
    """The run files in ``log_dir``, newest first (by modification time)."""
    found = []
    for path in Path(log_dir).glob("cdh_planner_*.mcap"):
        if RUN_FILE.fullmatch(path.name) and path.is_file():
            try:
                found.append((path.stat().st_mtime, path))
            except OSError:      # removed meanwhile
                continue
    return [p for _, p in sorted(found, key=lambda item: (-item[0], item[1].name))]


def prune(log_dir, max_files=0, max_age_days=0.0, current=None, now=None):
    """Remove the run files beyond ``max_files`` and older than ``max_age_days`` (except
    ``current``); (removed paths, [(path, OSError) that could not be removed])."""
    if not max_files and not max_age_days:
        return [], []
    now = time.time() if now is None else now
    current = Path(current).resolve() if current else None
    removed, failed = [], []
    for rank, path in enumerate(run_files(log_dir)):
        if current is not None and path.resolve() == current:
            continue
        try:
            old = max_age_days and now - path.stat().st_mtime > max_age_days * DAY_S
        except OSError:
            continue
        if (max_files and rank >= max_files) or old:
            try:
                path.unlink()
                removed.append(path)
            except OSError as exc:
                failed.append((path, exc))
    return removed, failed
