"""Time-optimal timing that keeps the tensions in range under the motion's own accelerations
(TOPP-RA, the ``toppra`` library).

    timing = dynamic_timing(robot, path, mass=0.6, inertia=I, max_cable_speed=0.05,
                            max_cable_accel=0.2)
    timing.path   # PlannedPath: t, cable rates, dynamic tension envelope at the waypoints

Model (SI units)
----------------
The geometric path is C2 through the planned waypoints: p(s) a natural cubic spline, R(s)
scipy's RotationSpline (C2 on SO(3); both in numpy, ports/splines.py), s the
cumulative pose distance |dp| + L |d angle| (m).
With u = s'' and x = s'^2, the centre of mass c = p + R g (g: the load point, platform
frame) has c'' = c_s u + c_ss x; the body angular velocity is w s' and its derivative
w u + w_s x (w = dR/ds in the body frame). Newton-Euler about O gives the inertial wrench

    w_in = A u + B x,  A = [m c_s; c x m c_s + R I w],
                       B = [m c_ss; c x m c_ss + R (I w_s + w x I w)],

and the cables must balance w0 - w_in (w0: the load wrench of the quasi-static model, its
gravity force m g). Tensions f = J^-1 (w0 - w_in) are linear in (u, x), the ellipsoid's
spread v = sqrt(diag(J^-1 E^-1 J^-T)) does not depend on them, so every constraint

    fmin + v <= f <= fmax - v,   |L_s u + L_ss x| <= a_max,   L_s^2 x <= v_max^2

is linear in (u, x) at each gridpoint: exactly TOPP-RA's setting. With elastic cables
(m > 6) the winch limits bound the commanded, unstretched lengths (what a controller is sent,
``PlannedPath.commanded``): L_s and L_ss are then theirs (``_command_rates``). toppra
solves it on a grid of the path (collocation) and gives the largest x(s), time-optimal at
the grid.
``toppra`` is used rather than our own pass because it is the maintained reference
implementation of TOPP-RA (Pham & Pham 2018), with its LP-based reachability.

The result is then checked densely in time (every ``check_dt`` s): positions, velocities
and accelerations of the spline motion, the dynamic wrench, lengths, tensions with the
ellipsoid's spread, winch speeds and accelerations. Between gridpoints the collocation may
miss a violation; then the timing is slowed by ``SLOWDOWN`` and checked again. When no
dynamically feasible timing exists (a zero static margin, or more rounds than
``MAX_SLOWDOWNS``), ``feasible`` is False and the reason is given.
"""

from dataclasses import dataclass, replace
from functools import partial

import numpy as np

from ..errors import InputError, check_finite
from ..wrench import band_feasibility, rule_responses, rule_tensions
from ..model.elastic import is_elastic
from ..model.pose import tau_from_rotation
from .executed import executable, spline_rates, unique_sorted
from .motion_kernel import motion_terms
from .path import (COMMAND_PATH_WINDOW_M, PlannedPath, averaged_along_path, cable_arc_length,
                   command_tensions, command_window, with_commands)
from ..ports import CubicSpline, Rotation, RotationSpline, import_toppra, spline_derivatives

GRID_POINTS = 400       # toppra gridpoints along the path (at least one per waypoint)
CHECK_DT = 1e-3         # s: the dense check's time step
SLOWDOWN = 1.02         # time scale per failed dense check
MAX_SLOWDOWNS = 40
TOL = 1e-9              # N, m/s, m/s^2: rounding allowed in the dense check
DERATE = 1e-3           # share of the winch limits and tension ranges kept in reserve
SUSPECTS = 16           # failing runs of a dense check whose worst samples the next one
                        # looks at first
toppra = import_toppra()  # without matplotlib and scipy.interpolate (start-up)
toppra.setup_logging("ERROR")  # its warnings repeat what feasible=False says


