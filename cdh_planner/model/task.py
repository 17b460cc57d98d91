"""Task constraints on the platform pose: which poses a motion may use.

A task maps its free coordinates y (shape (N, k)) to poses (p m, tau rad) and back:
- ``FreeTask``: y = (x, y, z, phi, theta, sigma), free flight (k = 6).
- ``SliceTask``: some pose coordinates fixed (the paper's Robot 1 slices).
- ``SphereTask``: the paper's Eq. 17, P on a sphere facing its centre,
  y = (alpha1, alpha2) or (alpha1, alpha2, sigma) with free torsion.
"""

from dataclasses import dataclass, field

import numpy as np

from ..errors import InputError
from .pose import rotation_angle_between, rotation_tt, wrap_angle

POSE_NAMES = ("x", "y", "z", "phi", "theta", "sigma")
PERIODIC = {"phi", "sigma", "alpha1"}
TASK_TYPES = ("free", "slice", "sphere")


@dataclass(frozen=True)
class FreeTask:
    type: str = "free"

    @property
    def names(self):
        return POSE_NAMES

    def pose(self, y):
        y = np.atleast_2d(np.asarray(y, dtype=float))
        return y[:, :3].copy(), y[:, 3:].copy()

    def coords(self, p, tau):
        return np.concatenate([np.atleast_2d(p), np.atleast_2d(tau)], axis=1)

    def residual(self, p, tau):
        """Every pose is on the free task: zeros (N,)."""
        return np.zeros(np.atleast_2d(p).shape[0])


@dataclass(frozen=True)
class SliceTask:
    """Pose coordinates in ``fixed`` (name -> value, m or rad) stay constant."""

    fixed: dict = field(default_factory=dict)
    type: str = "slice"

    @property
    def names(self):
        return tuple(n for n in POSE_NAMES if n not in self.fixed)

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
        dev = [np.abs(full[:, j] - v) if name not in PERIODIC else np.abs(wrap_angle(full[:, j] - v))
               for j, name in enumerate(POSE_NAMES) if name in self.fixed
               for v in [self.fixed[name]]]
        return np.max(dev, axis=0) if dev else np.zeros(full.shape[0])


@dataclass(frozen=True)
class SphereTask:
    """Paper Eq. 17: p = c + r [cos a2 cos a1, cos a2 sin a1, -sin a2],
    phi = a1 - pi, theta = pi/2 - a2, sigma = 0 (or free). ``center`` m, ``radius`` m."""

    center: tuple = (0.0, 0.0, 0.0)
    radius: float = 0.1
    free_torsion: bool = False
    type: str = "sphere"

    @property
    def names(self):
        return ("alpha1", "alpha2", "sigma") if self.free_torsion else ("alpha1", "alpha2")

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


@dataclass(frozen=True)
class ImplicitTask:
    """Paper Eq. 15: poses with C(p, tau) = 0, for library use (a callable is not a file
    value). ``equations(p (3,), tau (3,)) -> (C (k,), dC/d(p, tau) (k, 6))`` with full row
    rank on the poses used; ``count`` = k. Task coordinates are the whole pose, as in free
    flight."""

    equations: object
    count: int
    type: str = "implicit"

    @property
    def names(self):
        return POSE_NAMES

    def pose(self, y):
        return FreeTask().pose(y)

    def coords(self, p, tau):
        return FreeTask().coords(p, tau)

    def residual(self, p, tau):
        """max |C| of each pose (the equations' own units)."""
        p, tau = np.atleast_2d(p), np.atleast_2d(tau)
        return np.array([np.max(np.abs(self.equations(a, b)[0])) for a, b in zip(p, tau)])


def task_from_dict(d, where="task"):
    """Build a task from the problem file / parameter form {type, fixed | center, radius, ...}."""
    if d is None:
        return FreeTask()
    if not isinstance(d, dict):
        raise InputError(where, d, "expected a mapping with 'type'")
    kind = d.get("type", "free")
    allowed = {"free": {"type"}, "slice": {"type", "fixed"},
               "sphere": {"type", "center", "radius", "free_torsion"}}
    if kind not in allowed:
        raise InputError(f"{where}.type", kind, f"unknown task type (expected one of {', '.join(TASK_TYPES)})")
    unknown = sorted(set(d) - allowed[kind])
    if unknown:
        raise InputError(f"{where}.{unknown[0]}", d[unknown[0]], f"not a key of a '{kind}' task")
    if kind == "free":
        return FreeTask()
    if kind == "slice":
        fixed = d.get("fixed")
        if not isinstance(fixed, dict) or not fixed:
            raise InputError(f"{where}.fixed", fixed, "expected a mapping of pose coordinates to values")
        out = {}
        for name, value in fixed.items():
            if name not in POSE_NAMES:
                raise InputError(f"{where}.fixed.{name}", value, f"unknown coordinate (expected {POSE_NAMES})")
            out[name] = _finite(f"{where}.fixed.{name}", value)
        if len(out) >= 6:
            raise InputError(f"{where}.fixed", fixed, "at least one coordinate must stay free")
        return SliceTask(fixed=out)
    center = d.get("center")
    if not isinstance(center, (list, tuple)) or len(center) != 3:
        raise InputError(f"{where}.center", center, "expected 3 numbers (m)")
    center = tuple(_finite(f"{where}.center[{i}]", c) for i, c in enumerate(center))
    radius = _finite(f"{where}.radius", d.get("radius"))
    if radius <= 0:
        raise InputError(f"{where}.radius", radius, "must be positive (m)")
    free_torsion = d.get("free_torsion", False)
    if not isinstance(free_torsion, bool):
        raise InputError(f"{where}.free_torsion", free_torsion, "expected true or false")
    return SphereTask(center=center, radius=radius, free_torsion=free_torsion)


def _finite(where, value):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
        raise InputError(where, value, "expected a finite number")
    return float(value)
