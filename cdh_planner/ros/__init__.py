"""The ROS 2 side of cdh_planner, in four parts and a client:

- ``core/``: the node's logic without rclpy (plan service, plan requests, execution state,
  scene state, diagnostics, frames, parameters, run log, live state); tests drive it directly
  and ``test_layers.py`` checks that nothing under it imports rclpy;
- ``msgs/``: conversions between the library's objects and ROS messages (no rclpy either);
- ``node/``: the PlannerNode and its thin rclpy adapters (``node/main.py`` runs it);
- ``execution/``: command outlets, controller clients, the simulated controller;
- ``client.py`` (PlannerClient), ``replay.py``, ``interface.py`` (names and QoS), ``polled.py``
  (subscriptions read on demand, not served by the executor), ``actions.py`` (an action
  client whose futures always complete), ``context.py``, ``isolation.py``: what clients, commands and tests share with the node.
"""