@dataclass
class DynamicTiming:
    """``path`` (PlannedPath re-timed, tensions dynamic at the waypoints), ``feasible``,
    ``reason`` (when not), ``duration`` (s), ``slowdown`` (time scale over toppra's
    optimum, 1.0 when its timing passed the dense check), the dense check's least tension
    margin (N) and its sample count, and the profile (``s`` gridpoints, ``sd`` = s')."""

    path: PlannedPath
    feasible: bool
    reason: str
    duration: float
    slowdown: float
    least_tension_margin_n: float
    samples: int
    s: np.ndarray
    sd: np.ndarray
    geometry: object = None
    reachability: object = None  # the toppra instance that timed it: ``limit`` asks it

    @property
    def limit(self):
        """The largest s' (m/s) at each gridpoint over every feasible s'' (None without
        ``reachability``): two LPs per gridpoint, solved when a picture asks, not per plan."""
        if self.reachability is None:
            return None
        return np.sqrt(np.maximum(self.reachability.compute_feasible_sets()[:, 1], 0.0))

    def pose_at(self, t):
        """The timed motion itself: positions (M, 3) m and rotations (M, 3, 3) at times t (s)."""
        t = np.clip(np.asarray(t, dtype=float), 0.0, self.duration)
        ss, _, _ = _state_at(t, self.s, self.sd, _grid_times(self.s, self.sd))
        return self.geometry.p(ss), self.geometry.R(ss).as_matrix()


class _Geometry:
    """The C2 path through the waypoints and its derivatives in s."""

    def __init__(self, robot, path):
        L_ref = float(np.mean(np.linalg.norm(robot.platform_anchors, axis=1)))
        rot = Rotation.from_quat(path.quaternion)
        step = np.linalg.norm(np.diff(path.p, axis=0), axis=1) + L_ref * (rot[:-1].inv() * rot[1:]).magnitude()
        keep = np.concatenate([[True], step > 1e-12])  # drop repeated waypoints
        self.s_wp = np.concatenate([[0.0], np.cumsum(step)])
        self.keep = keep
        knots = self.s_wp[keep]
        if knots.size < 2:
            raise InputError("path", len(path), "needs two distinct waypoints to be timed")
        self.length = float(knots[-1])
        self.p = CubicSpline(knots, path.p[keep], bc_type="natural")
        self.R = RotationSpline(knots, rot[keep])
        # the static tensions the commands average along the path (``_command_rates``)
        self.arc = cable_arc_length(path.lengths)
        self.f0_wp = None  # six cables: the stretch of t0 = J^-1 w0 is left to ``executable``
        if is_elastic(robot) and averaged_along_path(len(robot.base_anchors)):
            self.f0_wp = rule_tensions(robot, path.p, rot.as_matrix())[0]

    def at(self, s):
        """p, R, c_s-ready pieces at s (M,): p, p_s, p_ss (M,3), R (M,3,3), w, w_s (M,3) body."""
        s = np.clip(s, 0.0, self.length)
        rot, w, w_s = spline_derivatives(self.R, s)
        return (*spline_derivatives(self.p, s), rot.as_matrix(), w, w_s)


def _terms(robot, geo, s, mass, inertia):
    """Per s: cable lengths L (M,6), L_s, L_ss, static tensions f0 (M,6), spread v (M,6),
    tension rates a_f, b_f (M,6) with f = f0 + a_f u + b_f x."""
    p, p_s, p_ss, R, w, w_s = geo.at(s)
    # w_in = A u + B x and the lengths' s-rates, compiled (motion_kernel: the module
    # docstring's Newton-Euler; L_s = u . q_s, L_ss = (|q_s|^2 - L_s^2) / L + u . q_ss of
    # the platform anchors q_i = p + R b_i)
    A, B, L, L_s, L_ss = motion_terms(robot, p, p_s, p_ss, R, w, w_s, mass, inertia)
    # the published rule, t0 + P (w - w0) (P = J^-1 for six cables), its band v = |rows of
    # P L| (with elastic cables P_K's: wrench.stiffness_band), and P A, P B, in one pass
    f0, v, change = rule_responses(robot, p, R, np.stack([A, B], axis=1))
    return L, L_s, L_ss, f0, v, -change[:, 0], -change[:, 1]


