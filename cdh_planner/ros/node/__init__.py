"""The PlannerNode (``planner_node.py``) and its rclpy adapters; ``main.py`` runs it."""
