"""Time parameterisation of a cable-space path under per-winch speed and acceleration limits.

    timing = time_parameterize(lengths, max_cable_speed=0.05, max_cable_accel=0.2)
    path = time_path(path, 0.05, 0.2)          # PlannedPath with t, velocities, accelerations

Model (units: m, s; ``b`` is a squared path speed, m^2/s^2)
-------------------------------------------------------------
The waypoints L_0 .. L_{N-1} (cable lengths, (N, 6) m) are joined by straight segments in
cable space, with path parameter s = Euclidean arc length in R^6 (m). Segment k has unit
direction u_k and length l_k; the winch limits v_i, a_i become, on it, a path-speed limit
W_k = min_i v_i / |u_ki| and a path-acceleration limit A_k = min_i a_i / |u_ki|.

At an interior vertex the direction turns from u_{k-1} to u_k. The parabola in s through
the three waypoints has a tangent between u_{k-1} and u_k and the second derivative
c_k = 2 (u_k - u_{k-1}) / (l_{k-1} + l_k) (1/m), so the cable acceleration near the vertex
is about u a + c_k b (a = path acceleration, m/s^2). Per cable we keep

    g_ki |a| + |c_ki| b_k <= a_i,    g_ki = max(|u_{k-1,i}|, |u_ki|),

which caps b_k (|c_ki| b_k <= a_i) and leaves the adjacent segments the acceleration budget
alpha_k(b_k) = min_i (a_i - |c_ki| b_k) / g_ki. The forward / backward pass computes the
largest vertex speeds with b_{k+1} - b_k <= 2 l_k min(A_k, alpha_k(b_k), alpha_{k+1}(b_{k+1}))
(and the mirror image), both passes in closed form; every budget decreases with b, so the
minimum of the two passes is feasible (the usual argument). Each segment is then run
time-optimally between its vertex speeds: accelerate, cruise at W_k, decelerate (a
trapezoid or triangle in speed). For a straight line this is exactly the analytic
trapezoid / triangle profile, at any sampling.

Rest points: the first and last waypoints, and both ends of every zero-length segment
(a duplicated waypoint, e.g. where two plans were joined), are passed at zero speed; a
zero-length segment lasts ``dwell_s`` so that times strictly increase.

Reported velocities and accelerations
-------------------------------------
They are what the positions and times say, so that a controller interpolating with them
(ros2_control's JointTrajectoryController: quintic splines through position, velocity and
acceleration) does not fight the waypoints: at an interior waypoint, the first and second
derivatives at t_k of the parabola through waypoints k-1, k, k+1,

    v_k = (h_k D_{k-1} + h_{k-1} D_k) / (h_{k-1} + h_k),
    a_k = 2 (D_k - D_{k-1}) / (h_{k-1} + h_k),

with D_k = (L_{k+1} - L_k) / h_k the finite-difference velocity of segment k. At a rest
point v = 0 and a is that of the parabola with zero slope there through the moving
neighbour (2 D / h, signed). So the reported accelerations *are* the second finite
differences, and v_k is a convex combination of D_{k-1} and D_k.

Guarantees (exact arithmetic; floating point adds rounding at the 1e-12 level):
- |D_ki| <= v_i: a segment's mean speed is at most its peak, which the caps keep <= W_k;
  hence |v_ki| <= v_i too;
- |a_ki| <= a_i at rest points: a segment run from rest with |path accel| <= A covers at
  most A h^2 / 2;
- at interior waypoints the second difference is the tangential part (within the budget
  above) plus the turn 2 (u_k - u_{k-1}) sdot_k / (h_{k-1} + h_k). That turn term equals the
  model's c_k b_k when the mean speed over the two segments equals sdot_k and exceeds it
  at a local speed minimum. Every waypoint is checked; where a limit is exceeded the
  vertex cap is lowered and the passes are redone (``SHRINK_ROUNDS`` rounds), then any
  remaining offender is slowed to rest, where the bound holds (the same A h^2 / 2
  argument on both sides). The result always satisfies the limits; it is time-optimal
  for the vertex model, and the discrete check only ever lowers a few corner speeds (none
  on a densely sampled smooth path).

Between waypoints a controller's own interpolant is not bound by these guarantees: a
time-optimal profile switches acceleration abruptly (bang-bang), and any C2 curve through
the same (t_k, L_k) overshoots near a switch. Measured with the quintic of
JointTrajectoryController (every 1e-5 of the duration): on 300 to 1000 waypoints of a
curved Robot 2 path, speed up to 1.006 x the limit and acceleration up to 1.4 x, during
under 0.5 % of the time; 1.8 x at a sharp corner; with only 2 waypoints the quintic's speed
peaks at 1.67 x. The planner's output stage therefore checks the quintic itself
(``trajectory.executed``) and slows a quasi-static trajectory uniformly until the quintic
keeps the limits (exact: the same curve with rates / c and accelerations / c^2).
"""

