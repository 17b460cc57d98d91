"""Counted progress of a study on stderr, the way ``progress.chart_progress`` shows the
atlas: a tqdm bar with rate and ETA on a terminal, else one plain line at most every
``LINE_INTERVAL_S`` seconds (a log file, a pipe), nothing when quiet.

    with count_progress(quiet) as update:
        update("points", done, total)
"""

import time
from contextlib import contextmanager

from ..progress import LINE_INTERVAL_S, displayed

UNITS = {"points": "pose", "reach": "plan", "designs": "design"}


@contextmanager
def count_progress(quiet=False, stream=None, interval_s=LINE_INTERVAL_S, clock=time.monotonic):
    """Yield ``update(stage, done, total)`` (see the module docstring)."""
    with displayed(quiet, stream, _bars, lambda s: _lines(s, interval_s, clock)) as update:
        yield update


@contextmanager
def _bars(stream):
    from tqdm import tqdm

    bars = {}
    try:
        def update(stage, done, total):
            bar = bars.get(stage)
            if bar is None:
                bar = bars[stage] = tqdm(total=total, unit=UNITS.get(stage, "call"), desc=stage,
                                         leave=False, file=stream)
            bar.update(done - bar.n)
        yield update
    finally:
        for bar in bars.values():
            bar.close()


def _lines(stream, interval_s, clock):
    last = clock()
    starts = {}  # stage -> (start time, done before): a stage that starts again restarts

    def update(stage, done, total):
        nonlocal last
        now = clock()
        if stage not in starts or done < starts[stage][1]:
            starts[stage] = (now, 0)
        start = starts[stage][0]
        starts[stage] = (start, done)
        if now - last < interval_s and done < total:
            return
        if now - last < interval_s and now - start < interval_s:
            return  # a short run: no line at all
        last = now
        rate = done / max(now - start, 1e-9)
        eta = (total - done) / rate if rate > 0 else float("inf")
        print(f"{stage}: {done}/{total} {UNITS.get(stage, 'call')}s, {rate:.3g}/s, "
              f"ETA {eta:.0f} s", file=stream, flush=True)
    return update
