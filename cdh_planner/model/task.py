"""Tasks, the constraints on the platform pose that say which poses a motion may use. Each
task is one class, a plug-in.

A task maps its free coordinates y (shape (N, k), ``names``) to poses (p m, tau rad) and
back. It also gives the equations C(p, tau, v) = 0 that restrict the navigation manifold to
it (paper Eq. 15), with their Jacobian. ``v`` holds the task's own variables, the first
``n_vars`` task coordinates when they are not pose coordinates (the sphere's alphas).
``register`` puts a class in ``TASKS`` (type -> class). That registry drives the problem
file (``task_from_dict``), the node's parameters (``task.<field>``), ``slice`` and the
planner's default cost. A new task is one registered class:

- ``FreeTask``: y = (x, y, z, phi, theta, sigma), free flight (n = 6).
- ``SliceTask``: some pose coordinates fixed (the paper's Robot 1 slices).
- ``SphereTask``: the paper's Eq. 17, P on a sphere facing its centre,
  y = (alpha1, alpha2) or (alpha1, alpha2, sigma) with free torsion.
- ``PivotTask``: a tool point t (platform frame) stays at c (base frame), p + R t = c,
  orientation free: y = (phi, theta, sigma), n = 3.
- ``ImplicitTask`` (library only): the caller's own C(p, tau) = 0.
"""

from dataclasses import dataclass, field, replace
from typing import ClassVar

import numpy as np

from ..errors import MAX_POSITION_M, InputError, check_keys
from ..fields import BOOL, NUMBER, NUMBERS, Field, declared, read, with_key
from .pose import (on_singular_set, rotation_angle_between, rotation_tt, rotation_tt_derivatives,
                   tau_from_rotation, wrap_angle)

POSE_NAMES = ("x", "y", "z", "phi", "theta", "sigma")


@dataclass(frozen=True)
class Coordinate:
    """A task coordinate: ``unit`` "m" or "rad", whether it is ``periodic`` (2 pi), its
    ``bounds`` (lo, hi) if it has natural ones, and its picture ``label`` (TeX)."""

    name: str
    unit: str
    periodic: bool = False
    bounds: tuple = None
    label: str = ""


def _coordinates(*items):
    return {c.name: c for c in items}


# Every coordinate a registered task uses; a task with new ones declares them (``coordinates``).
COORDINATES = _coordinates(
    Coordinate("x", "m", label="$x$"), Coordinate("y", "m", label="$y$"),
    Coordinate("z", "m", label="$z$"),
    Coordinate("phi", "rad", True, (-np.pi, np.pi), r"$\phi$"),
    Coordinate("theta", "rad", False, (0.0, np.pi), r"$\theta$"),
    Coordinate("sigma", "rad", True, (-np.pi, np.pi), r"$\sigma$"))


def _field(default, kind=NUMBER, **meta):
    """A task dataclass field declared by its ``fields.Field`` (problem-file key = the
    attribute, node parameter ``task.<name>``): NUMBER, NUMBERS (a point: 3 numbers, kept as
    a tuple) or BOOL; every number (m or rad) lies within +-``errors.MAX_POSITION_M``."""
    factory = {"default_factory": lambda: default} if isinstance(default, (list, dict)) else \
        {"default": default}
    if kind in (NUMBER, NUMBERS):
        meta.setdefault("limit", MAX_POSITION_M)
    if kind == NUMBERS:
        meta.setdefault("count", 3)
    return field(**factory, metadata={"task": Field("", kind, **meta)})


def _center():
    # one parameter, task.center, for the two tasks that have a point in the base frame
    return _field((0.0, 0.0, 0.0), NUMBERS, unit="m, base frame",
                  description="sphere task: centre of the sphere; pivot task: the point c "
                              "the tool point stays at")


TASKS = {}