from dataclasses import dataclass, replace

import numpy as np

from ..errors import InputError, check_finite
from ..model.robot import N_CABLES
from ..model.robot_schema import MAX_CABLES, MIN_CABLES

DWELL_S = 1e-3  # s, duration of a zero-length segment (duplicated waypoint)
ZERO_LENGTH_M = 1e-9  # m, a segment this short (Euclidean, all 6 cables) has length zero
REL_TOL = 1e-9  # a reported value within limit * (1 + REL_TOL) is within the limit (rounding)
SHRINK_ROUNDS = 8  # rounds of lowering offending vertex caps before stopping there
SHRINK_MAX = 0.9  # each round lowers an offending b_k by at least this factor
MAX_DURATION_S = 1e6  # s (11.6 days): a longer trajectory is refused (slow limits, long path)
MAX_WAYPOINTS = 1_000_000  # waypoints of one trajectory


@dataclass(frozen=True)
class Timing:
    """Result of the time parameterisation of N waypoints.

    ``t`` (N,) s from the start, strictly increasing from 0; ``velocities`` and
    ``accelerations`` (N, 6) m/s, m/s^2 per cable; ``path_speed`` (N,) m/s, the speed along
    the cable-space path at each waypoint (Euclidean in R^6); ``rest`` (N,) bool, waypoints
    passed at zero speed; ``repairs``: rounds of the discrete check that lowered a speed.
    """

    t: np.ndarray
    velocities: np.ndarray
    accelerations: np.ndarray
    path_speed: np.ndarray
    rest: np.ndarray
    repairs: int = 0

    @property
    def duration(self):
        """Total duration (s)."""
        return float(self.t[-1])


# ----------------------------------------------------------------------------- validation

def check_limit(name, value, m=N_CABLES):
    """Per-winch limit: a positive finite scalar or m of them -> array (m,); InputError
    naming ``name`` (e.g. ``max_cable_speed[2]``) and the value otherwise."""
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(name, value, "expected a positive number or 6 of them") from None
    if arr.ndim == 0:
        if not (np.isfinite(arr) and arr > 0):
            raise InputError(name, float(arr), "must be a positive finite number")
        return np.full(m, float(arr))
    if arr.shape != (m,):
        raise InputError(name, arr.tolist(), f"expected a number or {m} numbers")
    bad = np.flatnonzero(~(np.isfinite(arr) & (arr > 0)))
    if bad.size:
        i = int(bad[0])
        raise InputError(f"{name}[{i}]", float(arr[i]), "must be a positive finite number")
    return arr.copy()


def check_lengths(lengths, name="lengths"):
    """Waypoint cable lengths (N, m) m, N >= 1, MIN_CABLES <= m <= MAX_CABLES, finite ->
    float array; InputError otherwise."""
    try:
        L = np.asarray(lengths, dtype=float)
    except (TypeError, ValueError):
        raise InputError(name, lengths, "expected an (N, 6) array of cable lengths (m)") from None
    if L.ndim != 2 or not MIN_CABLES <= L.shape[1] <= MAX_CABLES or L.shape[0] < 1:
        raise InputError(name, f"shape {L.shape}", f"expected an (N, m) array with N >= 1, "
                         f"{MIN_CABLES} <= m <= {MAX_CABLES}")
    if L.shape[0] > MAX_WAYPOINTS:
        raise InputError(name, f"shape {L.shape}", f"at most {MAX_WAYPOINTS} waypoints")
    bad = np.argwhere(~np.isfinite(L))
    if bad.size:
        k, i = (int(x) for x in bad[0])
        raise InputError(f"{name}[{k}][{i}]", float(L[k, i]), "must be a finite number")
    return L


# ----------------------------------------------------------------------------- geometry

