"""Progress output (progress.py): a bar on a terminal, sparse plain lines elsewhere.
A fake clock and in-memory streams: no timing."""

import io

from cdh_planner.progress import chart_progress


class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


class Terminal(io.StringIO):
    def isatty(self):
        return True


def test_not_a_terminal_writes_at_most_one_line_per_interval():
    stream, clock = io.StringIO(), FakeClock()
    with chart_progress(stream=stream, interval_s=5.0, clock=clock) as update:
        for k in range(640):  # 640 reports over 20 s of the fake clock (exact binary steps)
            clock.t += 1.0 / 32
            update(k, 0.5)
    lines = stream.getvalue().splitlines()
    assert len(lines) == 4  # at 5, 10, 15, 20 s
    assert "\r" not in stream.getvalue()
    assert lines[0].startswith("atlas: ") and "charts" in lines[0] and lines[0].endswith(" 5 s")


def test_a_short_plan_off_a_terminal_writes_nothing():
    stream, clock = io.StringIO(), FakeClock()
    with chart_progress(stream=stream, clock=clock) as update:
        for k in range(18):  # a 1 s plan: 18 frames
            clock.t += 1.0 / 18
            update(k, 0.1)
    assert stream.getvalue() == ""


def test_a_terminal_gets_the_bar():
    stream = Terminal()
    with chart_progress(stream=stream) as update:
        update(3, 0.25)
        update(7, 0.125)
    out = stream.getvalue()
    assert "atlas" in out and "\r" in out and "7chart" in out


def test_quiet_writes_nothing_anywhere():
    for stream in (io.StringIO(), Terminal()):
        with chart_progress(quiet=True, stream=stream) as update:
            update(5, 0.1)
        assert stream.getvalue() == ""


def test_a_closed_stream_counts_as_not_a_terminal():
    stream = io.StringIO()
    stream.close()
    with chart_progress(stream=stream, clock=FakeClock()) as update:
        update(1, 0.1)  # inside the interval: nothing written, nothing raised
