"""Elastic cables: the unstretched length that carries a tension, and back."""

import numpy as np

from cdh_planner.model.elastic import axial_stiffness, stretched_tensions, unstretched_lengths
from cdh_planner.model.robot import load_robot
from conftest import REPO


def test_unstretched_length_carries_its_tension_back():
    robot = load_robot(REPO / "config" / "robot2_8.yaml")
    rng = np.random.default_rng(1)
    L = rng.uniform(0.2, 0.6, size=(5, 8))
    t = rng.uniform(0.1, 6.58, size=(5, 8))
    L0 = unstretched_lengths(robot, L, t)
    assert np.all(L0 < L)
    np.testing.assert_allclose(stretched_tensions(robot, L, L0), t, rtol=1e-12)
    np.testing.assert_allclose(L0 * (1 + t / robot.cable_stiffness), L, rtol=1e-14)
    # a shorter pull is slack, not a push
    assert np.all(stretched_tensions(robot, 0.99 * L0, L0) == 0.0)
    # the stiffness k = EA / L0: dt = k dL for a small stretch
    dL = 1e-7
    np.testing.assert_allclose((stretched_tensions(robot, L + dL, L0) - t) / dL,
                               axial_stiffness(robot, L0), rtol=1e-6)