def register(cls):
    """Class decorator: make ``cls`` a task of problem files, node parameters and slice.

    Tasks share one ``task.<field>`` namespace of node parameters: a parameter that two
    tasks declare (task.center) must be declared alike (the same Field, default included), as
    must a coordinate two tasks introduce, and a type is registered once; a conflict is
    refused here (ValueError naming the task) rather than giving one task the other's
    parameter or coordinate."""
    if cls.type in TASKS and TASKS[cls.type] is not cls:
        raise ValueError(f"task type {cls.type!r} is already registered ({TASKS[cls.type].__name__})")
    shared = task_parameters()
    for f in cls.parameters():
        if f.key in shared and not _same_parameter(shared[f.key][0], f):
            other, first = shared[f.key]
            raise ValueError(f"task {cls.type!r}: parameter {f.key} ({f.kind}, default "
                             f"{f.default!r}) is declared otherwise by task {first!r} "
                             f"({other.kind}, default {other.default!r})")
    for c in cls.coordinates:
        if c.name in COORDINATES and COORDINATES[c.name] != c:
            raise ValueError(f"task {cls.type!r}: coordinate {c.name} ({c.unit}) is declared "
                             f"otherwise already ({COORDINATES[c.name].unit})")
    TASKS[cls.type] = cls
    COORDINATES.update({c.name: c for c in cls.coordinates})
    return cls


def task_parameters():
    """node parameter -> (its Field, type of the first task declaring it), over every
    registered task (``register`` keeps them consistent)."""
    out = {}
    for cls in TASKS.values():
        for f in cls.parameters():
            out.setdefault(f.key, (f, cls.type))
    return out


def _same_parameter(a, b):
    """Two Fields alike (NaN defaults equal)."""
    da, db = a.default, b.default
    nan = isinstance(da, float) and isinstance(db, float) and np.isnan(da) and np.isnan(db)
    return replace(a, default=None) == replace(b, default=None) and (nan or da == db)


class Task:
    """Base of every task (module doc). Subclasses are frozen dataclasses giving ``type``,
    ``names``, ``pose``, ``coords``, ``residual`` and, when they restrict the pose,
    ``equations``."""

    type: ClassVar[str] = ""
    coordinates: ClassVar[tuple] = ()      # Coordinates the task introduces
    n_vars: ClassVar[int] = 0              # task variables beside the pose in the manifold
    costs: ClassVar[tuple] = ("se3",)      # path costs that make sense (planner.task_cost)
    slerp: ClassVar[bool] = False          # every pose is on the task: direct motions slerp

    @property
    def names(self):
        return POSE_NAMES

    @property
    def periodic(self):
        """Per task coordinate: is it an angle modulo 2 pi?"""
        return tuple(COORDINATES[n].periodic for n in self.names)

    @property
    def default_cost(self):
        return self.costs[0]

    # ----- the equations (paper Eq. 15) -------------------------------------------------
    @property
    def n_equations(self):
        return 0

    @property
    def length_rows(self):
        """Per equation: is it in metres (the constraint divides those by a length scale)?"""
        return ()

    def equations(self, q, v):
        """C (k,) and dC/d(q, v) (k, 6 + n_vars) at the pose q = (p m, tau rad) (6,) and the
        task variables v (n_vars,)."""
        return np.zeros(0), np.zeros((0, 6 + self.n_vars))

    def variables(self, p, tau):
        """The task variables (N, n_vars) of poses on the task: its first n_vars coordinates."""
        return self.coords(p, tau)[:, :self.n_vars]

    # ----- poses <-> task coordinates ---------------------------------------------------
    def pose(self, y):
        y = np.atleast_2d(np.asarray(y, dtype=float))
        return y[:, :3].copy(), y[:, 3:].copy()

    def coords(self, p, tau):
        return np.concatenate([np.atleast_2d(p), np.atleast_2d(tau)], axis=1)

    def residual(self, p, tau):
        """How far (m or rad) poses are from the task: zeros (N,) when every pose is on it."""
        return np.zeros(np.atleast_2d(p).shape[0])

    def own_cost(self, kind):
        """cost(p_a, tau_a, p_b, tau_b) of a kind only this task knows (None: not one), over
        rows: arrays (..., 3) -> (...)."""
        return None

    def describe(self):
        """One line for titles and logs."""
        return f"{self.type} task"

    # ----- the singular set of tilt-and-torsion (theta = 0 or pi: end_taus) -------------
    def fixed_angle(self, name):
        """The value (rad) the task holds the pose angle ``name`` ("phi" or "sigma") at, or
        None where it is free."""
        return None

    def singular_phi(self, tau, hint):
        """The azimuth phi (rad) of the pose tau (3,) on theta = 0 or pi, where the rotation
        does not fix it, in this task's coordinates: the task's fixed phi; at theta = pi with
        sigma fixed, where the rotation fixes 2 phi - sigma, the one of the two solutions
        (pi apart) nearest ``hint``; else ``hint`` (rad)."""
        phi_fixed, sigma_fixed = self.fixed_angle("phi"), self.fixed_angle("sigma")
        if phi_fixed is not None:
            return float(phi_fixed)
        if tau[1] == np.pi and sigma_fixed is not None:
            base = 0.5 * (2.0 * tau[0] - tau[2] + sigma_fixed)
            return float(wrap_angle(base + np.pi * np.round(wrap_angle(hint - base) / np.pi)))
        return float(hint)

    # ----- problem files and node parameters --------------------------------------------
    @classmethod
    def task_fields(cls):
        """The Field of each setting of the task (key: its problem-file key)."""
        return declared(cls, "task")

    @classmethod
    def from_dict(cls, d, where):
        """The task of its problem-file mapping (``type`` already checked)."""
        check_keys(where, d, ["type"] + [f.key for f in cls.task_fields()])
        return cls(**{f.key: _as_declared(read(f, d.get(f.key, f.default), f"{where}.{f.key}"))
                      for f in cls.task_fields()})

    @classmethod
    def parameters(cls):
        """The Field of each setting of the task as a node parameter (key ``task.<name>``)."""
        return [with_key(f, f"task.{f.key}") for f in cls.task_fields()]

    @classmethod
    def dict_of_parameters(cls, values):
        """The problem-file mapping of the node's flat parameter values (name -> value)."""
        return {"type": cls.type, **{f.key: values[f"task.{f.key}"] for f in cls.task_fields()}}

    @classmethod
    def example(cls):
        """A valid task of this class for the registry's contract tests (test_tasks.py:
        equations against finite differences, the pose map both ways): its defaults unless
        the class gives its own."""
        return cls()