@dataclass(frozen=True)
class _Geometry:
    """Per-segment and per-vertex constants of the path (see the module docstring).

    Segments (N-1): ``ell`` m, ``moving`` bool, ``W`` m/s, ``A`` m/s^2. Vertices (N):
    ``rest`` bool, ``cap`` m^2/s^2 (largest b), budget alpha_k(b) = min_i(a0 - a1 b) with
    ``a0`` (N, 6) m/s^2 and ``a1`` (N, 6) 1/m (a0 = inf where no budget applies).
    """

    ell: np.ndarray
    moving: np.ndarray
    W: np.ndarray
    A: np.ndarray
    rest: np.ndarray
    cap: np.ndarray
    a0: np.ndarray
    a1: np.ndarray


def _geometry(L, vmax, amax, zero_length_m):
    """Segment directions, limits, vertex caps and budgets of the cable-space polyline."""
    n = L.shape[0]
    dL = np.diff(L, axis=0)
    ell = np.linalg.norm(dL, axis=1)
    moving = ell > zero_length_m
    u = np.where(moving[:, None], dL / np.where(moving, ell, 1.0)[:, None], 0.0)
    with np.errstate(divide="ignore"):
        W = np.where(moving, np.min(vmax / np.abs(u), axis=1), 0.0)
        A = np.where(moving, np.min(amax / np.abs(u), axis=1), 0.0)
    rest = np.zeros(n, dtype=bool)
    rest[[0, -1]] = True
    rest[:-1] |= ~moving
    rest[1:] |= ~moving
    cap = np.full(n, np.inf)
    cap[:-1] = np.minimum(cap[:-1], W ** 2)
    cap[1:] = np.minimum(cap[1:], W ** 2)
    cap[rest] = 0.0
    a0 = np.full((n, L.shape[1]), np.inf)
    a1 = np.zeros((n, L.shape[1]))
    turn = np.flatnonzero(~rest)
    if turn.size:
        g = np.maximum(np.abs(u[turn - 1]), np.abs(u[turn]))
        c = np.abs(2.0 * (u[turn] - u[turn - 1]) / (ell[turn - 1] + ell[turn])[:, None])
        with np.errstate(divide="ignore", invalid="ignore"):
            cap[turn] = np.minimum(cap[turn], np.min(amax / c, axis=1))
            has_g = g > 0
            a0[turn] = np.where(has_g, amax / np.where(has_g, g, 1.0), np.inf)
            a1[turn] = np.where(has_g, c / np.where(has_g, g, 1.0), 0.0)
    return _Geometry(ell=ell, moving=moving, W=W, A=A, rest=rest, cap=cap, a0=a0, a1=a1)


# ----------------------------------------------------------------------------- passes

def _budget(a0, a1, b):
    """alpha(b) = min_i (a0_i - a1_i b): path acceleration left at a vertex (m/s^2)."""
    return min(p - q * b for p, q in zip(a0, a1))


def _reach(b_from, ell, A, a0_from, a1_from, a0_to, a1_to):
    """Largest b at the far end of a segment of length ``ell`` (m) reachable from
    ``b_from`` (m^2/s^2): b - b_from <= 2 ell min(A, alpha_from(b_from), alpha_to(b)).
    The last term is solved for b in closed form: b (1 + 2 ell a1) <= b_from + 2 ell a0."""
    best = b_from + 2.0 * ell * min(A, _budget(a0_from, a1_from, b_from))
    for p, q in zip(a0_to, a1_to):
        best = min(best, (b_from + 2.0 * ell * p) / (1.0 + 2.0 * ell * q))
    return best


def _passes(geo, cap):
    """Forward / backward pass: largest vertex b (N,) m^2/s^2 under ``cap`` and the
    acceleration budgets; the minimum of the two passes (both start and end at rest)."""
    n = cap.size
    ell, A = geo.ell.tolist(), geo.A.tolist()
    a0, a1, cap_l = geo.a0.tolist(), geo.a1.tolist(), cap.tolist()
    fwd = [0.0] * n
    for k in range(n - 1):
        reach = _reach(fwd[k], ell[k], A[k], a0[k], a1[k], a0[k + 1], a1[k + 1])
        fwd[k + 1] = max(0.0, min(cap_l[k + 1], reach))
    bwd = [0.0] * n
    for k in range(n - 2, -1, -1):
        reach = _reach(bwd[k + 1], ell[k], A[k], a0[k + 1], a1[k + 1], a0[k], a1[k])
        bwd[k] = max(0.0, min(cap_l[k], reach))
    return np.minimum(fwd, bwd)


