"""A cable-length trajectory checked as its consumer executes it.

    check = check_path(robot, path, mass, inertia, max_cable_speed, max_cable_accel)
    check.ok, check.reason, check.least_tension_margin_n, check.bad_segments
    path, check = executable(robot, path, motion, mass, inertia, max_cable_speed, max_cable_accel)

A ros2_control JointTrajectoryController (JTC) moves each joint between two points with
the quintic matching position, velocity and acceleration at both ends (``quintic``). The
platform then follows the cable lengths: its pose is their forward kinematics (Newton,
``model.forward_kinematics.forward_kinematics_many``), seeded at each instant with the
planned pose there (so Newton stays on the platform's branch; a solution more than
SEED_TOL_M away is a failure). Its acceleration c'' (centre of
mass) and body angular rate and acceleration come from central differences at ``dt``
(1 ms), and the cables must balance the load wrench minus the inertial wrench

    w_in = [m c''; c x m c'' + R (I alpha + omega x I omega)]   (omega, alpha body frame),

as trajectory.dynamics models it. The tensions f = J^-1 (w0 - w_in) with the ellipsoid's
spread v must keep fmin + v <= f <= fmax - v; the quintic's lengths, rates and
accelerations must stay within the length and winch limits (checked exactly: per segment,
the extremes of each polynomial, ``quintic_bounds``). The tensions are sampled every
dt / PHASES s from dt after the start to dt before the end, each sample with its own
stencil t - dt, t, t + dt (one never straddles an end, where the JTC's hold makes the
acceleration jump): a violation narrower than dt is seen whatever its phase.

Elastic cables (``robot.cable_stiffness``): the JTC interpolates the commanded,
unstretched lengths L0 (``PlannedPath.commanded``), and the platform's pose is the elastic
equilibrium of those cables (``model.elastic.equilibrium_poses``: the cables' tensions
max(0, EA (L - L0) / L0) balance the load wrench), first at rest, then, with the inertial
wrench of the motion those static poses make (the same central differences), again; its
tensions are the ones checked (with the same spread v). A slack cable (tension 0) fails
as a tension below its minimum; an equilibrium not found is a lost pose.

``executable`` adds points to a timed PlannedPath until this check passes (module
docstring of that function).
"""

from dataclasses import dataclass, field, replace
from math import comb

import numpy as np

from ..wrench import load_point, rule_tensions
from ..model.elastic import equilibrium_poses, is_elastic, static_load
from ..model.forward_kinematics import forward_kinematics_many
from ..model.pose import cross, tau_from_rotation
from ..ports import CubicSpline, Rotation, Slerp
from .motion_kernel import turns
from .path import with_commands
from .timing import limit_ratio

CHECK_DT = 1e-3        # s: step of the check's central differences
PHASES = 2             # samples per CHECK_DT: a violation narrower than the step is not
                       # missed by the phase of the samples
TOL = 1e-9             # N, m, m/s, m/s^2: rounding allowed
MAX_POINTS = 4000      # points of a trajectory handed to a consumer
MAX_ROUNDS = 12        # rounds of adding points
WINCH_ROUNDS = 3       # of which for the winch limits alone: near an acceleration switch of
                       # the motion every quintic overshoots (by ~0.1 - 0.4 x the jump,
                       # however dense the points), which only slowing down removes
SLOWDOWNS = 8          # uniform slow-downs tried when adding points is not enough
SLOWDOWN = 1.05        # time scale per slow-down
TENSION_SLOWDOWN = 1.25  # ... when tensions or poses fail: the motion's own wrench, what
                         # slowing removes, falls as 1 / scale^2 (8 of them: x 6)
SEED_TOL_M = 1e-2      # m: a forward kinematics solution this far from its seed is a twin
PROGRESS = 0.1         # two rounds of added points that shrink the time the check fails
                       # in by less than this share are futile: the motion itself fails
                       # there, not the quintic between its points (slowing is what helps;
                       # two: a failure inside one segment can fail both its halves once)


# ----------------------------------------------------------------------------- the quintic

