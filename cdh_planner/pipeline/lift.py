"""Lift: start and goal poses -> points of the navigation manifold M, or why not.

One pose plans one path however it is written: the angles are taken from the rotation
only and snapped onto the task (``model.task.end_taus``) before the lift.
"""

import numpy as np

from ..errors import InputError
from ..wrench import band_feasibility
from ..model.pose import rotation_tt
from ..model.task import end_taus
from ..status import Status

TASK_TOL = 1e-6  # m / rad: how far a start or goal may be off the task's constraint


class Lift:
    """Start and goal of one robot, task and constraint onto M (module docstring)."""

    def __init__(self, validity, constraint, in_domain):
        """``in_domain(x)``: is x inside the atlas's domain (margin above the floor)."""
        self.validity, self.constraint, self.in_domain = validity, constraint, in_domain
        self.robot, self.task = validity.robot, validity.task

    def __call__(self, start, goal, tolerance):
        """({"start": x, "goal": x}, None) or (None, (Status, message)) of two Poses,
        each within ``tolerance`` (m or rad) of the task."""
        points = {}
        for label, p, tau in self.end_poses(start, goal, tolerance):
            x, why = self.lift(label, p, tau, tolerance)
            if x is None:
                return None, why
            points[label] = x
        return points, None

    def end_poses(self, start, goal, tolerance):
        """(label, p m, tau rad) of start and goal, their angles as the query plans between
        them (``task.end_taus``: from the rotation only, snapped onto theta = 0 or pi
        within ``tolerance`` (rad, at least TASK_TOL), phi chosen there by the task and the
        other end), so one pose plans one path whichever way it was written."""
        ends = [(label, finite_vector(f"{label}.p", pose.p, 3),
                 finite_vector(f"{label}.tau", pose.tau, 3))
                for label, pose in (("start", start), ("goal", goal))]
        taus = end_taus(self.task, [tau for _, _, tau in ends], max(tolerance, TASK_TOL))
        return [(label, p, tau) for (label, p, _), tau in zip(ends, taus)]

    def lift(self, label, p, tau, tolerance):
        """(x on M, None) or (None, (reason, message)) of the pose (p m, tau rad). A pose
        within ``tolerance`` (m or rad) of the task is projected onto it (the pose of its
        own task coordinates)."""
        task = self.task
        off = float(task.residual(p[None], tau[None])[0])
        if off > max(tolerance, TASK_TOL):
            return None, (Status.INVALID, f"{label} pose is off the {task.type} task by "
                                          f"{off:.3g} (m or rad), beyond the tolerance "
                                          f"{tolerance:g}: {describe(p, tau)}")
        p, tau = (a[0] for a in task.pose(task.coords(p[None], tau[None])))
        if float(task.residual(p[None], tau[None])[0]) > TASK_TOL:  # e.g. an implicit task
            return None, (Status.INVALID, f"{label} pose is off the {task.type} task by "
                                          f"{off:.3g} (m or rad) and cannot be projected onto "
                                          f"it: {describe(p, tau)}")
        f = band_feasibility(self.robot, p[None], tau[None])
        if not f.feasible[0]:
            return None, (Status.infeasible(label), f"{label} pose is not wrench-feasible: "
                          f"{f.binding[0]} violated (margin {f.margin[0]:.3g}) at {describe(p, tau)}")
        collides = self._collision(label, p, tau)
        if collides is not None:
            return None, collides
        inaccurate = self.validity.accuracy_violation(p, tau)
        if inaccurate is not None:
            return None, (Status.infeasible(label), f"{label} pose is outside the accuracy "
                          f"limit: {inaccurate} at {describe(p, tau)}")
        x = self.constraint.lift(p, tau)
        if not self.in_domain(x):
            return None, (Status.infeasible(label), f"{label} pose is feasible but closer to the "
                          f"boundary of C than the planner's margin floor "
                          f"({self.validity.margin_floor:g}): {describe(p, tau)}")
        return x, None

    def _collision(self, label, p, tau):
        """(Status, message) if the pose (p m, tau rad) is in collision with the scene."""
        collision = self.validity.collision
        if collision is None:
            return None
        c = collision.clearance(p, rotation_tt(tau))
        if c.ok:
            return None
        return (Status.in_collision(label), f"{label} pose is in collision: {c.binding} "
                f"{c.distance * 1e3:.3g} mm apart (clearance "
                f"{self.validity.scene.clearance * 1e3:g} mm) at {describe(p, tau)}")


def finite_vector(name, v, n):
    """``v`` as n finite floats, or InputError naming ``name``."""
    try:
        a = np.asarray(v, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise InputError(name, v, f"expected {n} numbers") from None
    if a.shape != (n,):
        raise InputError(name, np.asarray(v).tolist(), f"expected {n} numbers")
    if not np.all(np.isfinite(a)):
        raise InputError(name, a.tolist(), "must be finite numbers")
    return a


def describe(p, tau):
    """A pose (p m, tau rad) for a message."""
    # 6 significant digits: a position of 1e308 (a node's goal) is not 309 digits long
    return (f"p = [{', '.join(f'{v:.6g}' for v in p)}] m, "
            f"tau = [{', '.join(f'{v:.6g}' for v in tau)}] rad")
