"""A planned platform path with everything a winch controller needs, per waypoint.

    path = with_commands(robot, path)   # carries the robot's cable stiffness (None: rigid)
    L0, V0, A0 = path.commanded()       # the lengths and rates a length controller receives
"""

from dataclasses import dataclass, replace

import numpy as np

COMMAND_WINDOW_S = 0.05  # s: the commanded tension is the nominal one averaged over +- this
                         # at least (``command_window``)
COMMAND_ACCEL_SHARE = 0.25  # of the winch acceleration limit: what the stretch of a jump of
                            # the dynamic tensions may take in the commands (``command_window``)
COMMAND_PATH_WINDOW_M = 5e-3  # m of cable-space arc length (``cable_arc_length``): the
                              # nominal tension is first averaged over +- this along the path


@dataclass
class PlannedPath:
    """N waypoints. Units: m, rad, N, s. Quaternions are (x, y, z, w).

    Consecutive waypoints are close enough that the motion between them (position linear,
    orientation slerp) is wrench-feasible; ``margin`` is the normalised feasibility margin
    of each waypoint (positive). ``t`` is time from start (s), from the cable-space time
    parameterisation; ``velocities`` / ``accelerations`` are the cable length rates
    (m/s, m/s^2) at the waypoints (of the geometric ``lengths``). ``cable_stiffness`` (m,)
    N: the cables' axial stiffness EA (``robot.cable_stiffness``), None for rigid cables;
    with it, ``commanded`` gives the unstretched lengths a length controller receives.
    """

    p: np.ndarray  # (N, 3)
    quaternion: np.ndarray  # (N, 4)
    tau: np.ndarray  # (N, 3) phi, theta, sigma
    lengths: np.ndarray  # (N, m): one column per cable
    tension_min: np.ndarray  # (N, m): one column per cable
    tension_nominal: np.ndarray  # (N, m): one column per cable
    tension_max: np.ndarray  # (N, m): one column per cable
    margin: np.ndarray  # (N,)
    t: np.ndarray  # (N,)
    velocities: np.ndarray  # (N, m): one column per cable
    accelerations: np.ndarray  # (N, m): one column per cable
    cable_stiffness: np.ndarray = None  # (m,) N, or None: rigid cables (not per waypoint)
    command_window_s: float = COMMAND_WINDOW_S  # s: the commands' time average (not per
                                                # waypoint; ``command_window``)

    def commanded(self, window_s=None):
        """(lengths m, velocities m/s, accelerations m/s^2), each (N, m): the points a
        length controller receives. Elastic cables: the unstretched lengths L0 = L / (1 + t
        / EA) that are the planned lengths L under the tensions t, so that the cables carry
        them at the planned pose; t is the nominal tension, for m > 6 cables averaged along
        the path over COMMAND_PATH_WINDOW_M of cable-space arc length either side (their
        centred rule turns its nominal by hundreds of newtons within millimetres of motion:
        the average spreads that turn over a length the dynamic timing can bound the
        stretch's rates on, ``dynamics._command_rates``), then over ``window_s`` s
        (default ``command_window_s``) either side, both with a tent weight
        (``command_tensions``): a dynamic timing's tension jumps where its acceleration
        switches, and a step in L0 there would make a controller's quintic (and a damped
        cable) jerk and the winch exceed its limits; the average spreads a jump J over the
        window, its second rate at most J / window^2. Rates: those of L - stretch, exactly (the stretch L t / (EA + t) with the
        average's own rates), zero where the path rests. Rigid cables: the geometric
        lengths and rates themselves (the same arrays)."""
        if self.cable_stiffness is None:
            return self.lengths, self.velocities, self.accelerations
        window_s = self.command_window_s if window_s is None else window_s
        along = self.tension_nominal
        if averaged_along_path(along.shape[1]):
            along = command_tensions(cable_arc_length(self.lengths), along,
                                     COMMAND_PATH_WINDOW_M)[0]
        f, df, ddf = command_tensions(self.t, along, window_s)
        EA = self.cable_stiffness
        q = f / (EA + f)                          # the stretch per length, t / (EA + t)
        dq = EA * df / (EA + f) ** 2
        ddq = EA * ddf / (EA + f) ** 2 - 2 * EA * df ** 2 / (EA + f) ** 3
        L, V, A = self.lengths, self.velocities, self.accelerations
        V0 = V - (V * q + L * dq)
        V0[~np.any(V != 0.0, axis=1)] = 0.0       # at rest
        return L * (1.0 - q), V0, A - (A * q + 2 * V * dq + L * ddq)

    def __len__(self):
        return self.p.shape[0]

    def length_m(self):
        """Length of the platform's position path (m)."""
        return float(np.sum(np.linalg.norm(np.diff(self.p, axis=0), axis=1)))


def with_commands(robot, path):
    """``path`` (PlannedPath) carrying ``robot``'s cable stiffness, which ``commanded``
    turns into the commands of elastic cables (None: rigid)."""
    return replace(path, cable_stiffness=robot.cable_stiffness)


