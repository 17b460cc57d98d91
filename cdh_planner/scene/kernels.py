"""The compiled kernel of the collision checks (collision.py): for a batch of poses, the
lower bounds of every cable-obstacle and platform-obstacle distance (bounding spheres),
the exact cable-cable, cable-platform (primitive platform) and cable-obstacle (primitive
obstacle, where its bound does not rule it out) distances and the cables' capsule frames
for coal. Plain Python functions compiled by numba (no numba import here):
ahead of time by ``python -m cdh_planner.scene.aot`` (``make``), else by the JIT
(``cdh_planner.aot``: one way for every kernel of the package).
"""

import math
import sys

import numpy as np

from .. import aot
from ..model.shape_forms import BOX_FORM, CAPSULE_FORM, COAL_FORM, SPHERE_FORM

EPS = 1e-300
GOLDEN_STEPS = 40   # golden-section steps on a cable: 0.618^40 = 4e-9 of its length (~1 nm)


def _batch(P, Rs, static, pairs, lb, frames, frames_p, cc, cp, least):
    """``_kernel`` and ``_least`` for each pose n (P[n] (3,) m, Rs[n] (3, 3)): the
    buffers carry a leading pose axis (lb (N, m + 1, K + 1), frames (N, m, 16), frames_p
    (N, m, 13), cc (N, pairs), cp (N, m), least (N, 3))."""
    for n in range(P.shape[0]):
        _kernel(P[n], Rs[n], static, pairs, lb[n], frames[n], frames_p[n], cc[n], cp[n])
        _least(cc[n], cp[n], least[n])
        _obstacles(static, pairs.shape[0], lb[n], frames[n], least[n])


def _obstacles(static, n_pairs, lb, frames, least):
    """Cable against primitive obstacle (sphere, box, cylinder, capsule; form codes in
    static, after the bounding radii), exactly (``_segment_sdf``: the signed distance of
    the cable's axis, less its radius) for each pair whose lower bound lb[i, k] is below the
    least distance so far, which it lowers (least: value, 2, i (K + 1) + k); lb[i, k] of
    every primitive pair is then inf (nothing left for coal: an exact distance not below
    the least found is never the least). A mesh (COAL_FORM) keeps its bound for coal."""
    m, K = lb.shape[0] - 1, lb.shape[1] - 1
    for i in range(m):
        a, b = _v(static, 3 * i), _v(frames[i], 13)
        for k in range(K):
            if static[6 * m + 7 * K + 13 * k] == COAL_FORM:
                continue
            if lb[i, k] < least[0]:
                d = _cable_obstacle(static, m, K, n_pairs, k, a, b)
                if d < least[0]:
                    least[0], least[1], least[2] = d, 2.0, i * (K + 1) + k
            lb[i, k] = np.inf


def _cable_obstacle(static, m, K, n_pairs, k, a, b):
    """Signed distance (m) of the cable a..b (its axis; less the cable radius) to the
    primitive obstacle k (its form at 6 m + 7 K + 13 k of static: code, three numbers,
    rotation row-major; its centre at 6 m + 3 k)."""
    f = 6 * m + 7 * K + 13 * k
    c, M = _v(static, 6 * m + 3 * k), static[f + 4:f + 13]
    r = static[6 * m + 20 * K + 2 * n_pairs]
    return _segment_sdf(_local(M, c, a), _local(M, c, b), static[f:f + 4]) - r


def _cable_obstacle_batch(P, Rs, static, pairs, out):
    """out[n, i, k] = ``_cable_obstacle`` of cable i and obstacle k at pose n (P[n] (3,)
    m, Rs[n] (3, 3)), every pair unpruned; nan for a mesh (COAL_FORM: coal's)."""
    m, K = out.shape[1], out.shape[2]
    for n in range(P.shape[0]):
        for i in range(m):
            a = _v(static, 3 * i)
            b = _add(_rot(Rs[n], _v(static, 3 * m + 3 * i)), _v(P[n], 0))
            for k in range(K):
                if static[6 * m + 7 * K + 13 * k] == COAL_FORM:
                    out[n, i, k] = np.nan
                else:
                    out[n, i, k] = _cable_obstacle(static, m, K, pairs.shape[0], k, a, b)