def _command_rates(robot, geo, s, L, L_s, L_ss):
    """The s-derivatives (M, m) of the lengths the winches are commanded at s (M,), what the
    winch limits bound: for elastic cables the unstretched lengths L0 = L EA / (EA + f) with
    f the static tensions averaged along the path as ``PlannedPath.commanded`` averages
    them (over +- COMMAND_PATH_WINDOW_M of cable-space arc length, through the waypoints'
    values). The centred rule of m > 6 cables turns its nominal by hundreds of newtons
    over millimetres of motion; the stretch's rates then outrun the geometric ones
    (test_elastic_commands.py), and only a timing that bounds them keeps the winches
    within their limits. Rigid cables and six cables (t0 = J^-1 w0 turns no faster than the
    pose; its stretch's rates are left to ``executable``, as in the command's average):
    L_s, L_ss themselves."""
    if geo.f0_wp is None:
        return L_s, L_ss
    k = np.clip(np.searchsorted(geo.s_wp, s, side="right") - 1, 0, len(geo.s_wp) - 2)
    ds = geo.s_wp[k + 1] - geo.s_wp[k]
    slope = np.where(ds > 0, (geo.arc[k + 1] - geo.arc[k]) / np.where(ds > 0, ds, 1.0), 0.0)
    arc = geo.arc[k] + slope * (np.clip(s, geo.s_wp[k], geo.s_wp[k + 1]) - geo.s_wp[k])
    f, f_a, f_aa = command_tensions(geo.arc, geo.f0_wp, COMMAND_PATH_WINDOW_M, at=arc)
    f_s, f_ss = f_a * slope[:, None], f_aa * (slope ** 2)[:, None]
    EA = robot.cable_stiffness
    c = EA / (EA + f)                                    # L0 = c L
    c_s = -EA * f_s / (EA + f) ** 2
    c_ss = -EA * f_ss / (EA + f) ** 2 + 2 * EA * f_s ** 2 / (EA + f) ** 3
    return c * L_s + c_s * L, c * L_ss + 2 * c_s * L_s + c_ss * L


class _WrenchConstraint(toppra.constraint.LinearConstraint):
    """Tensions with the ellipsoid's spread and the winch limits, as toppra's canonical
    linear constraint v = a u + b x + c, F v <= g, with x bounded by the winch speeds."""

    def __init__(self, terms, robot, vmax, amax):
        super().__init__()
        self.terms, self.robot, self.vmax, self.amax = terms, robot, vmax, amax
        self.discretization_type = toppra.constraint.DiscretizationType.Interpolation
        # F is the same matrix at every gridpoint: toppra's seidel wrapper then forms
        # F a, F b, F c for all gridpoints in one product, not by a Python loop of three
        # np.dot per gridpoint (3 - 4 ms a timing; each entry is one +-a_j plus exact zeros,
        # so the same numbers: test_timing_reuse)
        self.identical = True

    def compute_constraint_params(self, path, gridpoints, *args, **kwargs):
        L, L_s, L_ss, f0, v, a_f, b_f = self.terms
        n = len(gridpoints)
        a = np.concatenate([L_s, a_f], axis=1)
        b = np.concatenate([L_ss, b_f], axis=1)
        c = np.concatenate([np.zeros_like(f0), f0], axis=1)
        m = f0.shape[1]
        eye = np.eye(2 * m)
        F = np.broadcast_to(np.concatenate([eye, -eye]), (n, 4 * m, 2 * m)).copy()
        r = self.robot
        reserve = DERATE * (r.tension_max - r.tension_min)
        g = np.concatenate([np.broadcast_to(self.amax, (n, m)), r.tension_max - v - reserve,
                            np.broadcast_to(self.amax, (n, m)), -(r.tension_min + v + reserve)], axis=1)
        with np.errstate(divide="ignore"):
            x_max = np.min(np.where(np.abs(L_s) > 1e-12, self.vmax ** 2 / L_s ** 2, np.inf), axis=1)
        xbound = np.column_stack([np.zeros(n), np.minimum(x_max, 1e12)])
        # interpolation: each interval's constraints also hold at its far end (toppra's
        # first-order scheme), which the collocation at gridpoints alone misses
        a, b, c, F, g, ubound, xbound = toppra.constraint.canlinear_colloc_to_interpolate(
            a, b, c, F, g, None, xbound, np.asarray(gridpoints))
        return a, b, c, F[0], g, ubound, xbound  # ``identical``: one F, g per gridpoint