def _as_declared(value):
    """A task's value as its dataclass keeps it: a point (array) as a tuple of floats."""
    return tuple(value.tolist()) if isinstance(value, np.ndarray) else value


def _fixed(name):
    """The Field of the slice's fixed pose coordinate ``name``: node parameter
    task.fixed.<name>, NaN (free) by default."""
    return Field(f"task.fixed.{name}", NUMBER, float("nan"), f"slice task: fixed value of "
                 f"{name}, or NaN for free", unit=COORDINATES[name].unit, limit=MAX_POSITION_M)


@register
@dataclass(frozen=True)
class FreeTask(Task):
    """Free flight: every pose, y = (x, y, z, phi, theta, sigma)."""

    type: ClassVar[str] = "free"
    slerp: ClassVar[bool] = True


@register
@dataclass(frozen=True)
class SliceTask(Task):
    """Pose coordinates in ``fixed`` (name -> value, m or rad) stay constant."""

    fixed: dict = field(default_factory=dict)
    type: ClassVar[str] = "slice"

    @classmethod
    def example(cls):
        return cls(fixed={"x": 0.0, "y": 0.0, "z": 0.35, "sigma": 0.6})  # Robot 1's slices

    @property
    def names(self):
        return tuple(n for n in POSE_NAMES if n not in self.fixed)

    @property
    def costs(self):
        # the paper's SO(3) geodesic where the position is fixed (Robot 1's slices)
        return ("so3", "se3") if {"x", "y", "z"} <= set(self.fixed) else ("se3",)

    @property
    def n_equations(self):
        return len(self.fixed)

    @property
    def length_rows(self):
        return tuple(n in ("x", "y", "z") for n in POSE_NAMES if n in self.fixed)

    def equations(self, q, v):
        rows = [j for j, n in enumerate(POSE_NAMES) if n in self.fixed]
        C = np.array([q[j] - self.fixed[POSE_NAMES[j]] for j in rows])
        periodic = np.array([COORDINATES[POSE_NAMES[j]].periodic for j in rows], dtype=bool)
        C[periodic] = wrap_angle(C[periodic])
        J = np.zeros((len(rows), 6))
        J[np.arange(len(rows)), rows] = 1.0
        return C, J

    def pose(self, y):
        y = np.atleast_2d(np.asarray(y, dtype=float))
        full = np.empty((y.shape[0], 6))
        free = iter(range(y.shape[1]))
        for j, name in enumerate(POSE_NAMES):
            full[:, j] = self.fixed[name] if name in self.fixed else y[:, next(free)]
        return full[:, :3], full[:, 3:]

    def coords(self, p, tau):
        full = np.concatenate([np.atleast_2d(p), np.atleast_2d(tau)], axis=1)
        return full[:, [POSE_NAMES.index(n) for n in self.names]]

    def residual(self, p, tau):
        """Largest deviation of the fixed coordinates (m or rad, angles wrapped)."""
        full = np.concatenate([np.atleast_2d(p), np.atleast_2d(tau)], axis=1)
        dev = [np.abs(wrap_angle(full[:, j] - v) if COORDINATES[name].periodic else full[:, j] - v)
               for j, name in enumerate(POSE_NAMES) if name in self.fixed
               for v in [self.fixed[name]]]
        return np.max(dev, axis=0) if dev else np.zeros(full.shape[0])

    def fixed_angle(self, name):
        return self.fixed.get(name)

    def describe(self):
        return "slice " + ", ".join(describe_value(n, v) for n, v in self.fixed.items())

    @classmethod
    def from_dict(cls, d, where):
        check_keys(where, d, ("type", "fixed"))
        fixed = d.get("fixed")
        if not isinstance(fixed, dict) or not fixed:
            raise InputError(f"{where}.fixed", fixed, "expected a mapping of pose coordinates to values")
        out = {}
        for name, value in fixed.items():
            if name not in POSE_NAMES:
                raise InputError(f"{where}.fixed.{name}", value, f"unknown coordinate (expected {POSE_NAMES})")
            out[name] = read(_fixed(name), value, f"{where}.fixed.{name}")
        if len(out) >= 6:
            raise InputError(f"{where}.fixed", fixed, "at least one coordinate must stay free")
        return cls(fixed=out)

    @classmethod
    def parameters(cls):
        return [_fixed(n) for n in POSE_NAMES]

    @classmethod
    def dict_of_parameters(cls, values):
        return {"type": cls.type, "fixed": {n: values[f"task.fixed.{n}"] for n in POSE_NAMES
                                            if not np.isnan(values[f"task.fixed.{n}"])}}