def quintic(t_wp, L, V, A, t, rates=True):
    """Positions (M, J) m, velocities m/s and accelerations m/s^2 at times ``t`` (M,) of the
    JTC interpolation of points at ``t_wp`` (N,) s with positions L, velocities V and
    accelerations A (N, J): per segment the quintic through both ends' position, velocity
    and acceleration; before the first point and after the last the end is held (rest).
    ``rates`` False: the positions alone (velocities and accelerations None)."""
    t_wp = np.asarray(t_wp, dtype=float)
    t = np.asarray(t, dtype=float)
    k = np.clip(np.searchsorted(t_wp, t, side="right") - 1, 0, len(t_wp) - 2)
    h = (t_wp[k + 1] - t_wp[k])[:, None]
    s = np.clip((t - t_wp[k]) / h[:, 0], 0.0, 1.0)[:, None]
    # each segment's coefficients once, then per sample (the same numbers)
    b0, b1, b2, b3, b4, b5 = (b[k] for b in _coefficients(t_wp, L, V, A, np.arange(len(t_wp) - 1)))
    pos = b0 + s * (b1 + s * (b2 + s * (b3 + s * (b4 + s * b5))))
    before, after = t < t_wp[0], t > t_wp[-1]
    pos[before], pos[after] = L[0], L[-1]
    if not rates:
        return pos, None, None
    vel = (b1 + s * (2 * b2 + s * (3 * b3 + s * (4 * b4 + s * 5 * b5)))) / h
    acc = (2 * b2 + s * (6 * b3 + s * (12 * b4 + s * 20 * b5))) / (h * h)
    vel[before | after] = 0.0
    acc[before | after] = 0.0
    return pos, vel, acc


def _coefficients(t_wp, L, V, A, k):
    """The quintics of segments k: p(s) = sum b_i s^i, s = (t - t_k) / h_k in [0, 1]
    (each b_i (K, J))."""
    h = (t_wp[k + 1] - t_wp[k])[:, None]
    p0, v0, a0, p1, v1, a1 = L[k], V[k] * h, A[k] * h * h, L[k + 1], V[k + 1] * h, A[k + 1] * h * h
    d = p1 - p0 - v0 - 0.5 * a0
    dv = v1 - v0 - a0
    da = a1 - a0
    return (p0, v0, 0.5 * a0, 10 * d - 4 * dv + 0.5 * da, -15 * d + 7 * dv - da,
            6 * d - 3 * dv + 0.5 * da)


def quintic_bounds(t_wp, L, V, A, segments=None, limits=None):
    """Per segment (K of them, default all) and joint, exactly: the least and largest
    position (m), the largest |velocity| (m/s) and |acceleration| (m/s^2) of the JTC's
    quintic, each (K, J). Each is a polynomial on [0, 1]: its extremes are at the ends or
    where its derivative vanishes (real roots from the companion matrix, and a few fixed
    fractions in case a root is ill-conditioned). ``limits`` (least, largest) (J,) m: the
    positions' extremes only where their Bernstein hull (the range of the Bernstein
    coefficients, which holds the polynomial on [0, 1]) is not within the limits by
    HULL_ROUNDING_M; elsewhere the hull's ends, within the limits as the extremes are."""
    t_wp, L, V, A = (np.asarray(x, dtype=float) for x in (t_wp, L, V, A))
    k = np.arange(len(t_wp) - 1) if segments is None else np.asarray(segments, dtype=int)
    h = (t_wp[k + 1] - t_wp[k])[:, None]
    b = np.stack(_coefficients(t_wp, L, V, A, k), axis=-1)                # (K, J, 6)
    vel = b[..., 1:] * np.arange(1, 6)                                     # per unit s
    acc = vel[..., 1:] * np.arange(1, 5)
    if limits is None:
        lo, hi = _extremes(b)
    else:
        hull = b @ BERNSTEIN_5.T
        lo, hi = hull.min(axis=-1), hull.max(axis=-1)
        inside = (lo >= limits[0] + HULL_ROUNDING_M) & (hi <= limits[1] - HULL_ROUNDING_M)
        if not inside.all():
            lo[~inside], hi[~inside] = _extremes(b[~inside])
    return lo, hi, np.max(np.abs(_extremes(vel)), axis=0) / h, np.max(np.abs(_extremes(acc)), axis=0) / h ** 2


