"""Clearance: how far a path keeps from the boundary of C, and the cost that trades length for it.

The planner's clearance cost of a motion of length ds (in the task's metric) at normalised
margin m (``wrench.band_feasibility``: the least of the 24 distances to a length or tension
bound, each over its range) is

    dJ = (1 + w phi(m)) ds,    phi(m) = ln(M / m),    M = 1/2,

with w the planner's ``clearance_weight``. Why this phi:

- **Scale-free.** phi drops by ln 2 whenever the margin doubles, at any margin: doubling
  the margin along a stretch saves 0.69 w per unit of its length, whether the margin goes
  from 0.001 to 0.002 or from 0.1 to 0.2, and a detour is worth it when its extra cost
  is less. The margins of C differ by orders of magnitude between robots (Robot 1's C is
  0.01 to 0.05 wide, Robot 2's band reaches 0.25), so a weight means the same on both;
  with 1/m the same w would be negligible on one robot and overwhelming on the other.
- **A barrier, but a soft one.** phi grows without bound towards the boundary of C (the
  log barrier of interior-point methods), yet its integral stays finite: a narrow passage
  that the path must cross is crossed briefly at a finite price, where a global margin
  floor removes it.
- **Length is a lower bound.** No pose has a margin above 1/2 (the two margins of a
  length or tension bound sum to at most 1), so phi >= 0 and the cost is never below the
  length: the task metric stays an admissible, consistent A* heuristic.
- **w = 0 is the length**, the paper's cost, exactly.

A segment between two poses costs its length times 1 + w times the mean of phi at its
ends (trapezoid; ``segment_costs``); a long direct motion is sampled along its length
(``mean_phi``). ``path_margins`` reports the least normalised margin and the least tension
margin in N of a path, sampled as densely as ``verify`` checks it.
"""

import numpy as np

from ..wrench import band_feasibility
from .path_check import DEFAULT_STEP_M, DEFAULT_STEP_RAD, SlerpPath

MAX_MARGIN = 0.5  # no pose has a larger normalised margin
MIN_MARGIN = 1e-9  # phi is capped here (about 20): a sample outside C is not a NaN


def phi(margin):
    """ln(MAX_MARGIN / m), m clipped to [MIN_MARGIN, MAX_MARGIN]: >= 0, 0 only at the
    largest margin any pose can have."""
    return np.log(MAX_MARGIN / np.clip(margin, MIN_MARGIN, MAX_MARGIN))


def density(margin, weight):
    """1 + w phi(m): the clearance cost per unit of length at margin m."""
    return 1.0 + weight * phi(margin)


def segment_costs(lengths, margins, weight):
    """Clearance cost of consecutive segments of ``lengths`` (N - 1,) between waypoints of
    ``margins`` (N,): length times 1 + w times the mean of phi at the ends."""
    ph = phi(np.asarray(margins, dtype=float))
    return np.asarray(lengths, dtype=float) * (1.0 + weight * 0.5 * (ph[:-1] + ph[1:]))


def tension_margins(robot, f):
    """Per pose and cable, min(f0 - v - fmin, fmax - f0 - v) (N, m), N: how far the tension
    envelope of a ``Feasibility`` is from the tension limits (negative outside)."""
    return np.minimum(f.tension_min - robot.tension_min, robot.tension_max - f.tension_max)


def path_margins(robot, positions, quaternions, max_step_m=DEFAULT_STEP_M,
                 max_step_rad=DEFAULT_STEP_RAD):
    """(least normalised margin, least tension margin N) over the waypoints (positions
    (N, 3) m, quaternions (N, 4)) and the motion between them (position linear,
    orientation slerp), sampled at most ``max_step_m`` / ``max_step_rad`` apart."""
    positions = np.atleast_2d(np.asarray(positions, dtype=float))
    if len(positions) == 1:
        positions = np.repeat(positions, 2, axis=0)
        quaternions = np.repeat(np.atleast_2d(quaternions), 2, axis=0)
    motion = SlerpPath(positions, np.asarray(quaternions, dtype=float))
    dp, da = motion.speeds()
    n = np.maximum(1, np.ceil(np.maximum(dp / max_step_m, da / max_step_rad))).astype(int)
    seg = np.repeat(np.arange(motion.n_segments), n)
    s = np.concatenate([np.arange(k) / k for k in n])
    seg, s = np.append(seg, motion.n_segments - 1), np.append(s, 1.0)
    least, least_n = np.inf, np.inf
    for a in range(0, seg.size, 20_000):  # bounded memory
        p, R = motion(seg[a:a + 20_000], s[a:a + 20_000])
        f = band_feasibility(robot, p, R=R)
        least = min(least, float(np.min(f.margin)))
        tm = tension_margins(robot, f)
        least_n = min(least_n, float(np.min(np.where(np.isfinite(tm), tm, -np.inf))))
    return least, least_n
