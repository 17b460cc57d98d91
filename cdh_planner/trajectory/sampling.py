"""The cable state between the waypoints of a timed path, as a controller interpolates it.

    sample_cable_state(path, t) -> CableSample (lengths m, velocities m/s, effort N)

Numerics only (no ROS): the node's command stream and the replay use it.
"""

from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..model.robot_schema import MAX_CABLES, MIN_CABLES
from .executed import quintic


def check_timed_path(path):
    """InputError unless ``path`` (PlannedPath) has per-cable arrays (N, m), m the number
    of cables (MIN_CABLES to MAX_CABLES), and times that start >= 0 and strictly increase."""
    n = len(path)
    shape = np.shape(path.lengths)
    m = shape[1] if len(shape) == 2 and MIN_CABLES <= shape[1] <= MAX_CABLES else MIN_CABLES
    for name in ("lengths", "velocities", "accelerations", "tension_min", "tension_nominal",
                 "tension_max"):
        shape = np.shape(getattr(path, name))
        if shape != (n, m):
            raise InputError(f"path.{name}", f"shape {shape}", f"expected ({n}, {m})")
    if np.shape(path.t) != (n,):
        raise InputError("path.t", f"shape {np.shape(path.t)}", f"expected ({n},)")
    if n and (not np.all(np.isfinite(path.t)) or path.t[0] < 0 or np.any(np.diff(path.t) <= 0)):
        raise InputError("path.t", np.asarray(path.t).tolist()[:8],
                         "must start >= 0 and strictly increase (time-parameterise the path)")


@dataclass(frozen=True)
class CableSample:
    """Cable command at one instant: ``lengths`` (m,) m, ``velocities`` (m,) m/s,
    ``effort`` (m,) N (nominal tensions)."""

    lengths: np.ndarray
    velocities: np.ndarray
    effort: np.ndarray


def sample_cable_state(path, t, method="quintic"):
    """Commanded cable lengths, velocities (``PlannedPath.commanded``: unstretched with
    elastic cables) and nominal tensions at time ``t`` (s from the start).

    ``method``: ``quintic`` interpolates each segment with the quintic through position,
    velocity and acceleration at both ends, as ros2_control's JointTrajectoryController
    does with the same points (``trajectory.executed.quintic``: so streaming and the
    controller agree, and both execute what the planner checked; at a waypoint it returns
    that waypoint); ``linear`` moves on the straight cable-space segment at its mean
    velocity (L_{k+1} - L_k) / h_k (its velocity steps at every point: not what was
    checked). Effort is linear in t. Outside [t_0, t_end] the path is clamped to its end and held (velocity 0).
    """
    check_timed_path(path)
    t = float(t)
    if not np.isfinite(t):
        raise InputError("t", t, "must be a finite number of seconds")
    if method not in ("quintic", "linear"):
        raise InputError("method", method, "expected 'quintic' or 'linear'")
    n, T = len(path), np.asarray(path.t, dtype=float)
    lengths, velocities, accelerations = path.commanded()
    if n == 1 or t <= T[0] or t >= T[-1]:
        k = 0 if (n == 1 or t <= T[0]) else n - 1
        inside = n > 1 and t == T[k]
        vel = velocities[k] if inside else np.zeros(np.shape(lengths)[1])
        return CableSample(lengths=np.array(lengths[k], dtype=float),
                           velocities=np.array(vel, dtype=float),
                           effort=np.array(path.tension_nominal[k], dtype=float))
    k = int(np.searchsorted(T, t, side="right") - 1)
    h = T[k + 1] - T[k]
    s = (t - T[k]) / h
    effort = (1 - s) * path.tension_nominal[k] + s * path.tension_nominal[k + 1]
    if method == "linear":
        rate = (lengths[k + 1] - lengths[k]) / h
        return CableSample(lengths=lengths[k] + rate * (t - T[k]), velocities=rate,
                           effort=np.asarray(effort, dtype=float))
    pos, vel, _ = quintic(T, lengths, velocities, accelerations, np.array([t]))
    return CableSample(lengths=pos[0], velocities=vel[0], effort=np.asarray(effort, dtype=float))
