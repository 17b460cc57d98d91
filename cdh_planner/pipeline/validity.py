"""Which poses and motions the planner may use: the one place every stage asks.

A pose is valid when its margin is at least the planner's margin floor: the wrench
feasibility margin (normalised, ``wrench.band_feasibility``), with a scene the least of it
and the collision margin (``scene.collision.combine``) and, with accuracy limits
(``accuracy.AccuracyLimits``: planner.accuracy_position_m / _orientation_rad), the accuracy
margin; a motion between two poses when it is, densely (``trajectory.path_check``, with the
same collision model and margins). Poses are task
coordinate rows y (N, k) (``model.task``): M is
the graph of the closed-form lift over the feasible poses of the task, so moving y and
checking the pose keeps every point on M.
"""

import dataclasses

import numpy as np

from ..accuracy import accuracy_limits
from ..wrench import band_feasibility  # m > 6: the rule's band
from ..model.pose import quaternion_from_tau, rotation_tt, wrap_angle
from ..scene.margin import COLLISION_UNIT_M, combine
from ..trajectory.path_check import SlerpPath, TaskLinePath, check_motion, check_path

COARSE_SAMPLES = 17  # a direct motion is first checked at these few points (a cheap "no")
QUATERNION_MEMO = 4096  # orientations whose quaternion Validity remembers
KNOWN_COLLISIONS = 512  # poses in collision remembered (``KnownCollisions``; the deepest kept)