def _kernel(p, R, static, pairs, lb, frames, frames_p, cc, cp):
    """For pose (p, R): lb[i, k] = dist(segment a_i b_i, core_k) - rho_k - r, a lower
    bound of cable i's distance to obstacle k (its bounding capsule: the core segment
    c_k -+ h_k, a point for h_k = 0, and radius rho_k; exact for a capsule), and lb[m, k]
    the platform's (dist(centre, core_k) - rho_k - rho_platform; inf without a platform);
    lb[i, K] cable i's (cut by rho at its platform anchor) to the platform's own shape
    (inf without one, or if nothing is left; lb[m, K] inf); frames[i]: cable i's capsule
    frame (rotation taking z to the cable, row-major; centre; half length), frames_p[i]
    that of its cut part; cc[n]: the distance of the capsules of cable pair n (shared ends
    cut by rho; inf if nothing is left); cp[i]: cable i's (cut) distance to a sphere, box or
    cylinder platform, exact here (lb[i, K] is then inf: no coal call), inf otherwise.
    Scalar code on 3-tuples: no allocation in the loops."""
    m, K, P = lb.shape[0] - 1, lb.shape[1] - 1, pairs.shape[0]
    oB, oC = 3 * m, 6 * m
    oH = oC + 3 * K   # the obstacles' bounding capsules: half axes, then radii
    oR = oH + 3 * K
    oT = oR + K + 13 * K   # after the obstacles' forms (``_obstacles``)
    o = oT + 2 * P
    r, rho = static[o], static[o + 1]
    pc = _add(_rot(R, _v(static, o + 2)), _v(p, 0))
    prad = static[o + 5]
    form = static[o + 6:o + 19]     # kind code, dimensions, rotation (platform frame)
    M = _axes(R, form)   # the platform shape's axes in the base frame
    for i in range(m):
        a = _v(static, 3 * i)
        b = _add(_rot(R, _v(static, oB + 3 * i)), _v(p, 0))
        frames[i, 13], frames[i, 14], frames[i, 15] = b  # the platform anchor, for the pairs
        _frame(a, b, frames[i])
        for k in range(K):
            lb[i, k] = _core_distance(_v(static, oC + 3 * k), _v(static, oH + 3 * k), a, b) \
                - static[oR + k] - r
        lb[i, K], cp[i] = _own(a, b, pc, prad, M, form, r, rho, frames_p[i])
    lb[m, K] = np.inf
    for k in range(K):
        lb[m, k] = _point_core(_v(static, oC + 3 * k), _v(static, oH + 3 * k), pc) \
            - static[oR + k] - prad if prad >= 0.0 else np.inf
    for n in range(P):
        i, j = pairs[n, 0], pairs[n, 1]
        cut_a, cut_b = static[oT + 2 * n], static[oT + 2 * n + 1]
        ok1, p0, p1 = _cut(_v(static, 3 * i), _v(frames[i], 13), cut_a, cut_b, rho)
        ok2, q0, q1 = _cut(_v(static, 3 * j), _v(frames[j], 13), cut_a, cut_b, rho)
        cc[n] = _segment_segment(p0, p1, q0, q1) - 2.0 * r if ok1 and ok2 else np.inf


def _core_distance(c, h, a, b):
    """Distance of the segment a..b to the core segment c - h .. c + h (the point c if
    h = 0: a bounding sphere's centre)."""
    if h[0] == 0.0 and h[1] == 0.0 and h[2] == 0.0:
        return _point_segment(c, a, b)
    return _segment_segment(a, b, _sub(c, h), _add(c, h))


def _point_core(c, h, x):
    """Distance of the point x to the core segment c - h .. c + h (a point if h = 0)."""
    if h[0] == 0.0 and h[1] == 0.0 and h[2] == 0.0:
        return _norm(_sub(c, x))
    return _point_segment(x, _sub(c, h), _add(c, h))


def _least(cc, cp, out):
    """out = (least of cc and cp, 0 if it is cc's / 1 if cp's / -1 if both are empty or
    inf, its index); ``_obstacles`` may lower it after."""
    out[0], out[1], out[2] = np.inf, -1.0, -1.0
    for n in range(cc.shape[0]):
        if cc[n] < out[0]:
            out[0], out[1], out[2] = cc[n], 0.0, n
    for i in range(cp.shape[0]):
        if cp[i] < out[0]:
            out[0], out[1], out[2] = cp[i], 1.0, i


def _own(a, b, pc, prad, M, form, r, rho, frame):
    """(lower bound, exact distance) of the cable a..b, cut by rho at its platform anchor
    b, to the platform's own shape: exact for a primitive (the bound inf), else the bound
    from its bounding sphere and the cut capsule's ``frame`` for coal; (inf, inf) without a
    platform or a cut cable."""
    if prad < 0.0:
        return np.inf, np.inf
    ok, q0, q1 = _cut(a, b, 0.0, 1.0, rho)
    if not ok:
        return np.inf, np.inf
    if form[0] != COAL_FORM:
        return np.inf, _segment_sdf(_local(M, pc, q0), _local(M, pc, q1), form) - r
    _frame(q0, q1, frame)
    return _point_segment(pc, q0, q1) - prad - r, np.inf