class _Interval:
    """The minimal geometric path toppra needs: its interval and dimension."""

    def __init__(self, length, m=6):
        self.path_interval = np.array([0.0, length])
        self.dof = m
        self.duration = length


def dynamic_timing(robot, path, mass, inertia, max_cable_speed, max_cable_accel,
                   grid_points=GRID_POINTS, check_dt=CHECK_DT):
    """DynamicTiming of ``path`` (a PlannedPath) for a load of ``mass`` (kg) and
    ``inertia`` (3x3 kg m^2 about the centre of mass, platform frame) at robot.load_point,
    winch limits in m/s and m/s^2 (one number or 6). Never raises for an infeasible
    timing: ``feasible`` False with the reason."""
    mass = check_finite("load.mass", mass, positive=True)
    inertia = np.asarray(inertia, dtype=float).reshape(3, 3)
    m = len(robot.base_anchors)
    vmax = np.broadcast_to(np.asarray(max_cable_speed, dtype=float), (m,))
    amax = np.broadcast_to(np.asarray(max_cable_accel, dtype=float), (m,))
    geo = _Geometry(robot, path)
    grid = _grid(geo, grid_points)
    L, L_s, L_ss, f0, v, a_f, b_f = _terms(robot, geo, grid, mass, inertia)
    terms = (L, *_command_rates(robot, geo, grid, L, L_s, L_ss), f0, v, a_f, b_f)
    # the winch limits (and tension ranges) derated by DERATE: between gridpoints a profile
    # at the limit overshoots it by about 1e-4 (measured), which the dense check would refuse
    instance = toppra.algorithm.TOPPRA([_WrenchConstraint(terms, robot, vmax * (1 - DERATE),
                                                          amax * (1 - DERATE))],
                                       _Interval(geo.length, m), gridpoints=grid)
    _, sd, _ = instance.compute_parameterization(0.0, 0.0)  # (s'', s', extra variables)
    if sd is None or not np.all(np.isfinite(sd)):
        return _infeasible(path, geo, grid, "no dynamically feasible timing: the path has no "
                                              "speed at which every tension stays in range")
    suspects = np.empty(0)  # s of the worst samples of the last failed dense check
    for k in range(MAX_SLOWDOWNS + 1):
        scale = SLOWDOWN ** k
        t_grid = _grid_times(grid, sd / scale)
        if not np.all(np.isfinite(t_grid)):
            break
        if k < MAX_SLOWDOWNS and _fails_near(robot, geo, grid, sd / scale, mass, inertia, vmax,
                                             amax, check_dt, suspects):
            continue  # a sample of this timing's own dense check fails: so would the check
        check = _dense_check(robot, geo, grid, sd / scale, mass, inertia, vmax, amax, check_dt)
        suspects = check[4]
        if check[0]:
            timed = _retimed(robot, path, geo, grid, sd / scale, t_grid, mass, inertia, amax)
            return DynamicTiming(path=timed, feasible=True, reason="", duration=float(t_grid[-1]),
                                 slowdown=scale, least_tension_margin_n=check[1], samples=check[2],
                                 s=grid, sd=sd / scale, geometry=geo, reachability=instance)
    return _infeasible(path, geo, grid, f"the dense check failed after {MAX_SLOWDOWNS} slowdowns "
                                        f"({check[3]})")


def tensions_over_time(robot, timing, mass, inertia, dt=CHECK_DT):
    """(t (M,), dynamic f (M, m), static f0 (M, m), spread v (M, m)) of a feasible timing,
    every dt s: what the cables carry with and without the motion's own accelerations (N)."""
    sample = _sampled(robot, timing.geometry, timing.s, timing.sd, mass, inertia, dt)
    return sample.t, sample.f, sample.f0, sample.v


@dataclass
class _Sample:
    """The timed motion every dt: times t, s' and s'' (M,), lengths L, the s-derivatives
    C_s, C_ss of the commanded lengths (``_command_rates``), dynamic tensions f, static f0
    and the ellipsoid's spread v (M, m)."""

    t: np.ndarray
    sdot: np.ndarray
    sddot: np.ndarray
    L: np.ndarray
    C_s: np.ndarray
    C_ss: np.ndarray
    f: np.ndarray
    f0: np.ndarray
    v: np.ndarray