@register
@dataclass(frozen=True)
class SphereTask(Task):
    """Paper Eq. 17: p = c + r [cos a2 cos a1, cos a2 sin a1, -sin a2],
    phi = a1 - pi, theta = pi/2 - a2, sigma = 0 (or free). ``center`` m, ``radius`` m."""

    center: tuple = _center()
    radius: float = _field(0.1, unit="m", sign="positive", description="sphere task: radius")
    free_torsion: bool = _field(False, BOOL, unit="",
                                description="sphere task: the torsion sigma is free as well")
    type: ClassVar[str] = "sphere"
    coordinates: ClassVar[tuple] = (
        Coordinate("alpha1", "rad", True, (-np.pi, np.pi), r"$\alpha_1$"),
        Coordinate("alpha2", "rad", False, (-np.pi / 2, np.pi / 2), r"$\alpha_2$"))
    n_vars: ClassVar[int] = 2
    costs: ClassVar[tuple] = ("great_circle", "se3")

    @classmethod
    def example(cls):
        return cls(center=(0.0, 0.0, 0.306), radius=0.13, free_torsion=True)  # Robot 2's, Eq. 17

    @property
    def names(self):
        return ("alpha1", "alpha2", "sigma") if self.free_torsion else ("alpha1", "alpha2")

    @property
    def n_equations(self):
        return 5 if self.free_torsion else 6

    @property
    def length_rows(self):
        return (True, True, True, False, False, False)[:self.n_equations]

    def equations(self, q, v):
        (a1, a2), c = v, np.asarray(self.center)
        c1, s1, c2, s2 = np.cos(a1), np.sin(a1), np.cos(a2), np.sin(a2)
        C = np.zeros(self.n_equations)
        J = np.zeros((self.n_equations, 8))
        C[0:3] = q[0:3] - c - self.radius * np.array([c2 * c1, c2 * s1, -s2])
        J[0:3, 0:3] = np.eye(3)
        J[0:3, 6] = -self.radius * np.array([-c2 * s1, c2 * c1, 0.0])
        J[0:3, 7] = -self.radius * np.array([-s2 * c1, -s2 * s1, -c2])
        C[3], J[3, 3], J[3, 6] = wrap_angle(q[3] - a1 + np.pi), 1.0, -1.0
        C[4], J[4, 4], J[4, 7] = q[4] - np.pi / 2 + a2, 1.0, 1.0
        if not self.free_torsion:
            C[5], J[5, 5] = wrap_angle(q[5]), 1.0
        return C, J

    def pose(self, y):
        y = np.atleast_2d(np.asarray(y, dtype=float))
        a1, a2 = y[:, 0], y[:, 1]
        sigma = y[:, 2] if self.free_torsion else np.zeros_like(a1)
        p = np.asarray(self.center) + self.radius * np.stack(
            [np.cos(a2) * np.cos(a1), np.cos(a2) * np.sin(a1), -np.sin(a2)], axis=1)
        tau = np.stack([wrap_angle(a1 - np.pi), np.pi / 2 - a2, sigma], axis=1)
        return p, tau

    def coords(self, p, tau):
        tau = np.atleast_2d(tau)
        a1 = wrap_angle(tau[:, 0] + np.pi)
        a2 = np.pi / 2 - tau[:, 1]
        cols = [a1, a2] + ([tau[:, 2]] if self.free_torsion else [])
        return np.stack(cols, axis=1)

    def residual(self, p, tau):
        """Distance (m, or rad for angles) of poses from the task: 0 on the sphere task."""
        p, tau = np.atleast_2d(p), np.atleast_2d(tau)
        n = p - np.asarray(self.center)
        dist = np.linalg.norm(n, axis=1)
        # The platform must face the centre: its pose must equal the pose of its own alphas.
        a2 = np.arcsin(np.clip(-n[:, 2] / np.maximum(dist, 1e-12), -1, 1))
        a1 = np.arctan2(n[:, 1], n[:, 0])
        y = np.stack([a1, a2] + ([tau[:, 2]] if self.free_torsion else []), axis=1)
        p_ref, tau_ref = self.pose(y)
        ang = rotation_angle_between(rotation_tt(tau), rotation_tt(tau_ref))
        return np.maximum(np.abs(dist - self.radius), ang)

    def fixed_angle(self, name):
        return 0.0 if name == "sigma" and not self.free_torsion else None

    def own_cost(self, kind):
        """great_circle: the arc on the sphere (m), plus r times the torsion change (free
        torsion)."""
        if kind != "great_circle":
            return None
        c, r = np.asarray(self.center), self.radius

        def arcs(pa, ta, pb, tb):
            na, nb = pa - c, pb - c
            out = r * np.arctan2(np.linalg.norm(np.cross(na, nb), axis=-1), np.sum(na * nb, axis=-1))
            return out + (r * np.abs(wrap_angle(tb[..., 2] - ta[..., 2])) if self.free_torsion else 0.0)
        return arcs

    def describe(self):
        c = ", ".join(f"{v:.4g}" for v in self.center)
        return f"sphere task, centre [{c}] m, radius {self.radius:.4g} m"