def _local(M, c, x):
    """x (base frame) in the frame of axes M (columns; row-major 9-tuple) and origin c."""
    d = _sub(x, c)
    return (M[0] * d[0] + M[3] * d[1] + M[6] * d[2],
            M[1] * d[0] + M[4] * d[1] + M[7] * d[2],
            M[2] * d[0] + M[5] * d[1] + M[8] * d[2])


def _axes(R, form):
    """R times the platform shape's rotation (form[4:13], row-major): its axes (columns)
    in the base frame, a row-major 9-tuple (scalar code: no BLAS, which pycc lacks)."""
    F = form[4:13]
    return (R[0, 0] * F[0] + R[0, 1] * F[3] + R[0, 2] * F[6],
            R[0, 0] * F[1] + R[0, 1] * F[4] + R[0, 2] * F[7],
            R[0, 0] * F[2] + R[0, 1] * F[5] + R[0, 2] * F[8],
            R[1, 0] * F[0] + R[1, 1] * F[3] + R[1, 2] * F[6],
            R[1, 0] * F[1] + R[1, 1] * F[4] + R[1, 2] * F[7],
            R[1, 0] * F[2] + R[1, 1] * F[5] + R[1, 2] * F[8],
            R[2, 0] * F[0] + R[2, 1] * F[3] + R[2, 2] * F[6],
            R[2, 0] * F[1] + R[2, 1] * F[4] + R[2, 2] * F[7],
            R[2, 0] * F[2] + R[2, 1] * F[5] + R[2, 2] * F[8])


def _sdf(x, form):
    """Signed distance (m) of the point x (shape frame) to a sphere (SPHERE_FORM: radius),
    box (BOX_FORM: half edges) or cylinder (CYLINDER_FORM: radius, half height; axis z)."""
    if form[0] == SPHERE_FORM:
        return _norm(x) - form[1]
    if form[0] == BOX_FORM:
        q = (abs(x[0]) - form[1], abs(x[1]) - form[2], abs(x[2]) - form[3])
    else:
        q = (math.hypot(x[0], x[1]) - form[1], abs(x[2]) - form[2], -np.inf)
    out = (max(q[0], 0.0), max(q[1], 0.0), max(q[2], 0.0))
    return _norm(out) + min(max(q[0], max(q[1], q[2])), 0.0)


def _segment_sdf(x0, x1, form):
    """Least signed distance of the segment x0..x1 (shape frame) to the shape: the signed
    distance to a convex set is convex, so golden-section search on the segment finds its
    minimum (GOLDEN_STEPS steps: within 4e-9 of the segment's length); a sphere's and a
    capsule's (CAPSULE_FORM: radius, half length; axis z) in closed form."""
    if form[0] == SPHERE_FORM:
        return _point_segment((0.0, 0.0, 0.0), x0, x1) - form[1]
    if form[0] == CAPSULE_FORM:
        return _segment_segment(x0, x1, (0.0, 0.0, -form[2]), (0.0, 0.0, form[2])) - form[1]
    d = _sub(x1, x0)
    lo, hi, g = 0.0, 1.0, 0.6180339887498949
    c, e = hi - g, g
    fc = _sdf(_add(x0, _scale(c, d)), form)
    fe = _sdf(_add(x0, _scale(e, d)), form)
    for _ in range(GOLDEN_STEPS):
        if fc < fe:
            hi, e, fe = e, c, fc
            c = hi - g * (hi - lo)
            fc = _sdf(_add(x0, _scale(c, d)), form)
        else:
            lo, c, fc = c, e, fe
            e = lo + g * (hi - lo)
            fe = _sdf(_add(x0, _scale(e, d)), form)
    return min(fc, fe, _sdf(x0, form), _sdf(x1, form))


def _v(x, o):
    return (x[o], x[o + 1], x[o + 2])


def _add(a, b):
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def _sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def _scale(s, a):
    return (s * a[0], s * a[1], s * a[2])


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _norm(a):
    return math.sqrt(_dot(a, a))


def _rot(R, x):
    return (R[0, 0] * x[0] + R[0, 1] * x[1] + R[0, 2] * x[2],
            R[1, 0] * x[0] + R[1, 1] * x[1] + R[1, 2] * x[2],
            R[2, 0] * x[0] + R[2, 1] * x[1] + R[2, 2] * x[2])