# a quintic's Bernstein coefficients on [0, 1] from its power ones b_i: sum_{i <= j}
# C(j, i) / C(5, i) b_i (row j)
BERNSTEIN_5 = np.array([[comb(j, i) / comb(5, i) if i <= j else 0.0 for i in range(6)]
                        for j in range(6)])
HULL_ROUNDING_M = 1e-12  # m: a hull within the limits by this is so despite rounding


def _extremes(c):
    """(min, max) over s in [0, 1] of the polynomials sum c_i s^i (c (..., d + 1))."""
    d = c[..., 1:] * np.arange(1, c.shape[-1])                             # derivative
    lead = d[..., -1:]
    scale = np.max(np.abs(d), axis=-1, keepdims=True) + 1e-300
    lead = np.where(np.abs(lead) < 1e-12 * scale, np.copysign(1e-12, lead) * scale, lead)
    n = d.shape[-1] - 1
    s = [np.zeros(c.shape[:-1]), np.ones(c.shape[:-1])]
    s += [np.full(c.shape[:-1], f) for f in np.linspace(0.0, 1.0, 9)[1:-1]]
    if n >= 1:
        comp = np.zeros(c.shape[:-1] + (n, n))
        comp[..., 0, :] = -d[..., -2::-1] / lead                          # monic companion
        comp[..., np.arange(1, n), np.arange(n - 1)] = 1.0
        roots = np.linalg.eigvals(comp)
        s += [np.clip(np.where(np.isfinite(r), r.real, 0.0), 0.0, 1.0) for r in np.moveaxis(roots, -1, 0)]
    s = np.stack(s, axis=-1)                                               # (..., m)
    g = np.zeros_like(s)
    for coef in np.moveaxis(c, -1, 0)[::-1]:                               # Horner
        g = g * s + coef[..., None]
    return np.min(g, axis=-1), np.max(g, axis=-1)


# ----------------------------------------------------------------------------- the check


def unique_sorted(a):
    """The distinct values of a 1-D array, ascending (np.unique's answer; np.unique itself
    imports numpy.ma, 10 - 20 ms of a plan's start-up)."""
    a = np.sort(np.asarray(a).ravel())
    return a[np.concatenate([[True], a[1:] != a[:-1]])] if a.size else a


@dataclass(frozen=True)
class ExecutionCheck:
    """The check of one trajectory as executed: ``ok``; ``reason`` (what failed, one
    line); least tension margin (N, and normalised by fmax - fmin) and when (s);
    largest winch speed and acceleration over the limits (1 = at a limit); the segments
    (indices k of [t_k, t_k+1]) where something failed; ``samples`` checked."""

    ok: bool
    reason: str
    least_tension_margin_n: float
    least_margin: float
    worst_t: float
    speed_ratio: float
    accel_ratio: float
    bad_segments: np.ndarray
    samples: int
    added: int = 0       # points ``executable`` added
    slowdown: float = 1.0  # the uniform slow-down ``executable`` applied
    # a whole check's tension margins (M, m) N, lost poses (M,) and poses in collision (M,)
    # at its samples (None when the tensions were not reached): what
    # ``check_executed(reuse=...)`` takes over
    per_sample: tuple = field(default=None, repr=False, compare=False)

    def describe(self):
        """One line: how the trajectory was made executable and its least margin."""
        slow = f", slowed x {self.slowdown:.3g}" if self.slowdown > 1 else ""
        return (f"checked as a JointTrajectoryController executes it (quintic, every "
                f"{CHECK_DT * 1e3:g} ms): {self.added} points added{slow}, least tension "
                f"slack {self.least_tension_margin_n:.3g} N")