def _sampled(robot, geo, s, sd, mass, inertia, dt, pick=None):
    """_Sample of the timing every dt s; ``pick``: only those sample indices (the same
    samples, computed row by row as in the whole set)."""
    t_grid = _grid_times(s, sd)
    t = np.append(np.arange(0.0, t_grid[-1], dt), t_grid[-1])
    if pick is not None:
        t = t[pick]
    _, sdot, sddot = state = _state_at(t, s, sd, t_grid)
    L, L_s, L_ss, f0, v, a_f, b_f = _terms(robot, geo, state[0], mass, inertia)
    f = f0 + a_f * sddot[:, None] + b_f * (sdot ** 2)[:, None]
    return _Sample(t, sdot, sddot, L, *_command_rates(robot, geo, state[0], L, L_s, L_ss),
                   f, f0, v)


def _grid(geo, n):
    """The waypoints' s and n evenly spaced ones, none closer than a tenth of the spacing to
    a waypoint (a sliver interval would turn toppra's rounding into a huge s'')."""
    even = np.linspace(0.0, geo.length, n)
    wp = unique_sorted(geo.s_wp)
    gap = np.min(np.abs(even[:, None] - wp[None, :]), axis=1)
    return unique_sorted(np.concatenate([wp, even[gap > 0.1 * geo.length / (n - 1)]]))


def _infeasible(path, geo, grid, reason):
    return DynamicTiming(path=path, feasible=False, reason=reason, duration=float(path.t[-1]),
                         slowdown=np.inf, least_tension_margin_n=-np.inf, samples=0, s=grid,
                         sd=np.zeros_like(grid))


def _grid_times(s, sd):
    """Times at the gridpoints with constant s'' between them: dt = 2 ds / (sd0 + sd1)."""
    mean = sd[:-1] + sd[1:]
    with np.errstate(divide="ignore"):
        dt = np.where(mean > 0, 2 * np.diff(s) / mean, np.inf)
    return np.concatenate([[0.0], np.cumsum(dt)])


def _state_at(t, s, sd, t_grid):
    """s, s', s'' at times t (constant s'' between gridpoints)."""
    k = np.clip(np.searchsorted(t_grid, t, side="right") - 1, 0, len(s) - 2)
    h = t_grid[k + 1] - t_grid[k]
    u = (sd[k + 1] - sd[k]) / h
    tau = t - t_grid[k]
    return s[k] + sd[k] * tau + 0.5 * u * tau ** 2, sd[k] + u * tau, u


def _limits(robot, m, vmax, amax):
    """Per sample of a _Sample: tension margins (M, m) N, winch speeds and accelerations
    (M, m) m/s, m/s^2, and which samples break a limit (M,) bool (beyond TOL)."""
    margin = np.minimum(m.f - m.v - robot.tension_min, robot.tension_max - m.f - m.v)
    speed = np.abs(m.C_s * m.sdot[:, None])
    accel = np.abs(m.C_s * m.sddot[:, None] + m.C_ss * (m.sdot ** 2)[:, None])
    broken = (np.any(margin < -TOL, axis=1) | np.any(m.L < robot.length_min - TOL, axis=1)
              | np.any(m.L > robot.length_max + TOL, axis=1) | np.any(speed > vmax + TOL, axis=1)
              | np.any(accel > amax + TOL, axis=1))
    return margin, speed, accel, broken


def _fails_near(robot, geo, s, sd, mass, inertia, vmax, amax, dt, suspects):
    """Does a sample of this timing's dense check (every dt s) break a limit, among the few
    around the path parameters ``suspects`` (where a faster timing of the same path failed)?
    True only when one does: then the whole check fails too (same samples, same rows; with
    m > 6 the same to ~1e-12 N, the centring's rounding, against TOL = 1e-9), and its ~10^4
    samples need not be computed. False says nothing."""
    if suspects.size == 0:
        return False
    t_grid = _grid_times(s, sd)
    n = len(np.arange(0.0, t_grid[-1], dt)) + 1
    near = np.floor(np.interp(suspects, s, t_grid) / dt).astype(int)
    pick = unique_sorted(np.clip(near[:, None] + np.arange(-2, 4), 0, n - 1))
    return bool(np.any(_limits(robot, _sampled(robot, geo, s, sd, mass, inertia, dt, pick),
                               vmax, amax)[3]))


