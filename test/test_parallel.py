"""``parallel``: a batch's blocks cover it once, in order, each starting at a multiple of the
kernel's chunk; joined they are the one call's answer; small batches and
CDH_PLANNER_THREADS=1 stay on the caller's thread."""

import os
import threading

import numpy as np
import pytest

from cdh_planner import parallel


@pytest.mark.parametrize("n, chunk, threads", [(0, 1, 2), (5, 1, 2), (4096, 512, 2),
                                                (20_000, 512, 3), (4097, 512, 8), (9999, 7, 4)])
def test_blocks_cover_the_batch_at_chunk_starts(n, chunk, threads, monkeypatch):
    monkeypatch.setenv("CDH_PLANNER_THREADS", str(threads))
    bounds = parallel.block_bounds(n, chunk)
    assert bounds[0][0] == 0 and bounds[-1][1] == n
    assert all(a1 == b0 for (_, b0), (a1, _) in zip(bounds[:-1], bounds[1:]))
    assert all(a % chunk == 0 for a, _ in bounds)
    assert len(bounds) == (1 if n < parallel.MIN_POSES else min(threads, -(-n // chunk)))


def test_joined_blocks_are_one_call_and_run_on_threads(monkeypatch):
    monkeypatch.setenv("CDH_PLANNER_THREADS", "3")
    x = np.arange(3 * parallel.MIN_POSES, dtype=float)
    together = threading.Barrier(3, timeout=120)  # passed only by three threads at once
    first = []

    def kernel(a, b):
        if a == 0:
            first.append(threading.get_ident())
        together.wait()
        return x[a:b] ** 2, np.arange(a, b)

    squares, index = parallel.blocks(kernel, len(x))
    np.testing.assert_array_equal(squares, x ** 2)
    np.testing.assert_array_equal(index, np.arange(len(x)))
    assert first == [threading.get_ident()]  # the caller takes the first block


@pytest.mark.parametrize("given", ["1", "0", "x", ""])
def test_the_thread_count_is_the_setting_or_the_cores(given, monkeypatch):
    monkeypatch.setenv("CDH_PLANNER_THREADS", given)
    expected = 1 if given == "1" else min(parallel.MAX_THREADS, len(os.sched_getaffinity(0)))
    assert parallel.threads() == expected
    together = threading.Barrier(expected, timeout=120)
    assert len(parallel.map_blocks(lambda a, b: together.wait(), 10 * parallel.MIN_POSES)) == expected


@pytest.mark.parametrize("threads", ["1", "3"])
def test_in_order_yields_every_result_in_order(threads, monkeypatch):
    """A stream of blocks (``verify``'s JSON rows): every call once, in the order given,
    however many are computed ahead."""
    monkeypatch.setenv("CDH_PLANNER_THREADS", threads)
    calls = [(a, a + 3) for a in range(0, 30, 3)]
    assert list(parallel.in_order(lambda a, b: list(range(a, b)), calls)) == [
        list(range(a, b)) for a, b in calls]
