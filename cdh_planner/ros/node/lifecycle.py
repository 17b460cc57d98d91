"""The node's lifecycle (``rclpy.lifecycle``): the transitions a stock lifecycle manager
drives through ``~/change_state``. The node supplies ``_configure(config)`` (load the robot,
warm the planner, open the run file), ``close()`` (release all that) and ``execution``.

- configure: parameters checked (``params.node_config``), then ``_configure``; a bad
  parameter fails the transition (the node stays unconfigured) and is logged naming it;
- activate: plans, goals and ``~/execute`` served; deactivate: refused again, a running
  or waiting plan call cancelled, and an execution stopped (holding);
- cleanup, shutdown: ``close()``;
- a transition the current state does not have (by id: configure to an active node, an
  unknown id) is refused (``success`` false) and logged naming it; the node keeps serving.
  (rclpy 7.1 raises in its change_state callback, which stops the executor.)
"""

from rclpy.lifecycle import TransitionCallbackReturn

from ..core.params import node_config


class LifecycleMixin:
    """Mixed into PlannerNode (before rclpy's LifecycleNode)."""

    def guard_change_state(self):
        """Wrap ~/change_state's callback: a transition id the current state does not have
        is refused before rclpy's state machine sees it."""
        service = self._service_change_state
        handle = service.callback

        def change_state(request, response):
            transition = request.transition
            if not transition.label:
                state = self._state_machine.current_state[1]
                allowed = {t[0] for t in self._state_machine.available_transitions}
                if transition.id not in allowed:
                    self.get_logger().warning(
                        f"~/change_state: transition {transition.id} refused: not a transition "
                        f"of state {state} (allowed: {sorted(allowed)})")
                    response.success = False
                    return response
            return handle(request, response)

        service.callback = change_state

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
        self.plans.cancel_all()   # a running plan or goal ends (canceled), waiting ones too
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
