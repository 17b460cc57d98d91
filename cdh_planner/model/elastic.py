"""Elastic cables (numpy only): a cable of unstretched length L0 (m) under tension t (N) is
L0 (1 + t / EA) long, EA its axial stiffness (N, ``robot.cable_stiffness``). A robot
without a stiffness has rigid cables: every function here then gives the rigid answer.
"""

import numpy as np


def is_elastic(robot):
    """Does the robot file give its cables a stiffness?"""
    return robot.cable_stiffness is not None


def unstretched_lengths(robot, L, t):
    """L0 (N, m) m: the unstretched lengths that are L (N, m) m long under tensions t (N, m) N,
    L0 = L / (1 + t / EA); L itself for rigid cables."""
    L = np.asarray(L, dtype=float)
    if not is_elastic(robot):
        return L.copy()
    return L / (1.0 + np.asarray(t, dtype=float) / robot.cable_stiffness)


def stretched_tensions(robot, L, L0):
    """Tensions (N, m) N of cables of unstretched length L0 pulled to length L (both m):
    EA (L - L0) / L0, zero where slack (a cable cannot push)."""
    return np.maximum(0.0, robot.cable_stiffness * (np.asarray(L) - L0) / L0)


def axial_stiffness(robot, L0):
    """k_i = EA_i / L0_i (N/m) of cables of unstretched lengths L0 (N, m) m."""
    return robot.cable_stiffness / np.asarray(L0, dtype=float)