def _frame(a, b, out):
    """out[:13] = rotation taking z to the unit vector u along a -> b (row-major:
    Rodrigues about z x u, R = I + K + K^2 / (1 + u_z)), the midpoint, half the length."""
    d = _sub(b, a)
    length = _norm(d)
    x, y, z = (d[0] / length, d[1] / length, d[2] / length) if length > 0.0 else (0.0, 0.0, 1.0)
    if z < -1.0 + 1e-12:
        rows = (1.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 0.0, -1.0)
    else:
        h = 1.0 / (1.0 + z)
        rows = (1.0 - h * x * x, -h * x * y, x,
                -h * x * y, 1.0 - h * y * y, y,
                -x, -y, 1.0 - h * (x * x + y * y))
    for c in range(9):
        out[c] = rows[c]
    for c in range(3):
        out[9 + c] = 0.5 * (a[c] + b[c])
    out[12] = 0.5 * length


def _cut(a, b, cut_a, cut_b, rho):
    """(ok, a', b'): the segment a..b with rho removed at the ends flagged; ok False if
    nothing is left."""
    d = _sub(b, a)
    length = _norm(d)
    if (cut_a > 0.0 or cut_b > 0.0) and length == 0.0:
        return False, a, b
    s0 = rho / length if cut_a > 0.0 else 0.0
    s1 = 1.0 - (rho / length if cut_b > 0.0 else 0.0)
    if (cut_a > 0.0 or cut_b > 0.0) and s1 <= s0:
        return False, a, b
    return True, _add(a, _scale(s0, d)), _add(a, _scale(s1, d))


def _point_segment(c, a, b):
    d, w = _sub(b, a), _sub(c, a)
    dd = _dot(d, d)
    t = 0.0 if dd <= 0.0 else min(1.0, max(0.0, _dot(w, d) / dd))
    return _norm(_sub(w, _scale(t, d)))


def _segment_segment(p0, p1, q0, q1):
    """Least distance between segments p0..p1 and q0..q1 (Ericson, Real-Time Collision
    Detection, 5.1.9)."""
    d1, d2, r = _sub(p1, p0), _sub(q1, q0), _sub(p0, q0)
    a, e, f = _dot(d1, d1), _dot(d2, d2), _dot(d2, r)
    if a <= EPS and e <= EPS:
        return _norm(r)
    if a <= EPS:
        s, t = 0.0, min(1.0, max(0.0, f / e))
    else:
        c = _dot(d1, r)
        if e <= EPS:
            s, t = min(1.0, max(0.0, -c / a)), 0.0
        else:
            b = _dot(d1, d2)
            denom = a * e - b * b
            s = min(1.0, max(0.0, (b * f - c * e) / denom)) if denom > 1e-14 * a * e else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                s, t = min(1.0, max(0.0, -c / a)), 0.0
            elif t > 1.0:
                s, t = min(1.0, max(0.0, (b - c) / a)), 1.0
    return _norm(_sub(_add(r, _scale(s, d1)), _scale(t, d2)))


# ----- compilation -------------------------------------------------------------------------
HELPERS = ("_kernel", "_obstacles", "_cable_obstacle", "_core_distance", "_point_core", "_least", "_own", "_local", "_axes", "_sdf", "_segment_sdf", "_v", "_add",
           "_sub", "_scale", "_dot", "_norm", "_rot", "_frame", "_cut", "_point_segment",
           "_segment_segment")
INLINE = ("_v", "_add", "_sub", "_scale", "_dot", "_norm", "_rot")
AOT_EXPORTS = {"collision_batch": (
    "void(float64[:, ::1], float64[:, :, ::1], float64[::1], int64[:, ::1], "
    "float64[:, :, ::1], float64[:, :, ::1], float64[:, :, ::1], float64[:, ::1], "
    "float64[:, ::1], float64[:, ::1])"),
    "cable_obstacle_batch": (
    "void(float64[:, ::1], float64[:, :, ::1], float64[::1], int64[:, ::1], float64[:, :, ::1])")}
AOT_PREFIX = "_kernels_aot_"


AOT_SOURCES = ("kernels.py", "../model/shape_forms.py")  # what the machine code is of: this file and the shape forms it reads


def aot_kernel():
    """The ahead-of-time compiled kernel, or None if it was not built for this source."""
    built = aot.load(sys.modules[__name__])
    return built and built["collision_batch"]


def jit_kernel():
    """numba's JIT batch kernel (cache=True); the helpers become numba functions here."""
    return aot.jit(globals(), HELPERS, INLINE)(_batch)


def jit_kernels():
    """The JIT entries by name (``cdh_planner.aot``): ``jit_kernel`` and the unpruned
    cable-obstacle distances."""
    return {"collision_batch": jit_kernel(),
            "cable_obstacle_batch": aot.jit(globals(), HELPERS, INLINE)(_cable_obstacle_batch)}


_ENTRIES = aot.entries(sys.modules[__name__])
collision_batch, cable_obstacle_batch = (_ENTRIES[k] for k in AOT_EXPORTS)
