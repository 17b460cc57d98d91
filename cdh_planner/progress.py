"""The atlas' growth on stderr, for the command line (``plan``, ``call``).

    with chart_progress(quiet=False) as update:
        update(charts, best_h)          # each progress report: charts so far, heuristic

On a terminal: a tqdm bar, cleared when done. Anywhere else (a log file, a CI log, a pipe)
the bar's carriage-return frames would pile up as lines, so it writes one plain line at
most every ``LINE_INTERVAL_S`` seconds (none for a plan shorter than that).
"""

import os
import sys
import time
from contextlib import contextmanager

LINE_INTERVAL_S = 5.0  # s between two lines when the stream is not a terminal


def _is_terminal(stream):
    try:
        return stream.isatty()
    except (AttributeError, ValueError):  # no isatty, or a closed stream
        return False


@contextmanager
def displayed(quiet, stream, bar, lines):
    """The choice every progress display makes: yield an update that does nothing when
    ``quiet``; on a terminal ``bar(stream)``'s (a context manager yielding the update);
    anywhere else ``lines(stream)`` (plain lines). ``stream`` None: stderr."""
    stream = sys.stderr if stream is None else stream
    if quiet:
        yield lambda *args: None
    elif _is_terminal(stream):
        with bar(stream) as update:
            yield update
    else:
        yield lines(stream)


@contextmanager
def chart_progress(quiet=False, stream=None, interval_s=LINE_INTERVAL_S, clock=time.monotonic):
    """Yield ``update(charts, best_h)`` that shows the chart count and the search's best
    remaining distance estimate (task units) on ``stream`` (default: stderr): a bar on a
    terminal, else a line at most every ``interval_s`` s of ``clock``; nothing if ``quiet``."""
    with displayed(quiet, stream, _bar, lambda s: _lines(s, interval_s, clock)) as update:
        yield update


@contextmanager
def _bar(stream):
    from tqdm import tqdm  # only for a terminal

    with tqdm(total=None, unit="chart", desc="atlas", leave=False, file=stream) as bar:
        def update(charts, best_h):
            bar.n = int(charts)
            bar.set_postfix(best_h=f"{best_h:.3g}", refresh=False)
            bar.refresh()
        yield update


def _lines(stream, interval_s, clock):
    start = clock()
    last = start

    def update(charts, best_h):
        nonlocal last
        now = clock()
        if now - last < interval_s:
            return
        last = now
        print(f"atlas: {int(charts)} charts, best_h {best_h:.3g}, {now - start:.0f} s",
              file=stream, flush=True)
    return update


class Held:
    """What ``stderr_held`` kept: ``text`` (str), filled when the block ends."""

    text = ""


@contextmanager
def stderr_held():
    """What C code (rcl's, Ray's logging) writes to file descriptor 2 in the block: written
    to stderr after it if the block returns, dropped if it raises (its exception says what
    matters; the yielded ``Held.text`` keeps the words for the caller to read)."""
    import tempfile  # here: only the ROS and Ray commands hold stderr (1 ms of every start)
    sys.stderr.flush()
    held = Held()
    saved = os.dup(2)
    with tempfile.TemporaryFile() as f:
        os.dup2(f.fileno(), 2)
        try:
            yield held
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            f.seek(0)
            held.text = f.read().decode(errors="replace")
    if held.text:
        sys.stderr.write(held.text)
        sys.stderr.flush()
