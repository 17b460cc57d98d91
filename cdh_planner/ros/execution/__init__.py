"""Executing a plan: the command outlets, the controller clients (FollowJointTrajectory) and
the simulated controller."""