def _dense_check(robot, geo, s, sd, mass, inertia, vmax, amax, dt):
    """(ok, least tension margin N, samples, what failed, s of up to SUSPECTS of the worst
    failing samples) of the timing, every dt s."""
    m = _sampled(robot, geo, s, sd, mass, inertia, dt)
    margin, speed, accel, broken = _limits(robot, m, vmax, amax)
    least = float(np.min(margin))
    span = robot.tension_max - robot.tension_min
    worst = np.max(np.maximum.reduce([-margin / span, speed / vmax - 1, accel / amax - 1]), axis=1)
    worst = np.where(broken, worst, -np.inf)
    # the worst sample of each run of failing samples (the worst runs first): a slower
    # timing fails first where the margin was least, or somewhere else that failed
    run = np.cumsum(np.concatenate([[True], broken[1:] != broken[:-1]]))
    order = np.lexsort((-worst, run))
    heads = order[np.concatenate([[True], run[order][1:] != run[order][:-1]])]
    heads = heads[broken[heads]]
    order = heads[np.argsort(-worst[heads])[:SUSPECTS]]
    bad = []
    if least < -TOL:
        bad.append(f"tension margin {least:.3g} N")
    if np.any(m.L < robot.length_min - TOL) or np.any(m.L > robot.length_max + TOL):
        bad.append("cable length")
    if np.any(speed > vmax + TOL):
        bad.append(f"winch speed {np.max(speed / vmax):.4g} x the limit")
    if np.any(accel > amax + TOL):
        bad.append(f"winch acceleration {np.max(accel / amax):.4g} x the limit")
    return not bad, least, len(m.t), ", ".join(bad), _state_at(m.t[order], s, sd,
                                                             _grid_times(s, sd))[0]


def _retimed(robot, path, geo, s, sd, t_grid, mass, inertia, amax):
    """The PlannedPath with t, cable rates and dynamic tensions at its waypoints, and the
    commands' time average that keeps their jumps' stretch within the winch acceleration
    limits amax (m/s^2, ``path.command_window``). A waypoint
    is a gridpoint, where s'' may switch: it gets the mean of its two intervals' s'' (a
    controller's quintic through it then overshoots either side by half as much as with
    one side's value; the tensions there are a mean of two feasible ones)."""
    t_wp = np.interp(geo.s_wp, s, t_grid)
    sdot = np.interp(geo.s_wp, s, sd)
    u = (sd[1:] ** 2 - sd[:-1] ** 2) / (2 * np.diff(s))                  # per interval
    g = np.clip(np.searchsorted(s, geo.s_wp), 0, len(s) - 1)            # s[g] = the waypoint's
    sddot = 0.5 * (u[np.maximum(g - 1, 0)] + u[np.minimum(g, len(u) - 1)])
    L, L_s, L_ss, f0, v, a_f, b_f = _terms(robot, geo, geo.s_wp, mass, inertia)
    f = f0 + a_f * sddot[:, None] + b_f * (sdot ** 2)[:, None]
    if is_elastic(robot):  # elastic cables at rest carry the static tensions: the ends'
        f[[0, -1]] = f0[[0, -1]]
    return replace(path, t=t_wp, velocities=L_s * sdot[:, None],
                   accelerations=L_s * sddot[:, None] + L_ss * (sdot ** 2)[:, None],
                   tension_nominal=f, tension_min=f - v, tension_max=f + v,
                   command_window_s=command_window(L, f - f0, robot.cable_stiffness, amax))