def averaged_along_path(m):
    """Are the nominal tensions of m cables averaged along the path before they make the
    commands (``PlannedPath.commanded``), and the timing bounds their stretch's rates
    (``dynamics._command_rates``)? For m > 6: a tension rule turns its nominal fast; six
    cables' t0 = J^-1 w0 turns no faster than the pose. One answer for both, so that the
    timing bounds the commands that are sent."""
    return m > 6


def command_window(lengths, dynamic, cable_stiffness, max_cable_accel):
    """s: the half-width of the commands' time average (``PlannedPath.commanded``) for
    waypoints of lengths (N, m) m whose nominal tensions' dynamic part (what the motion's
    accelerations add, N) is ``dynamic`` (N, m): the least that keeps the stretch of each
    jump J of it between consecutive waypoints within COMMAND_ACCEL_SHARE of the winch
    acceleration limit (m/s^2; one number or m), at least COMMAND_WINDOW_S. The tent
    average's second rate of a jump is at most J / w^2, its stretch's L J / (EA w^2)
    (EA = ``cable_stiffness``, (m,) N). A heavy platform's switches of acceleration jump by
    up to 100 N (CoGiRo: 0.10 s); a light one's by 0.1 N (robot2_8: COMMAND_WINDOW_S)."""
    if cable_stiffness is None or len(lengths) < 2:
        return COMMAND_WINDOW_S
    amax = np.broadcast_to(np.asarray(max_cable_accel, dtype=float), (lengths.shape[1],))
    jump = np.abs(np.diff(np.asarray(dynamic, dtype=float), axis=0))
    stretch = np.max(lengths[1:] * jump / cable_stiffness / (COMMAND_ACCEL_SHARE * amax))
    return max(COMMAND_WINDOW_S, float(np.sqrt(stretch)))


def cable_arc_length(L):
    """(N,) m: the cable-space arc length at the rows of lengths L (N, m) m, the cumulative
    Euclidean norm of their steps plus 1e-9 m per step (strictly increasing: a repeated row
    is a step)."""
    step = np.linalg.norm(np.diff(np.asarray(L, dtype=float), axis=0), axis=1) + 1e-9
    return np.concatenate([[0.0], np.cumsum(step)])


def command_tensions(t, f, window_s, at=None):
    """The tensions f (N, m) N at times t (N,) s, taken as linear between them and held
    before the first and after the last, averaged with the tent weight (window_s - |s|) /
    window_s^2 over s in [-window_s, window_s], at times ``at`` (M,) s (default t): the
    averages (M, m) N, their rates (N/s) and second rates (N/s^2), exactly. With F and G
    the first and second integrals of f, the average is the second difference
    (G(t + w) - 2 G(t) + G(t - w)) / w^2, its rates those of F and of f: a jump J of the
    tensions moves the average's second rate by at most J / w^2 (a box average's would be
    a spike at its edges)."""
    t, f = np.asarray(t, dtype=float), np.asarray(f, dtype=float)
    at = t if at is None else np.asarray(at, dtype=float)
    if len(t) < 2:
        zero = np.zeros((len(at), f.shape[1]))
        return zero + f[0], zero, zero.copy()
    h = np.diff(t)[:, None]
    slope = np.diff(f, axis=0) / h
    F = np.concatenate([np.zeros((1, f.shape[1])),
                        np.cumsum(f[:-1] * h + slope * h ** 2 / 2, axis=0)])
    G = np.concatenate([np.zeros((1, f.shape[1])),
                        np.cumsum(F[:-1] * h + f[:-1] * h ** 2 / 2 + slope * h ** 3 / 6, axis=0)])

    def integrals(x):  # f, F, G at x (held ends: f constant outside [t_0, t_N-1])
        k = np.clip(np.searchsorted(t, x, side="right") - 1, 0, len(t) - 2)
        d = (np.clip(x, t[0], t[-1]) - t[k])[:, None]
        fx = f[k] + slope[k] * d
        Fx = F[k] + f[k] * d + slope[k] * d ** 2 / 2
        Gx = G[k] + F[k] * d + f[k] * d ** 2 / 2 + slope[k] * d ** 3 / 6
        for edge, end in ((x < t[0], 0), (x > t[-1], -1)):  # linear / quadratic beyond
            e = (x - t[end])[:, None]
            fx = np.where(edge[:, None], f[end], fx)
            Fx = np.where(edge[:, None], F[end] + f[end] * e, Fx)
            Gx = np.where(edge[:, None], G[end] + F[end] * e + f[end] * e ** 2 / 2, Gx)
        return fx, Fx, Gx

    w = window_s
    lo, mid, hi = integrals(at - w), integrals(at), integrals(at + w)
    second = [(a - 2 * b + c) / w ** 2 for a, b, c in zip(lo, mid, hi)]
    return second[2], second[1], second[0]
