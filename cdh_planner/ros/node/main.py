"""Running the node as a process: ``cdh-planner node`` (``commands/node.py``) calls
``main``. The executor spins on a thread; the main thread waits for SIGINT / SIGTERM (rclpy
7.1's own SIGTERM handler does not wake a waiting executor, so both are handled here), then
shuts down in order: waiting plan calls answered, execution held, run file closed.
"""

import os
import signal
import sys
import threading

import rclpy
import rclpy.signals

from ...errors import InputError, clip
from ..context import init_context
from .planner_node import EXECUTOR_THREADS, PlannerNode, default_planner_factory

SHUTDOWN_JOIN_S = 5.0


def main(ros_args=(), planner_factory=default_planner_factory, log=print):
    """Run the node until SIGINT / SIGTERM; return the exit code: 0 after a clean shutdown
    (run file closed), 1 when the executor stopped on an error (a crash is never exit 0),
    2 when it cannot start (bad parameters: one line naming the parameter and value).
    ``ros_args``: what follows ``--ros-args``."""
    from ..executors import NodeExecutor

    stop = threading.Event()
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda *_: stop.set())
    try:
        context = init_context(["cdh-planner", "--ros-args", *ros_args],
                               signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    except InputError as exc:  # rcl's refusal of the arguments or the environment
        log(f"cdh-planner node: error: {exc}")
        return 2
    try:
        node = PlannerNode(planner_factory, context=context)
    except Exception as exc:  # noqa: BLE001 - InputError, or a parameter of the wrong type
        log(f"cdh-planner node: error: {exc if isinstance(exc, InputError) else clip(exc, 400)}")
        rclpy.try_shutdown(context=context)
        return 2
    executor = NodeExecutor(num_threads=EXECUTOR_THREADS, context=context)
    executor.add_node(node)
    crashed = []

    def spin():
        try:
            executor.spin()
        except Exception as exc:  # noqa: BLE001 - e.g. the context shut down under it
            if not stop.is_set():
                crashed.append(exc)
                log(f"cdh-planner node: executor stopped: {clip(exc, 400)}")
        finally:
            stop.set()

    spinner = threading.Thread(target=spin, name="executor", daemon=True)
    spinner.start()
    while not stop.wait(1.0):
        pass
    node.get_logger().info("shutting down")
    node.begin_shutdown()                 # a running plan ends at its next progress report
    executor.shutdown(timeout_sec=2.0)
    # Wait for the executor thread to leave spin(): a thread still inside rclpy's wait when
    # the interpreter exits aborts the process ("terminate called without an active
    # exception", exit 134 instead of 0).
    spinner.join(timeout=SHUTDOWN_JOIN_S)
    node.close()                          # hold the winches, close the run file
    abandoned = node.plans is not None and node.plans.planning
    stuck = spinner.is_alive()
    node.destroy_node()
    rclpy.try_shutdown(context=context)
    if abandoned or stuck:  # a thread that cannot be joined: leave without waiting for it
        log("cdh-planner node: " + ("a plan was still running at shutdown; abandoned"
                                    if abandoned else "the executor did not stop; left"))
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(1 if crashed else 0)
    return 1 if crashed else 0
