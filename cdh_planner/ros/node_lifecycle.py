"""The node's lifecycle (``rclpy.lifecycle``): the transitions a stock lifecycle manager
drives through ``~/change_state``. The node supplies ``_configure(config)`` (load the robot,
warm the planner, open the run file), ``close()`` (release all that) and ``execution``.

- configure: parameters checked (``params.node_config``), then ``_configure``; a bad
  parameter fails the transition (the node stays unconfigured) and is logged naming it;
- activate: plans, goals and ``~/execute`` served; deactivate: refused again, and an
  execution stopped (holding);
- cleanup, shutdown: ``close()``.
"""

from rclpy.lifecycle import TransitionCallbackReturn

from .params import node_config


class LifecycleMixin:
    """Mixed into PlannerNode (before rclpy's LifecycleNode)."""

    def start(self):
        """Configure and activate now (autostart); raises what stopped configure (InputError:
        the caller says it, in one line)."""
        self._raise_configure_error = True
        try:
            if self.trigger_configure() != TransitionCallbackReturn.SUCCESS:
                raise self._configure_error or RuntimeError("configure failed")
        finally:
            self._raise_configure_error = False
        self.trigger_activate()

    @property
    def lifecycle_state(self):
        """unconfigured, inactive, active or finalized: kept by the transitions below
        (rclpy 7.1 has no public accessor of its state machine's state)."""
        return getattr(self, "_lifecycle_state", "unconfigured")

    def on_configure(self, state):
        """Check the parameters, load the robot, warm the planner, open the run file."""
        try:
            self._configure(node_config(self._values))
        except Exception as exc:  # noqa: BLE001 - InputError: the parameter and value
            self._configure_error = exc
            if not getattr(self, "_raise_configure_error", False):
                self.get_logger().error(f"configure failed: {exc}")
            return TransitionCallbackReturn.FAILURE
        self._lifecycle_state = "inactive"
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state):
        self.active, self._lifecycle_state = True, "active"
        self.get_logger().info("active: serving plans")
        return super().on_activate(state)

    def on_deactivate(self, state):
        self.active, self._lifecycle_state = False, "inactive"
        self.get_logger().info(f"inactive: {self.execution.stop()}")
        return super().on_deactivate(state)

    def on_cleanup(self, state):
        self.close()
        self._lifecycle_state = "unconfigured"
        return super().on_cleanup(state)

    def on_shutdown(self, state):
        self.close()
        self._lifecycle_state = "finalized"
        return super().on_shutdown(state)

    def on_error(self, state):
        """A transition raised: release everything; back to unconfigured."""
        self.close()
        self._lifecycle_state = "unconfigured"
        return TransitionCallbackReturn.SUCCESS