def check_executed(robot, t_wp, L, V, A, seed, mass=None, inertia=None, max_cable_speed=np.inf,
                   max_cable_accel=np.inf, dt=CHECK_DT, within=None, reuse=None, collision=None):
    """ExecutionCheck of the points (t_wp (N,) s; L, V, A (N, m) m, m/s, m/s^2) executed by
    a JTC (module docstring). ``seed(t)`` -> (p (M, 3), R (M, 3, 3)): a pose near the
    platform's at times t (the planned motion), where forward kinematics starts. ``mass``
    (kg) and ``inertia`` (3x3 kg m^2 about the load point) None: no inertial wrench.
    ``within`` (K, 2) s: check only the samples in these intervals (the same samples as a
    whole check has there); None: all.
    ``reuse`` (previous, changed): a whole check (``within`` None) of this trajectory before
    points were inserted only inside the intervals ``changed`` (K, 2) s, with the same first
    and last time. Its tension margins are taken over outside ``changed``: there the samples,
    the quintic (each segment's own from its two end points) and the seed (interpolated
    between the same two waypoints) are unchanged, so forward kinematics and the tensions
    (row by row) are the same numbers (with m > 6 to rounding: the centred nominal's Newton
    starts from the previous sample's, ``wrench``). The answer is the whole check's.
    ``collision``: the scene's CollisionModel (or None): the executed poses at the same
    samples must keep its clearance too."""
    t_wp, L, V, A = (np.asarray(x, dtype=float) for x in (t_wp, L, V, A))
    if len(t_wp) < 2:  # one point: the controller holds it
        return ExecutionCheck(True, "", np.inf, np.inf, float("nan"), 0.0, 0.0,
                              np.zeros(0, dtype=int), 0)
    n = max(4, int(np.ceil((t_wp[-1] - t_wp[0]) * PHASES / dt)))
    ts = np.linspace(t_wp[0], t_wp[-1], n + 1)      # every dt / PHASES s or less
    q = min(PHASES, n // 4)                          # the stencil: t - h, t, t + h
    h = ts[q] - ts[0]
    sel = np.ones(n + 1, dtype=bool)
    if within is not None:
        w = np.asarray(within, dtype=float).reshape(-1, 2)
        sel = np.any((ts[:, None] >= w[:, 0]) & (ts[:, None] <= w[:, 1]), axis=1)
    # lengths and winch rates first: the quintic's own, exactly per segment; the tensions
    # (forward kinematics, sampled) only if they pass
    k = np.arange(len(t_wp) - 1)
    if within is not None:
        k = k[np.any((t_wp[1:, None] >= w[:, 0]) & (t_wp[:-1, None] <= w[:, 1]), axis=1)]
    limits = (robot.length_min - TOL, robot.length_max + TOL)
    lo, hi, vel, acc = quintic_bounds(t_wp, L, V, A, k, limits)
    lengths_ok = (lo >= limits[0]) & (hi <= limits[1])
    m = L.shape[1]
    speed = np.max(vel / np.broadcast_to(max_cable_speed, (m,)), axis=1, initial=0.0)
    accel = np.max(acc / np.broadcast_to(max_cable_accel, (m,)), axis=1, initial=0.0)
    bad_k = k[~np.all(lengths_ok, axis=1) | (speed > 1 + TOL) | (accel > 1 + TOL)]
    margin, worst_t = np.full((0, m), np.inf), float("nan")
    lost = blocked = np.zeros(0, dtype=bool)
    span = robot.tension_max - robot.tension_min
    per_sample = None
    if bad_k.size == 0:
        mid = np.flatnonzero(sel[q:n + 1 - q]) + q   # samples whose tensions are checked
        old = _reusable(reuse, within, mid, ts)
        if old is None:
            margin, lost, blocked = _executed_margins(robot, t_wp, L, V, A, seed, ts, mid, q,
                                                      mass, inertia, collision)
        else:
            changed, margin, lost, blocked = old
            if changed.any():
                margin[changed], lost[changed], blocked[changed] = _executed_margins(
                    robot, t_wp, L, V, A, seed, ts, mid[changed], q, mass, inertia, collision)
        per_sample = (margin, lost, blocked) if within is None else None
        t_bad = ts[mid[(np.min(margin, axis=1) < -TOL) | lost | blocked]]
        near = np.concatenate([t_bad - h, t_bad, t_bad + h])  # the stencil's segments
        bad_k = np.clip(np.searchsorted(t_wp, near, side="right") - 1, 0, len(t_wp) - 2)
        if mid.size:
            worst_t = float(ts[mid][np.argmin(np.min(margin / span, axis=1))])
    least_n = float(np.min(margin, initial=np.inf))
    return ExecutionCheck(ok=bad_k.size == 0,
                          reason=_reason(least_n, lengths_ok, speed, accel, lost, blocked),
                          least_tension_margin_n=least_n,
                          least_margin=float(np.min(margin / span, initial=np.inf)),
                          worst_t=worst_t, speed_ratio=float(np.max(speed, initial=0.0)),
                          accel_ratio=float(np.max(accel, initial=0.0)),
                          bad_segments=unique_sorted(bad_k), samples=int(np.sum(sel)),
                          per_sample=per_sample)


def _reusable(reuse, within, mid, ts):
    """(changed (M,) bool: samples to compute again, margins, lost, blocked: copies of the
    previous whole check's) when ``reuse`` applies to this whole check (``check_executed``), else None."""
    if reuse is None or within is not None or reuse[0].per_sample is None:
        return None
    margin, lost, blocked = reuse[0].per_sample
    if len(margin) != len(mid):
        return None
    w = np.asarray(reuse[1], dtype=float).reshape(-1, 2)
    t = ts[mid]
    changed = np.any((t[:, None] >= w[:, 0]) & (t[:, None] <= w[:, 1]), axis=1)
    return changed, margin.copy(), lost.copy(), blocked.copy()


def _executed_margins(robot, t_wp, L, V, A, seed, ts, mid, q, mass, inertia, collision=None):
    """Tension margins (M, m) N at the samples ts[mid] of the executed motion (forward
    kinematics of the quintic's lengths, differences over ts[mid -+ q]), where forward
    kinematics lost the platform (M,) (no convergence, or a twin far from the seed), and
    where the pose is closer to the scene than its clearance (M,) (none without a
    ``collision`` model)."""
    need = unique_sorted(np.concatenate([mid - q, mid, mid + q]))
    pos = quintic(t_wp, L, V, A, ts[need], rates=False)[0]
    p_seed, R_seed = seed(ts[need])
    elastic = is_elastic(robot)
    if elastic:  # the static equilibrium first: the motion's accelerations from it
        fk = _equilibria(robot, pos, p_seed, R_seed)
    else:
        fk = forward_kinematics_many(robot, pos, p_seed, R_seed)
    lost = ~fk.ok | (np.linalg.norm(fk.p - p_seed, axis=1) > SEED_TOL_M)
    c_all = load_point(robot, fk.p, fk.R)
    at = [np.searchsorted(need, mid + o) for o in (-q, 0, q)]
    R, c = [fk.R[i] for i in at], [c_all[i] for i in at]
    h = ts[q] - ts[0]
    c_dd = (c[2] - 2 * c[1] + c[0]) / h ** 2
    front, back = _stencil_turns(fk.R, need, mid, q)
    omega = (back + front) / (2 * h)
    alpha = (back - front) / h ** 2
    p_mid, lost_mid = fk.p[at[1]], lost[at[1]]
    if elastic:  # the equilibrium with the inertial wrench, from the static one
        eq = _equilibria(robot, pos[at[1]], p_mid, R[1],
                         _inertial(R[1], c[1], c_dd, omega, alpha, mass, inertia))
        p_mid, R[1] = eq.p, eq.R
        lost_mid = lost_mid | ~eq.ok  # its sway from the static pose is the motion's own
        f, v = eq.tensions, _band(robot, p_mid, R[1])
    else:
        f, v = _tensions(robot, p_mid, R[1], c[1], c_dd, omega, alpha, mass, inertia)
    margin = np.minimum(f - v - robot.tension_min, robot.tension_max - f - v)
    blocked = np.zeros(len(mid), dtype=bool)
    if collision is not None:  # the samples in order: exact where a sweep bound cannot clear them
        blocked = collision.blocked_along(p_mid, R[1])
    return margin, lost[at[0]] | lost_mid | lost[at[2]], blocked


def _stencil_turns(R, need, mid, q):
    """(front, back) (M, 3) rad: the body-frame rotation vectors from sample mid - q to mid
    and from mid to mid + q of the rotations R (len(need), 3, 3) at the samples ``need``.
    The back turn of a sample is the front turn of the one q later: each turn is computed
    once (of a whole check's contiguous samples, half as many)."""
    first = unique_sorted(np.concatenate([mid - q, mid]))    # where each turn starts
    a, b = np.searchsorted(need, first), np.searchsorted(need, first + q)
    turn = turns(R, a, b)  # compiled: Rotation.from_matrix(R[a]^T R[b]).as_rotvec()
    return turn[np.searchsorted(first, mid - q)], turn[np.searchsorted(first, mid)]


def _equilibria(robot, L0, p, R, inertial=None):
    """``model.elastic.equilibrium_poses`` of cables of unstretched lengths L0 (M, m) m
    under the load wrench (``wrench.nominal_wrench``'s force at the load point and
    moment) minus ``inertial`` (M, 6), the motion's wrench about the origin (None: at rest),
    from the poses (p (M, 3) m, R (M, 3, 3))."""
    force, moment, arm = static_load(robot, len(p))
    if inertial is not None:  # [m c''; c x m c'' + R (I alpha + omega x I omega)]
        c = load_point(robot, p, R)
        moment = moment - (inertial[:, 3:] - cross(c, inertial[:, :3]))
        force, arm = force - inertial[:, :3], arm - inertial[:, :3]
    return equilibrium_poses(robot, L0, p, R, force, moment, arm)


def _band(robot, p, R):
    """The ellipsoid's spread v (M, m) N of the tensions at poses (p (M, 3) m,
    R (M, 3, 3)): the rule's band (|rows of J^-1 L| for six cables)."""
    return rule_tensions(robot, p, R)[1]


def _tensions(robot, p, R, c, c_dd, omega, alpha, mass, inertia):
    """Tensions f (M, m) balancing the load wrench minus the inertial wrench, and the
    ellipsoid's spread v (M, m), N: those of the published tension rule
    (``wrench.rule_tensions``: J^-1 for six cables; with more its centred nominal t0 moved
    by P times the inertial wrench, and its band v = |rows of P L|, P_K's with elastic
    cables)."""
    inertial = None if mass is None else _inertial(R, c, c_dd, omega, alpha, mass, inertia)
    return rule_tensions(robot, p, R, inertial)


def _inertial(R, c, c_dd, omega, alpha, mass, inertia):
    """The inertial wrench (M, 6) of the load (zero without a mass), as ``_tensions``."""
    if mass is None:
        return np.zeros((len(c), 6))
    I = np.asarray(inertia, dtype=float).reshape(3, 3)
    moment = np.einsum("nij,nj->ni", R, alpha @ I.T + cross(omega, omega @ I.T))
    force = mass * c_dd
    return np.concatenate([force, cross(c, force) + moment], axis=1)


def _reason(least_n, lengths_ok, speed, accel, no_pose, blocked=()):
    bad = []
    if least_n < -TOL:
        bad.append(f"tension margin {least_n:.3g} N")
    if not np.all(lengths_ok):
        bad.append("cable length out of range")
    if np.max(speed) > 1 + TOL:
        bad.append(f"winch speed {np.max(speed):.4g} x the limit")
    if np.max(accel) > 1 + TOL:
        bad.append(f"winch acceleration {np.max(accel):.4g} x the limit")
    if np.any(no_pose):
        bad.append("forward kinematics lost the platform's pose")
    if np.any(blocked):
        bad.append("a pose within the scene's clearance")
    return ", ".join(bad)


def path_seed(path):
    """seed(t) for check_executed from a PlannedPath: position linear and orientation
    slerp between its waypoints (near the platform's pose between dense waypoints)."""
    rot = Rotation.from_quat(path.quaternion)
    slerp = Slerp(path.t, rot)

    def seed(t):
        k = np.clip(np.searchsorted(path.t, t, side="right") - 1, 0, len(path) - 2)
        w = ((t - path.t[k]) / (path.t[k + 1] - path.t[k]))[:, None]
        return (1 - w) * path.p[k] + w * path.p[k + 1], slerp(t).as_matrix()
    return seed


def check_path(robot, path, mass=None, inertia=None, max_cable_speed=np.inf,
               max_cable_accel=np.inf, dt=CHECK_DT, within=None, reuse=None, collision=None):
    """check_executed of a timed PlannedPath's points as a length controller receives them
    (``PlannedPath.commanded`` with the robot's stiffness: lengths, velocities,
    accelerations at path.t), forward kinematics seeded from its waypoint poses."""
    L, V, A = with_commands(robot, path).commanded()  # the robot's stiffness
    return check_executed(robot, path.t, L, V, A, path_seed(path), mass, inertia,
                          max_cable_speed, max_cable_accel, dt, within, reuse, collision)


# ----------------------------------------------------------------------------- making it pass

def executable(robot, path, motion=None, mass=None, inertia=None, max_cable_speed=np.inf,
               max_cable_accel=np.inf, max_points=MAX_POINTS, collision=None, expired=None):
    """(path, ExecutionCheck): the timed PlannedPath ``path`` with points added until a JTC
    executing it passes ``check_path``, or the last check (``ok`` False) if it does not
    within ``max_points`` points and the rounds allowed, or once ``expired()`` (a
    zero-argument callable: the caller's time limit or cancel) is true after a check.

    ``motion(t, scale)`` -> PlannedPath: the motion that was checked (e.g. the dynamic
    timing's, ``trajectory.dynamics.motion_rows``), slowed ``scale`` times, at times t
    (s). Where the check fails, the midpoint of each failing segment is added, with that
    motion's own pose, lengths, rates, accelerations and tensions: between dense points
    the quintic approaches the motion. Two rounds after which the check fails over as much
    time as before them (``failing_time``, PROGRESS) end the adding: the motion itself
    fails there (IPAnema 2: eight rounds kept failing over the same 0.2 s, at -19.1 N, and
    took the path from 314 to 3715 points before the slow-downs that passed it). When
    that is not enough (or without a motion: the
    quasi-static timing of straight cable segments, whose quintic overshoots the winch
    limits), the whole trajectory is slowed uniformly. A slowed quintic is the same curve
    in lengths with rates / scale and accelerations / scale^2, so the winch ratios shrink
    exactly, and the inertial wrench shrinks towards the static one (feasible at every
    planned pose)."""
    scale, rounds, winch_rounds, slowed, n = 1.0, 0, 0, 0, len(path)
    within = None  # after adding points, only the samples they change are checked again
    whole, changed = None, []  # the last whole check, and where points were added since
    failing = []  # failing_time of the checks points were added for since the last slow-down
    while True:
        reuse = (whole, np.concatenate(changed)) if whole is not None and changed else None
        check = check_path(robot, path, mass, inertia, max_cable_speed, max_cable_accel,
                           within=within, reuse=reuse, collision=collision)
        check = replace(check, added=len(path) - n, slowdown=scale)
        if within is None:
            whole, changed = check, []
        if check.ok and within is None:
            return path, check
        if check.ok:
            within = None  # the whole trajectory once more: the answer's own check
            continue
        if expired is not None and expired():
            return path, replace(check, reason=f"{check.reason} when stopped after {rounds} "
                                               f"rounds of added points and {slowed} slow-downs")
        k = check.bad_segments
        winch_only = not np.isfinite(check.least_tension_margin_n)  # tensions not reached
        winch_rounds += winch_only
        failing_now = failing_time(path, k)
        if (motion is not None and rounds < MAX_ROUNDS and len(path) + k.size <= max_points
                and winch_rounds <= WINCH_ROUNDS
                and not (len(failing) >= 2 and failing_now > (1 - PROGRESS) * failing[-2])
                and not (winch_only and _points_exceed(robot, path, max_cable_speed,
                                                       max_cable_accel))):
            failing.append(failing_now)
            t = 0.5 * (path.t[k] + path.t[k + 1])
            within = np.column_stack([path.t[k] - CHECK_DT, path.t[k + 1] + CHECK_DT])
            changed.append(within)
            path = _merged(path, motion(t, scale), k + 1)
            rounds += 1
        elif slowed < SLOWDOWNS:
            step = SLOWDOWN if winch_only else TENSION_SLOWDOWN
            c = max(step, check.speed_ratio, np.sqrt(check.accel_ratio)) * (1 + 1e-6)
            path, scale, slowed, within = slow_down(robot, path, c), scale * c, slowed + 1, None
            whole, changed, failing = None, [], []  # every sample changes
            winch_rounds = 0
        else:
            return path, replace(check, reason=f"{check.reason} after {rounds} rounds of "
                                               f"added points ({len(path)} points) and "
                                               f"{slowed} slow-downs (x {scale:.3g})")


def failing_time(path, k):
    """Seconds of the path's segments k (the check's failing ones, ``bad_segments``)."""
    return float(np.sum(path.t[k + 1] - path.t[k]))


def _points_exceed(robot, path, max_cable_speed, max_cable_accel):
    """Do the commanded rates at the points themselves exceed a winch limit? Points added
    between them cannot lower those (with elastic cables the stretch's own rates add to the
    motion's, which the timing kept just within the limits): only slowing down does."""
    _, V, A = with_commands(robot, path).commanded()
    m = V.shape[1]
    return bool(np.max(limit_ratio(V, A, np.broadcast_to(max_cable_speed, (m,)),
                                   np.broadcast_to(max_cable_accel, (m,)))) > 1 + TOL)


def spline_rates(path):
    """``path`` with the cable rates and accelerations of the C2 cubic spline through its
    lengths at its times, at rest at both ends: a JTC's quintic through these points is
    that spline exactly. For a timing without a motion of its own (the quasi-static
    vertex model): on Robot 1's Table 1 paths its quintic overshoots the winch acceleration
    1.07 - 1.16 x, the waypoint parabolas' 1.4 - 1.6 x (so the slow-down is smaller)."""
    if len(path) < 2:
        return path
    spline = CubicSpline(path.t, path.lengths, bc_type="clamped")
    return replace(path, velocities=spline(path.t, 1), accelerations=spline(path.t, 2))


def _merged(path, rows, at):
    """``path`` with the rows of the PlannedPath ``rows`` inserted before indices ``at``;
    each new row's tau continues its left neighbour's azimuth (phi at a pole)."""
    fields = {}
    for name in path.__dataclass_fields__:
        if name in ("cable_stiffness", "command_window_s"):  # not per waypoint
            fields[name] = getattr(path, name)
            continue
        new = np.asarray(getattr(rows, name))
        if name == "tau":
            R = Rotation.from_quat(rows.quaternion).as_matrix()
            new = tau_from_rotation(R, phi_hint=path.tau[at - 1, 0])
        fields[name] = np.insert(np.asarray(getattr(path, name)), at, new, axis=0)
    return type(path)(**fields)


def slow_down(robot, path, scale):
    """``path`` executed ``scale`` (> 1) times slower: times x scale, cable rates / scale,
    accelerations / scale^2, and the dynamic part of the tensions / scale^2 (the static
    tensions of each pose, f0, unchanged; the ellipsoid's spread unchanged)."""
    R = Rotation.from_quat(path.quaternion).as_matrix()
    f0 = rule_tensions(robot, path.p, R)[0]
    f = f0 + (path.tension_nominal - f0) / scale ** 2
    return replace(path, t=path.t * scale, velocities=path.velocities / scale,
                   accelerations=path.accelerations / scale ** 2, tension_nominal=f,
                   tension_min=f - (path.tension_nominal - path.tension_min),
                   tension_max=f + (path.tension_max - path.tension_nominal))