def motion_rows(robot, timing, t, mass, inertia, scale=1.0):
    """The timed motion of a feasible DynamicTiming, slowed ``scale`` (>= 1) times, at
    times ``t`` (M,) s of the slowed motion, as PlannedPath rows: pose, lengths, cable
    rates and accelerations, dynamic tensions (f -+ the ellipsoid's spread) and the static
    margin. Slowing scales s' by 1 / scale and s'' by 1 / scale^2 (the same path)."""
    t = np.clip(np.asarray(t, dtype=float) / scale, 0.0, timing.duration)
    ss, sdot, sddot = _state_at(t, timing.s, timing.sd, _grid_times(timing.s, timing.sd))
    sdot, sddot = sdot / scale, sddot / scale ** 2
    L, L_s, L_ss, f0, v, a_f, b_f = _terms(robot, timing.geometry, ss, mass, inertia)
    f = f0 + a_f * sddot[:, None] + b_f * (sdot ** 2)[:, None]
    p, rot = timing.geometry.p(ss), timing.geometry.R(ss)
    q = rot.as_quat()
    q = np.where(q[:, 3:] < 0, -q, q)
    R = rot.as_matrix()
    return PlannedPath(p=p, quaternion=q, tau=tau_from_rotation(R), lengths=L,
                       tension_min=f - v, tension_nominal=f, tension_max=f + v,
                       margin=band_feasibility(robot, p, R=R).margin, t=t * scale,
                       velocities=L_s * sdot[:, None],
                       accelerations=L_s * sddot[:, None] + L_ss * (sdot ** 2)[:, None])


def _load_rows(robot, timing, t, scale):
    """motion_rows with the robot's own load (what ``executable`` samples)."""
    return motion_rows(robot, timing, t, robot.mass, robot.inertia, scale)


def check_dynamics(robot, dynamics):
    """InputError (naming the setting ``dynamics``) when the dynamic timing is asked for
    and the robot file gives no load mass."""
    if dynamics == "dynamic" and robot.mass is None:
        raise InputError("dynamics", dynamics, "needs the load's mass (robot.load.mass)")


def timed_path(robot, path, dynamics, max_cable_speed, max_cable_accel, collision=None,
               expired=None):
    """(PlannedPath, note, ExecutionCheck): ``path`` (quasi-statically timed) re-timed by
    ``dynamics`` ("auto": dynamic when the robot has a load mass; "dynamic";
    "quasi_static"), then given the points a JointTrajectoryController needs to execute
    the motion that was checked (``trajectory.executed.executable``; the check counts the
    load's inertia unless the timing is quasi-static by choice). The note says what was
    done ("" for quasi-static); when no dynamically feasible timing exists the quasi-static
    one is kept and the note says so. The check's ``ok`` False: no executable trajectory
    within the bounds (its ``reason`` says why). ``collision``: the scene's CollisionModel
    (or None), which the executed motion keeps clear of too. The path carries the robot's
    cable stiffness: its commands (``PlannedPath.commanded``) are what was checked.
    ``expired()``: true when the caller's time is up (``executable`` stops then)."""
    check_dynamics(robot, dynamics)
    note, motion, load = "", None, (None, None)
    if not (dynamics == "quasi_static" or (dynamics == "auto" and robot.mass is None)):
        load = (robot.mass, robot.inertia)
        try:
            timing = dynamic_timing(robot, path, robot.mass, robot.inertia, max_cable_speed,
                                    max_cable_accel)
        except (np.linalg.LinAlgError, ValueError) as exc:  # e.g. J singular between waypoints
            timing, note = None, f"dynamic timing failed ({exc}): quasi-static timing kept"
        if timing is not None and not timing.feasible:
            note = f"dynamic timing impossible ({timing.reason}): quasi-static timing kept"
        elif timing is not None:
            path = timing.path
            motion = partial(_load_rows, robot, timing)
            note = (f"dynamic timing {timing.duration:.3f} s (least tension slack "
                    f"{timing.least_tension_margin_n:.3g} N, checked every {CHECK_DT * 1e3:g} ms)")
    if motion is None:  # the quasi-static timing: hand out the C2 spline through its points
        path = spline_rates(path)
    path, check = executable(robot, path, motion, *load, max_cable_speed, max_cable_accel,
                             collision=collision, expired=expired)
    return with_commands(robot, path), note, check
