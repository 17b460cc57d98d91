"""Large batches of poses on the machine's cores. The compiled kernels release the GIL
while their machine code runs (``aot``), so a batch cut into blocks of poses runs on
threads side by side: ``blocks`` (``map_blocks`` for other work in blocks; ``in_order``
for a stream of blocks, such as ``verify``'s JSON rows; ``beside`` for a step beside the
caller's). Blocks start at multiples of a kernel's chunk (the
centred rule's Newton starts cold at a chunk's first pose), so the answers are the same
bits on any number of threads.

The threads: the cores this process may run on (``os.sched_getaffinity``), at most
MAX_THREADS, or ``CDH_PLANNER_THREADS`` (1: every batch on the calling thread). Batches
below MIN_POSES stay on the calling thread: a hand-over costs ~0.1 ms, the kernels
1 - 10 us a pose.
"""

import os
import threading
from collections import deque

import numpy as np

MIN_POSES = 4096
MAX_THREADS = 8
_pool = None
_pool_made = threading.Lock()


def threads():
    """How many threads a batch may use (module docstring): >= 1."""
    given = os.environ.get("CDH_PLANNER_THREADS", "")
    if given.strip().isdigit() and int(given) >= 1:
        return int(given)
    return max(1, min(MAX_THREADS, len(os.sched_getaffinity(0))))


def block_bounds(n, chunk=1):
    """The blocks [a, b) of n poses, one a thread (as many as ``threads()``, fewer for a
    small batch), each starting at a multiple of ``chunk``."""
    k = threads() if n >= MIN_POSES else 1
    chunks = -(-n // max(chunk, 1))
    cuts = [min(n, chunk * (chunks * i // k)) for i in range(k + 1)]
    return [(a, b) for a, b in zip(cuts[:-1], cuts[1:]) if b > a] or [(0, n)]


def blocks(kernel, n, chunk=1):
    """``kernel(a, b)`` (an array or a tuple of arrays, first axis the poses a <= q < b)
    over the blocks of ``block_bounds(n, chunk)`` on threads (``map_blocks``), joined along
    the first axis as one call over all n poses returns them."""
    parts = map_blocks(kernel, n, chunk)
    if len(parts) == 1:
        return parts[0]
    if isinstance(parts[0], tuple):
        return tuple(np.concatenate(column) for column in zip(*parts))
    return np.concatenate(parts)


def map_blocks(work, n, chunk=1):
    """[``work(a, b)`` for the blocks [a, b) of ``block_bounds(n, chunk)``], on threads, the
    caller's thread taking the first block."""
    bounds = block_bounds(n, chunk)
    rest = [_threads().submit(work, a, b) for a, b in bounds[1:]]
    return [work(*bounds[0])] + [f.result() for f in rest]


def in_order(work, calls):
    """``work(*args)`` for each ``args`` of ``calls``, yielded in order, the next ones
    (as many as ``threads()``) computed ahead on threads meanwhile: a stream whose consumer
    (a file's writes) runs beside its producers."""
    if threads() == 1:
        yield from (work(*args) for args in calls)
        return
    ahead = deque()
    for args in calls:
        ahead.append(_threads().submit(work, *args))
        if len(ahead) > threads():
            yield ahead.popleft().result()
    while ahead:
        yield ahead.popleft().result()


def beside(work, *args):
    """``work(*args)`` on a thread beside the caller's (a Future): independent steps of one
    command at once, where their compiled kernels or their I/O release the GIL."""
    return _threads().submit(work, *args)


def _threads():
    global _pool
    with _pool_made:  # the node calls kernels from more than one thread
        if _pool is None:
            # imported here: 2.4 ms (logging with it) that a small command never needs
            from concurrent.futures import ThreadPoolExecutor
            _pool = ThreadPoolExecutor(MAX_THREADS - 1, thread_name_prefix="cdh_blocks")
    return _pool
