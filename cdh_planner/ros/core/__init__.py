"""The node's logic without rclpy: what each ROS callback does, testable without a graph."""