@register
@dataclass(frozen=True)
class PivotTask(Task):
    """A tool point ``tool`` (m, platform frame) stays at ``center`` (m, base frame):
    p + R(tau) t = c, the orientation free (a camera or a tool tip pivoting about a
    target). y = (phi, theta, sigma), n = 3."""

    tool: tuple = _field((0.0, 0.0, 0.0), NUMBERS, unit="m, platform frame",
                         description="pivot task: the tool point t that stays at task.center")
    center: tuple = _center()
    type: ClassVar[str] = "pivot"
    costs: ClassVar[tuple] = ("so3", "se3")
    n_equations: ClassVar[int] = 3
    length_rows: ClassVar[tuple] = (True, True, True)

    @classmethod
    def example(cls):
        return cls(tool=(0.0, 0.0, 0.1), center=(0.0, 0.0, 0.35))

    @property
    def names(self):
        return ("phi", "theta", "sigma")

    def equations(self, q, v):
        R, dR = rotation_tt(q[3:6]), rotation_tt_derivatives(q[3:6])
        J = np.zeros((3, 6))
        J[:, :3] = np.eye(3)
        J[:, 3:] = np.einsum("ijk,j->ik", dR, np.asarray(self.tool))
        return q[:3] + R @ np.asarray(self.tool) - np.asarray(self.center), J

    def pose(self, y):
        tau = np.atleast_2d(np.asarray(y, dtype=float)).copy()
        return np.asarray(self.center) - rotation_tt(tau) @ np.asarray(self.tool), tau

    def coords(self, p, tau):
        return np.atleast_2d(np.asarray(tau, dtype=float)).copy()

    def residual(self, p, tau):
        """|p + R t - c| (m) of each pose."""
        tip = np.atleast_2d(p) + rotation_tt(np.atleast_2d(tau)) @ np.asarray(self.tool)
        return np.linalg.norm(tip - np.asarray(self.center), axis=1)

    def describe(self):
        t = ", ".join(f"{v:.4g}" for v in self.tool)
        c = ", ".join(f"{v:.4g}" for v in self.center)
        return f"pivot task, tool [{t}] m at [{c}] m"


