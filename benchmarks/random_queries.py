"""Seeded random free-flight queries: both ends wrench-feasible, the straight motion unsafe.

    queries = random_free_queries(robot, count=10, seed=0)   # [FreeQuery, ...]

The free-flight query a user makes most ("from this pose to that one") where the direct
motion (position linear, orientation slerp) is not safe, so a planner has work to do.
Poses are drawn by rejection: position uniform in the box under the base anchors that the
cables can reach (``model.robot.workspace_box``), orientation within ``max_tilt`` of the robot's home orientation (that of
the pose with the largest margin among random ones: loads hang, they do not tumble), kept
when the closed-form margin is at least ``min_margin``. Pairs are kept when the dense
check of the straight motion fails.
The same seed gives the same queries on every machine (numpy's PCG64).
"""

from dataclasses import dataclass

import numpy as np
from cdh_planner.ports.rotation import Rotation

from cdh_planner.wrench import wrench_feasibility  # m > 6: the facet test
from cdh_planner.model.pose import Pose, quaternion_from_tau, tau_from_rotation
from cdh_planner.model.robot import workspace_box
from cdh_planner.trajectory.path_check import SlerpPath, check_path

BATCH = 20_000  # poses drawn per rejection round
PROBE_SAMPLES = 200  # points of a straight motion probed before the dense check
MAX_ROUNDS = 200


@dataclass(frozen=True)
class FreeQuery:
    """``start`` and ``goal`` poses (m, rad); ``margin`` of each end; where the straight
    motion first leaves C (``unsafe_at``, fraction of the way)."""

    start: Pose
    goal: Pose
    margins: tuple
    unsafe_at: float


def home_orientation(robot, draws=100_000, seed=0):
    """The orientation (Rotation) of the pose with the largest margin among random ones."""
    rng = np.random.default_rng(seed)
    lo, hi = workspace_box(robot)
    p = rng.uniform(lo, hi, size=(draws, 3))
    R = Rotation.random(draws, rng)
    return R[int(np.argmax(wrench_feasibility(robot, p, R=R.as_matrix()).margin))]


def feasible_poses(robot, count, rng, min_margin=0.01, max_tilt=np.pi / 3, home=None,
                   feasibility=wrench_feasibility):
    """``count`` random wrench-feasible poses within ``max_tilt`` (rad) of the ``home``
    orientation (default: ``home_orientation``): positions (count, 3) m, tau (count, 3) rad.
    ``feasibility``: the test whose margin is at least ``min_margin`` (the planner's domain
    is ``band_feasibility``'s, stronger for more than six cables)."""
    lo, hi = workspace_box(robot)
    home = home_orientation(robot) if home is None else home
    ps, taus = [], []
    for _ in range(MAX_ROUNDS):
        p = rng.uniform(lo, hi, size=(BATCH, 3))
        axis = rng.standard_normal((BATCH, 3))
        axis /= np.linalg.norm(axis, axis=1, keepdims=True)
        angle = max_tilt * rng.random((BATCH, 1)) ** (1 / 3)  # uniform in the ball of rotation vectors
        R = (home * Rotation.from_rotvec(axis * angle)).as_matrix()
        ok = np.flatnonzero(feasibility(robot, p, R=R).margin >= min_margin)
        ps.extend(p[ok])
        taus.extend(tau_from_rotation(R[ok]))
        if len(ps) >= count:
            return np.array(ps[:count]), np.array(taus[:count])
    raise RuntimeError(f"fewer than {count} feasible poses in {MAX_ROUNDS * BATCH} draws")


def random_free_queries(robot, count, seed=0, min_margin=0.01, max_tilt=np.pi / 3,
                        feasibility=wrench_feasibility, connected=None):
    """``count`` FreeQuery, reproducible from ``seed``; ``feasibility``: the test of the
    ends (as in ``feasible_poses``) and of the straight motion. ``connected(tau_a, tau_b)``
    (tilt-and-torsion, rad; optional): False for a pair known to have no path (ends on
    opposite sides of an orientation cut no feasible pose lies on), which is left out."""
    rng = np.random.default_rng(seed)
    home = home_orientation(robot)
    out = []
    for _ in range(MAX_ROUNDS):
        p, tau = feasible_poses(robot, 2 * count, rng, min_margin, max_tilt, home, feasibility)
        margins = feasibility(robot, p, tau).margin
        for a in range(0, len(p) - 1, 2):
            b = a + 1
            if connected is not None and not connected(tau[a], tau[b]):
                continue
            motion = SlerpPath(p[[a, b]], quaternion_from_tau(tau[[a, b]]))
            s = np.linspace(0.0, 1.0, PROBE_SAMPLES)
            pp, RR = motion(np.zeros(s.size, dtype=int), s)
            if np.all(feasibility(robot, pp, R=RR).margin > 0):
                continue  # most likely safe: not a query that needs a planner
            seg = check_path(robot, motion, feasibility=feasibility)[0]
            if seg.feasible:  # the probe's infeasible pose was between the dense samples
                continue
            out.append(FreeQuery(Pose(p[a], tau[a]), Pose(p[b], tau[b]),
                                 (float(margins[a]), float(margins[b])), float(seg.first_unsafe.s)))
            if len(out) == count:
                return out
    raise RuntimeError(f"fewer than {count} queries with an unsafe straight motion")