class Validity:
    """Valid poses and motions of one robot and task (module docstring)."""

    def __init__(self, robot, task, margin_floor, scene=None, feasibility=band_feasibility,
                 accuracy=(0.0, 0.0)):
        """``scene`` (scene.schema.Scene or None): obstacles the poses keep clear of;
        ``feasibility(robot, p, tau, R)``: the wrench margin asked (default the planner's,
        ``wrench.band_feasibility``; ``wrench.wrench_feasibility`` gives ``verify``'s,
        the facet test, for m > 6 cables); ``accuracy``: the largest position (m) and
        rotation (rad) error of a pose from the winches' errors, 0 for none (InputError
        without robot.length_error)."""
        self.robot, self.task, self.margin_floor = robot, task, margin_floor
        self.accuracy = accuracy_limits(robot, *accuracy)
        self.feasibility = (feasibility if self.accuracy is None
                            else _within_accuracy(feasibility, self.accuracy))
        self.periodic = np.array(task.periodic, dtype=bool)
        self._quaternion_memo = {}  # tau row bytes -> quaternion (``_quaternions``)
        self.scene = scene
        self.collision = _collision_model(robot, scene)
        self.known = None if self.collision is None else KnownCollisions(
            robot, self.collision, scene.clearance + margin_floor * COLLISION_UNIT_M)

    def pose_margins(self, p, tau=None, R=None):
        """Margins (N,) and bindings of poses (p (N, 3) m, tau (N, 3) rad or R (N, 3, 3)):
        wrench feasibility's (normalised) and, with a scene, the least of it and the
        collision margin (scene.collision.combine): positive iff valid at floor 0."""
        f = self.feasibility(self.robot, p, tau, R)
        if self.collision is None:
            return f.margin, f.binding
        return combine(f.margin, f.binding, self.collision, p, rotation_tt(tau) if R is None else R)

    def margins(self, y):
        """Margins (N,) of task coordinate rows y (N, k) (``pose_margins``)."""
        p, tau = self.task.pose(y)
        return self.pose_margins(p, tau)[0]

    @property
    def blocks(self):
        """Do poses have constraints beyond the atlas's domain (wrench feasibility): a
        scene's collisions or accuracy limits? (``clear`` then tells)"""
        return self.collision is not None or self.accuracy is not None

    def clear(self, p, tau):
        """Is the pose (p (3,) m, tau (3,) rad) clear of collision and within the accuracy
        limits by the margin floor? (True without a scene and limits)"""
        R = rotation_tt(tau)
        if self.accuracy is not None:
            if self.accuracy.margins(self.robot, p[None], R[None])[0][0] < self.margin_floor:
                return False
        return self.collision is None or bool(self.clear_of_collision(p[None], R[None])[0])

    def clear_of_collision(self, p, R):
        """Which poses (p (N, 3) m, R (N, 3, 3)) are clear of collision by the margin floor
        (the collision margin in units of COLLISION_UNIT_M): (N,) bool, one batch."""
        return self.collision.margins_only(p, R) / COLLISION_UNIT_M >= self.margin_floor

    def accuracy_violation(self, p, tau):
        """None, or one line saying which accuracy limit the pose (p (3,) m, tau (3,) rad)
        exceeds (below the margin floor counts as exceeding)."""
        if self.accuracy is None:
            return None
        R = rotation_tt(tau)
        if self.accuracy.margins(self.robot, p[None], R[None])[0][0] >= self.margin_floor:
            return None
        return self.accuracy.describe(self.robot, p, R) or (
            f"accuracy within the margin floor ({self.margin_floor:g}) of its limit")

    def pose(self, y):
        """Which rows of y (N, k) are valid poses: margin at least the floor (N,) bool."""
        return self.margins(y) >= self.margin_floor

    def direct_motion(self, y):
        """The direct motion through task coordinates y (N, k): position linear and
        orientation slerp in free flight (what a controller executes), straight lines in a
        task's coordinates otherwise (slerp would leave the task)."""
        y = np.array(y, dtype=float)
        if self.task.slerp:
            p, tau = self.task.pose(y)
            return SlerpPath(p, self._quaternions(tau))
        per = self.periodic
        y[1:, per] = y[0, per] + np.cumsum(wrap_angle(np.diff(y[:, per], axis=0)), axis=0)  # short arcs
        return TaskLinePath(self.task, y)

    def _quaternions(self, tau):
        """``quaternion_from_tau`` of the rows of tau (N, 3) rad, remembered per row: the
        search's direct motions share their ends (a chart, the other side's root), and
        the conversion costs more than the rest of building a motion. Row by row the same
        numbers as one call on all rows (the conversion treats each row alone). Read
        into its own array, so a memo cleared meanwhile (another thread) loses nothing."""
        memo, keys = self._quaternion_memo, [row.tobytes() for row in tau]
        out, new = np.empty((len(keys), 4)), []
        for k, key in enumerate(keys):
            q = memo.get(key)
            if q is None:
                new.append(k)
            else:
                out[k] = q
        if new:
            out[new] = quaternion_from_tau(tau[new])
            if len(memo) + len(new) > QUATERNION_MEMO:
                memo.clear()
            memo.update((keys[k], out[k].copy()) for k in new)
        return out

    def probe(self, y, n, motion=None, samples=None):
        """Are n evenly spaced poses of every direct motion between the rows of y valid?
        (one vectorised closed-form call; ``motion``: ``direct_motion(y)`` if already built,
        ``samples``: its ``_samples(motion, n)`` if already taken)"""
        motion = self.direct_motion(y) if motion is None else motion
        p, R = _samples(motion, n) if samples is None else samples
        bad = ~(self.pose_margins(p, R=R)[0] >= self.margin_floor)
        if self.known is not None and bad.any():
            self.known.add(p[bad], R[bad])
        return not bad.any()

    def motion(self, ya, yb):
        """Is the direct motion ya -> yb dense-valid? Not if it passes a pose known to be
        in collision (``KnownCollisions``: a probe hit the obstacle there before); else a
        few points first (most unsafe motions fail there), then the dense check."""
        y = np.array([ya, yb])
        motion = self.direct_motion(y)  # built once for the looks
        coarse = _samples(motion, COARSE_SAMPLES)  # and its coarse poses taken once
        if self.known is not None and self.known.crossed(*coarse):
            return False
        if not (self.probe(y, COARSE_SAMPLES, motion, coarse)
                and self.probe(y, 8 * COARSE_SAMPLES, motion)):
            return False
        seg = check_path(self.robot, motion, collision=self.collision,
                         feasibility=self.feasibility)[0]
        return seg.feasible and seg.unresolved == 0 and seg.worst.margin >= self.margin_floor

    def segments(self, p, q):
        """The dense check of the waypoints p (N, 3) m, quaternions q (N, 4) and the
        motion between them (position linear, orientation slerp): one
        ``trajectory.path_check`` segment report per pair."""
        return check_motion(self.robot, p, q, collision=self.collision,
                            feasibility=self.feasibility)


def _samples(motion, n):
    """Poses (p (M, 3) m, R (M, 3, 3)) at n evenly spaced points of each segment of a
    direct motion."""
    seg = np.repeat(np.arange(motion.n_segments), n)
    s = np.tile(np.linspace(0.0, 1.0, n), motion.n_segments)
    return motion(seg, s)


