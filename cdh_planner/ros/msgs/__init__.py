"""Conversions between the library's objects (paths, envelopes, scenes) and ROS messages."""