def _segment_accel(geo, b):
    """Path acceleration bound (m/s^2) used inside each segment with the final vertex b:
    min(A_k, alpha_k(b_k), alpha_{k+1}(b_{k+1})), never below what the vertex speeds need."""
    alpha = np.min(geo.a0 - geo.a1 * b[:, None], axis=1)
    acc = np.minimum(geo.A, np.minimum(alpha[:-1], alpha[1:]))
    need = np.abs(np.diff(b)) / (2.0 * np.where(geo.moving, geo.ell, 1.0))
    return np.maximum(acc, need)


def trapezoid_durations(b0, b1, ell, acc, vcap):
    """Time-optimal durations (s) of straight segments of length ``ell`` (m) from path speed
    sqrt(b0) to sqrt(b1) (b in m^2/s^2) with |acceleration| <= ``acc`` (m/s^2) and speed <=
    ``vcap`` (m/s): accelerate, cruise at vcap if reached, decelerate. Requires
    |b1 - b0| <= 2 acc ell and b0, b1 <= vcap^2. Vectorised over segments."""
    b0, b1, ell, acc, vcap = np.broadcast_arrays(*(np.asarray(x, dtype=float)
                                                   for x in (b0, b1, ell, acc, vcap)))
    v0, v1 = np.sqrt(b0), np.sqrt(b1)
    peak2 = acc * ell + 0.5 * (b0 + b1)
    cruise = peak2 > vcap ** 2
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.where(acc > 0, (b1 - b0) / (4.0 * acc), 0.0)
        d1 = np.clip(0.5 * ell + shift, 0.0, ell)   # distance accelerating (no cruise)
        vp = np.sqrt(peak2)
        no_cruise = _ratio(2.0 * d1, v0 + vp) + _ratio(2.0 * (ell - d1), vp + v1)
        acc_c = np.where(cruise, acc, 1.0)
        up = np.clip((vcap ** 2 - b0) / (2.0 * acc_c), 0.0, ell)
        down = np.clip((vcap ** 2 - b1) / (2.0 * acc_c), 0.0, ell)
        flat = np.maximum(ell - up - down, 0.0)
        with_cruise = (_ratio(2.0 * up, v0 + vcap) + _ratio(2.0 * down, vcap + v1)
                       + _ratio(flat, vcap))
    return np.where(cruise, with_cruise, no_cruise)


def _ratio(num, den):
    """num / den with 0 where num is 0 (a phase of zero length takes no time)."""
    return np.where(num > 0, num / np.where(den > 0, den, 1.0), 0.0)


# ----------------------------------------------------------------------------- reported values

def waypoint_derivatives(lengths, t, rest):
    """Velocities and accelerations (N, 6) that the positions ``lengths`` (m) and times ``t``
    (s) imply: derivatives of the parabola through waypoints k-1, k, k+1 at interior
    waypoints; at ``rest`` waypoints v = 0 and a from the parabola with zero slope there
    through the moving neighbour."""
    L = np.asarray(lengths, dtype=float)
    n = L.shape[0]
    v = np.zeros_like(L)
    a = np.zeros_like(L)
    if n < 2:
        return v, a
    h = np.diff(t)
    D = np.diff(L, axis=0) / h[:, None]
    if n >= 3:
        h0, h1 = h[:-1, None], h[1:, None]
        v[1:-1] = (h1 * D[:-1] + h0 * D[1:]) / (h0 + h1)
        a[1:-1] = 2.0 * (D[1:] - D[:-1]) / (h0 + h1)
    for k in np.flatnonzero(rest):
        v[k] = 0.0
        right = k < n - 1 and not rest[k + 1]
        left = k > 0 and not rest[k - 1]
        if right:
            a[k] = 2.0 * D[k] / h[k]
        elif left:
            a[k] = -2.0 * D[k - 1] / h[k - 1]
        else:
            a[k] = 0.0
    return v, a


def limit_ratio(velocities, accelerations, vmax, amax):
    """Per waypoint, the largest |v_i| / vmax_i or |a_i| / amax_i (1 = at a limit)."""
    rv = np.max(np.abs(velocities) / vmax, axis=1)
    ra = np.max(np.abs(accelerations) / amax, axis=1)
    return np.maximum(rv, ra)