class KnownCollisions:
    """Poses that probes found in collision, each with the poses around it that must be
    too, so that a direct motion through them is refused without a probe (the search
    probes a direct motion to the same goal from chart after chart; behind an obstacle
    each would hit it again).

    At a pose where cable i against a primitive obstacle is at distance d (m, below
    d_min: the scene's clearance plus the margin floor, in metres), every pose whose
    platform anchor of cable i, p + R b_i, is within d_min - d of where it was is in
    collision too: each point of the cable moves no more than its platform anchor (the
    base anchor is fixed), and the distance moves no more than the cable's points
    (``CollisionModel.binding_cables``). So a motion with a sample there is invalid,
    whatever the probe's spacing. Holds the KNOWN_COLLISIONS deepest."""

    def __init__(self, robot, collision, d_min):
        """``d_min`` (m): the least valid distance (clearance + margin floor x
        COLLISION_UNIT_M)."""
        self.collision, self.d_min = collision, d_min
        self.anchors = np.asarray(robot.platform_anchors, dtype=float)
        self.cable = np.zeros(0, dtype=int)   # (K,) the binding cable
        self.centre = np.zeros((0, 3))        # (K, 3) m: its platform anchor there
        self.radius = np.zeros(0)             # (K,) m: d_min - d

    def add(self, p, R):
        """Remember the deepest of the poses (p (N, 3) m, R (N, 3, 3)) that a cable
        against an obstacle makes invalid (the others: wrench, cable pairs, meshes, are
        left out)."""
        d, cable = self.collision.binding_cables(p, R)
        if not np.any((cable >= 0) & (d < self.d_min)):
            return
        keep = np.array([np.argmin(np.where(cable >= 0, d, np.inf))])
        i = cable[keep]
        centre = p[keep] + np.einsum("nij,nj->ni", R[keep], self.anchors[i])
        self.cable = np.concatenate([self.cable, i])
        self.centre = np.concatenate([self.centre, centre])
        self.radius = np.concatenate([self.radius, self.d_min - d[keep]])
        if len(self.radius) > KNOWN_COLLISIONS:
            deepest = np.argsort(-self.radius, kind="stable")[:KNOWN_COLLISIONS]
            self.cable, self.centre, self.radius = \
                self.cable[deepest], self.centre[deepest], self.radius[deepest]

    def crossed(self, p, R):
        """Is any of the poses (p (M, 3) m, R (M, 3, 3)) within a known collision?"""
        if not len(self.radius):
            return False
        anchor = p[:, None, :] + np.einsum("mij,kj->mki", R, self.anchors[self.cable])
        return bool(np.any(np.linalg.norm(anchor - self.centre, axis=2) < self.radius))


class CollisionFreeDomain:
    """The planning manifold's constraint with collisions out of its domain, as wrench
    feasibility is for m > 6 (``configuration.inside``): the atlas centres no chart in
    collision and cuts a chart where it reaches an obstacle (``Atlas.expand``). Everything
    else is the wrapped constraint's."""

    def __init__(self, constraint, validity):
        self.constraint, self.validity = constraint, validity

    def __getattr__(self, name):
        if name in ("constraint", "validity") or name.startswith("__"):
            raise AttributeError(name)  # not set yet (copy, pickle): no recursion
        return getattr(self.constraint, name)

    def inside(self, x):
        """Is the point x of M in the domain: the constraint's own and clear of collision?"""
        return bool(self.inside_many(np.asarray(x)[None])[0])

    def inside_many(self, xs):
        """``inside`` of the rows of xs (N, n_vars): (N,) bool, one collision batch."""
        c = self.constraint
        many = getattr(c, "inside_many", None) or (
            lambda xs: [c.inside(x) for x in xs] if hasattr(c, "inside") else True)
        ok = np.asarray(many(xs), dtype=bool)
        poses = [self.constraint.pose(x) for x in xs]
        p = np.array([a for a, _ in poses]).reshape(-1, 3)
        tau = np.array([b for _, b in poses]).reshape(-1, 3)
        return ok & self.validity.clear_of_collision(p, rotation_tt(tau))


def wrapped(d, periodic):
    """Rows of task coordinates with the periodic columns wrapped to [-pi, pi)."""
    d = d.copy()
    d[:, periodic] = wrap_angle(d[:, periodic])
    return d


def _within_accuracy(feasibility, limits):
    """``feasibility`` with each pose's margin the least of its own and the accuracy
    margin (``accuracy.AccuracyLimits.combine``), as the collision margin is joined."""

    def checked(robot, p, tau=None, R=None):
        f = feasibility(robot, p, tau, R)
        R = rotation_tt(np.atleast_2d(tau)) if R is None else np.asarray(R).reshape(-1, 3, 3)
        margin, binding = limits.combine(f.margin, f.binding, robot, np.atleast_2d(p), R,
                                         f.tension_nominal)
        return dataclasses.replace(f, margin=np.where(np.isnan(margin), -np.inf, margin),
                                   binding=binding.astype(str))

    return checked


def _collision_model(robot, scene):
    """The CollisionModel of ``scene`` (None without one): coal and the compiled kernel are
    loaded only when there is a scene."""
    if scene is None:
        return None
    from ..scene.collision import CollisionModel
    return CollisionModel(robot, scene)
