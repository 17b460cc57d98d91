"""The physics plant: the robot of a robot file as a MuJoCo model the plans run on (no rclpy;
the planner never imports this package, nor mujoco).

- ``mjcf``: the robot (and a scene's obstacles) as MJCF: the base frame is MuJoCo's world,
  each cable a spatial tendon from its platform site to its base site driven by a ``general``
  actuator (gear -1: the actuator force is the tension, force range [0, inf): it only pulls),
  the platform a free body with the load's mass, inertia and centre of mass;
- ``plant``: ``SimulatedRobot``, MuJoCo stepped at 1 kHz under a command of unstretched
  lengths, measuring what a robot's sensors would (winch positions, load cells, a tracker);
- ``commands``: command sources (a JointTrajectoryController's interpolation of a trajectory,
  a stream of setpoints, a hold);
- ``run``: a plan's trajectory run on the plant, recorded, and its verdicts (slack, overload,
  margins against the limits and the published envelope, tracking error, contacts).
"""