# ----------------------------------------------------------------------------- entry points

def time_parameterize(lengths, max_cable_speed, max_cable_accel, *, dwell_s=DWELL_S,
                      zero_length_m=ZERO_LENGTH_M):
    """Time-optimal timing of the cable-space polyline through ``lengths`` (N, 6) m under
    per-winch ``max_cable_speed`` (m/s) and ``max_cable_accel`` (m/s^2) (a number or 6),
    starting and ending at rest. Returns a Timing (see the module docstring for the model,
    the reported values and the guarantees). Raises InputError naming a bad argument, or
    the speed limit when the trajectory would last over MAX_DURATION_S (or has more than
    MAX_WAYPOINTS waypoints)."""
    L = check_lengths(lengths)
    vmax = check_limit("max_cable_speed", max_cable_speed, L.shape[1])
    amax = check_limit("max_cable_accel", max_cable_accel, L.shape[1])
    dwell_s = check_finite("dwell_s", dwell_s, positive=True)
    zero_length_m = check_finite("zero_length_m", zero_length_m, positive=True)
    n = L.shape[0]
    if n == 1:
        zero = np.zeros((1, L.shape[1]))
        return Timing(t=np.zeros(1), velocities=zero, accelerations=zero.copy(),
                      path_speed=np.zeros(1), rest=np.ones(1, dtype=bool))
    geo = _geometry(L, vmax, amax, zero_length_m)
    cap = geo.cap.copy()
    repairs = 0
    for round_ in range(SHRINK_ROUNDS + n + 1):
        b, t = _schedule(geo, cap, dwell_s)
        v, a = waypoint_derivatives(L, t, geo.rest)
        ratio = limit_ratio(v, a, vmax, amax)
        bad = ratio > 1.0 + REL_TOL
        if not bad.any():
            _check_duration(t[-1], vmax, amax)
            return Timing(t=t, velocities=v, accelerations=a, path_speed=np.sqrt(b),
                          rest=geo.rest.copy(), repairs=repairs)
        if np.any(bad & (geo.rest | (b == 0))):
            break  # cannot happen (see the guarantees); refuse to return a violating timing
        repairs += 1
        if round_ < SHRINK_ROUNDS:
            cap[bad] = b[bad] * np.minimum(SHRINK_MAX, 1.0 / ratio[bad] ** 2)
        else:
            cap[bad] = 0.0
    k = int(np.argmax(ratio))
    raise RuntimeError(f"time parameterisation: waypoint {k} exceeds the winch limits by a "
                       f"factor {ratio[k]:.6g} after {repairs} repairs")


def _check_duration(duration, vmax, amax):
    """InputError naming the limits if the trajectory would last over MAX_DURATION_S."""
    if not duration <= MAX_DURATION_S:  # NaN / inf included (limits that underflow)
        raise InputError("max_cable_speed", float(np.min(vmax)),
                         f"the trajectory would last {duration:.3g} s, over the "
                         f"{MAX_DURATION_S:.0f} s limit (with max_cable_accel "
                         f"{float(np.min(amax)):.3g}): raise the limits")


def _schedule(geo, cap, dwell_s):
    """Vertex b (N,) m^2/s^2 and times t (N,) s for the given vertex caps."""
    b = _passes(geo, cap)
    acc = _segment_accel(geo, b)
    h = trapezoid_durations(b[:-1], b[1:], geo.ell, np.where(geo.moving, acc, 1.0),
                            np.where(geo.moving, geo.W, 1.0))
    h = np.where(geo.moving, h, dwell_s)
    return b, np.concatenate([[0.0], np.cumsum(h)])



def time_path(path, max_cable_speed, max_cable_accel, **options):
    """A copy of the PlannedPath ``path`` with ``t`` (s), ``velocities`` (m/s) and
    ``accelerations`` (m/s^2) from ``time_parameterize(path.lengths, ...)``; the other
    fields (lengths included) are unchanged. ``options``: dwell_s, zero_length_m."""
    timing = time_parameterize(path.lengths, max_cable_speed, max_cable_accel, **options)
    return replace(path, t=timing.t, velocities=timing.velocities,
                   accelerations=timing.accelerations)