@dataclass(frozen=True)
class ImplicitTask(Task):
    """Paper Eq. 15: poses with C(p, tau) = 0, for library use (a callable is not a file
    value). ``equations(p (3,), tau (3,)) -> (C (k,), dC/d(p, tau) (k, 6))`` with full row
    rank on the poses used; ``count`` = k. Task coordinates are the whole pose, as in free
    flight."""

    implicit: object = None
    count: int = 0
    type: ClassVar[str] = "implicit"

    @property
    def n_equations(self):
        return int(self.count)

    @property
    def length_rows(self):
        return (False,) * self.count  # the caller's own units

    def equations(self, q, v):
        return self.implicit(q[:3], q[3:6])

    def residual(self, p, tau):
        """max |C| of each pose (the equations' own units)."""
        p, tau = np.atleast_2d(p), np.atleast_2d(tau)
        return np.array([np.max(np.abs(self.implicit(a, b)[0])) for a, b in zip(p, tau)])


def task_from_dict(d, where="task"):
    """The task of a problem-file / parameter mapping {type, ...} (None: free flight)."""
    if d is None:
        return FreeTask()
    if not isinstance(d, dict):
        raise InputError(where, d, "expected a mapping with 'type'")
    kind = d.get("type", "free")
    if not isinstance(kind, str) or kind not in TASKS:
        raise InputError(f"{where}.type", kind, f"unknown task type (expected one of {', '.join(TASKS)})")
    return TASKS[kind].from_dict(d, where)


def end_taus(task, taus, tol):
    """The tilt-and-torsion angles (2, 3) rad a query plans between, of the start's and the
    goal's ``taus`` (2, 3): one pose, one plan, whatever angles wrote the pose.

    Each orientation is rewritten from its rotation (``pose.tau_from_rotation``); one within
    ``tol`` (rad) of theta = 0 or pi is snapped onto it (moved by at most ``tol``, as a pose
    off the task is projected onto it), so that noise there (forward kinematics of measured
    lengths) does not pick phi. On that set the rotation leaves phi free, and phi is, in
    this order: the task's (``Task.singular_phi``: a fixed phi, or with sigma fixed at
    theta = pi the allowed one nearest what follows); the other end's azimuth when that end
    is off the set, so the straight line in task coordinates tilts straight toward it (the
    sphere task's pole: the other end's meridian, the shortest arc), which is also the
    limit of what a pose tilted toward the other end gives; else 0.
    """
    taus = np.asarray(taus, dtype=float)
    R = rotation_tt(taus)
    first = tau_from_rotation(R, 0.0, tol)
    singular = on_singular_set(first)
    phi = first[:, 0].copy()
    for k, other in ((0, 1), (1, 0)):
        if singular[k]:
            phi[k] = task.singular_phi(first[k], 0.0 if singular[other] else first[other, 0])
    return tau_from_rotation(R, phi, tol)


def describe_value(name, value):
    """'x = 0 m' or 'sigma = 0.5934 rad (34 deg)'."""
    if COORDINATES[name].unit == "m":
        return f"{name} = {value:.4g} m"
    return f"{name} = {value:.4g} rad ({np.degrees(value):.4g} deg)"
