"""The trajectory's per-sample arithmetic compiled by numba. The dynamic timing's geometry
(``dynamics._terms``): at each sample of the path, from its pose p, R and their
s-derivatives (p_s, p_ss; the body rates w, w_s of R), the load's inertial wrench
coefficients A, B (w_in = A s'' + B s'^2) and the cable lengths with their s-derivatives,
at every millisecond of a motion (some 10^4 samples), where numpy spent its time on (N, 3)
and (N, m, 3) temporaries. The executed check's stencil turns (``turns``: the rotation
between two samples, some 10^4 a check). Plain Python here (no numba import): the entries
are the build ahead of time (``python -m cdh_planner.trajectory.motion_aot``, run by
``make``), else numba's JIT with ``cache=True`` (``cdh_planner.aot``). Their arguments are
C-contiguous float64 and int64 arrays and floats, as AOT_EXPORTS says (``motion_terms``
and ``turns`` pass them so). Units: m, rad, kg, kg m^2, N, per m of path parameter s.
"""

import sys

import numpy as np

from .. import aot
from ..ports import Rotation
from ..ports.rotation import SMALL_ANGLE


def _rotate(R, x0, x1, x2, i):
    """Row i of R times the vector (x0, x1, x2)."""
    return R[i, 0] * x0 + R[i, 1] * x1 + R[i, 2] * x2


def _motion_terms(p, p_s, p_ss, R, w, w_s, a, b, g, mass, inertia):
    """Per sample n (p, p_s, p_ss, w, w_s (N, 3), R (N, 3, 3)) of a robot with base and
    platform anchors a, b (m, 3) m, load point g (3,) m, load mass (kg) and inertia (3, 3)
    kg m^2 (about the load point, platform frame): A, B (N, 6), the inertial wrench
    w_in = A s'' + B s'^2 about the origin ([m c''; c x m c'' + R (I alpha + omega x I
    omega)], c = p + R g), and the lengths L (N, m) m with L_s = u . q_s and L_ss =
    (|q_s|^2 - L_s^2) / L + u . q_ss (q = p + R b_i the platform anchor, u the unit vector
    from a_i to it): ``dynamics._terms``'s maths, numpy's einsums there before."""
    n, m = p.shape[0], a.shape[0]
    A = np.empty((n, 6))
    B = np.empty((n, 6))
    L = np.empty((n, m))
    L_s = np.empty((n, m))
    L_ss = np.empty((n, m))
    for k in range(n):
        Rk = R[k]
        w0, w1, w2 = w[k, 0], w[k, 1], w[k, 2]
        v0, v1, v2 = w_s[k, 0], w_s[k, 1], w_s[k, 2]
        # the load point's rates: c_s = p_s + R (w x g), c_ss = p_ss + R (w_s x g + w x (w x g))
        x0, x1, x2 = w1 * g[2] - w2 * g[1], w2 * g[0] - w0 * g[2], w0 * g[1] - w1 * g[0]
        y0 = v1 * g[2] - v2 * g[1] + w1 * x2 - w2 * x1
        y1 = v2 * g[0] - v0 * g[2] + w2 * x0 - w0 * x2
        y2 = v0 * g[1] - v1 * g[0] + w0 * x1 - w1 * x0
        c0 = p[k, 0] + _rotate(Rk, g[0], g[1], g[2], 0)
        c1 = p[k, 1] + _rotate(Rk, g[0], g[1], g[2], 1)
        c2 = p[k, 2] + _rotate(Rk, g[0], g[1], g[2], 2)
        f0 = mass * (p_s[k, 0] + _rotate(Rk, x0, x1, x2, 0))
        f1 = mass * (p_s[k, 1] + _rotate(Rk, x0, x1, x2, 1))
        f2 = mass * (p_s[k, 2] + _rotate(Rk, x0, x1, x2, 2))
        h0 = mass * (p_ss[k, 0] + _rotate(Rk, y0, y1, y2, 0))
        h1 = mass * (p_ss[k, 1] + _rotate(Rk, y0, y1, y2, 1))
        h2 = mass * (p_ss[k, 2] + _rotate(Rk, y0, y1, y2, 2))
        # I w, I w_s + w x I w (body frame), turned into the base frame
        i0 = inertia[0, 0] * w0 + inertia[0, 1] * w1 + inertia[0, 2] * w2
        i1 = inertia[1, 0] * w0 + inertia[1, 1] * w1 + inertia[1, 2] * w2
        i2 = inertia[2, 0] * w0 + inertia[2, 1] * w1 + inertia[2, 2] * w2
        j0 = inertia[0, 0] * v0 + inertia[0, 1] * v1 + inertia[0, 2] * v2 + w1 * i2 - w2 * i1
        j1 = inertia[1, 0] * v0 + inertia[1, 1] * v1 + inertia[1, 2] * v2 + w2 * i0 - w0 * i2
        j2 = inertia[2, 0] * v0 + inertia[2, 1] * v1 + inertia[2, 2] * v2 + w0 * i1 - w1 * i0
        A[k, 0], A[k, 1], A[k, 2] = f0, f1, f2
        A[k, 3] = c1 * f2 - c2 * f1 + _rotate(Rk, i0, i1, i2, 0)
        A[k, 4] = c2 * f0 - c0 * f2 + _rotate(Rk, i0, i1, i2, 1)
        A[k, 5] = c0 * f1 - c1 * f0 + _rotate(Rk, i0, i1, i2, 2)
        B[k, 0], B[k, 1], B[k, 2] = h0, h1, h2
        B[k, 3] = c1 * h2 - c2 * h1 + _rotate(Rk, j0, j1, j2, 0)
        B[k, 4] = c2 * h0 - c0 * h2 + _rotate(Rk, j0, j1, j2, 1)
        B[k, 5] = c0 * h1 - c1 * h0 + _rotate(Rk, j0, j1, j2, 2)
        for i in range(m):
            b0, b1, b2 = b[i, 0], b[i, 1], b[i, 2]
            d0 = p[k, 0] + _rotate(Rk, b0, b1, b2, 0) - a[i, 0]
            d1 = p[k, 1] + _rotate(Rk, b0, b1, b2, 1) - a[i, 1]
            d2 = p[k, 2] + _rotate(Rk, b0, b1, b2, 2) - a[i, 2]
            length = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            u0, u1, u2 = d0 / length, d1 / length, d2 / length
            # q_s = p_s + R (w x b), q_ss = p_ss + R (w_s x b + w x (w x b))
            x0, x1, x2 = w1 * b2 - w2 * b1, w2 * b0 - w0 * b2, w0 * b1 - w1 * b0
            y0 = v1 * b2 - v2 * b1 + w1 * x2 - w2 * x1
            y1 = v2 * b0 - v0 * b2 + w2 * x0 - w0 * x2
            y2 = v0 * b1 - v1 * b0 + w0 * x1 - w1 * x0
            s0 = p_s[k, 0] + _rotate(Rk, x0, x1, x2, 0)
            s1 = p_s[k, 1] + _rotate(Rk, x0, x1, x2, 1)
            s2 = p_s[k, 2] + _rotate(Rk, x0, x1, x2, 2)
            t0 = p_ss[k, 0] + _rotate(Rk, y0, y1, y2, 0)
            t1 = p_ss[k, 1] + _rotate(Rk, y0, y1, y2, 1)
            t2 = p_ss[k, 2] + _rotate(Rk, y0, y1, y2, 2)
            rate = u0 * s0 + u1 * s1 + u2 * s2
            L[k, i] = length
            L_s[k, i] = rate
            L_ss[k, i] = (s0 * s0 + s1 * s1 + s2 * s2 - rate * rate) / length \
                + u0 * t0 + u1 * t1 + u2 * t2
    return A, B, L, L_s, L_ss


def _turns(R, a, b, small):
    """The rotation vectors (K, 3) rad of R[a_k]^T R[b_k] (R (N, 3, 3), a, b (K,)): the body
    frame turn from rotation a_k to b_k, as ``ports.Rotation.from_matrix(...).as_rotvec()``
    computes it (scipy's quaternion of the largest of the diagonal and the trace,
    normalised, w >= 0, angle 2 atan2(|xyz|, w), its series below ``small`` rad), and
    whether that needs the port itself (K,): the product not orthogonal to 1e-12 (the
    port projects it first) or not right-handed (the port refuses it)."""
    n = a.shape[0]
    out = np.empty((n, 3))
    other = np.zeros(n, dtype=np.bool_)
    M = np.empty((3, 3))
    q = np.empty(4)
    for k in range(n):
        A, B = R[a[k]], R[b[k]]
        for i in range(3):
            for j in range(3):
                M[i, j] = A[0, i] * B[0, j] + A[1, i] * B[1, j] + A[2, i] * B[2, j]
        det = (M[0, 0] * (M[1, 1] * M[2, 2] - M[1, 2] * M[2, 1])
               - M[0, 1] * (M[1, 0] * M[2, 2] - M[1, 2] * M[2, 0])
               + M[0, 2] * (M[1, 0] * M[2, 1] - M[1, 1] * M[2, 0]))
        for i in range(3):
            for j in range(3):
                gram = M[i, 0] * M[j, 0] + M[i, 1] * M[j, 1] + M[i, 2] * M[j, 2]
                eye = 1.0 if i == j else 0.0
                if not abs(gram - eye) <= 1e-12 + 1e-5 * eye:
                    other[k] = True
        if not det > 0.0:
            other[k] = True
        if other[k]:
            continue
        trace = M[0, 0] + M[1, 1] + M[2, 2]
        choice, big = 0, M[0, 0]
        if M[1, 1] > big:
            choice, big = 1, M[1, 1]
        if M[2, 2] > big:
            choice, big = 2, M[2, 2]
        if trace > big:
            choice = 3
        if choice == 3:
            q[0] = M[2, 1] - M[1, 2]
            q[1] = M[0, 2] - M[2, 0]
            q[2] = M[1, 0] - M[0, 1]
            q[3] = 1 + trace
        else:
            i = choice
            j, l = (i + 1) % 3, (i + 2) % 3
            q[i] = 1 - trace + 2 * M[i, i]
            q[j] = M[j, i] + M[i, j]
            q[l] = M[l, i] + M[i, l]
            q[3] = M[l, j] - M[j, l]
        norm = np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
        for i in range(4):
            q[i] = q[i] / norm
        flip = q[3] < 0 or (q[3] == 0 and (q[0] < 0 or (q[0] == 0 and (
            q[1] < 0 or (q[1] == 0 and q[2] < 0)))))
        if flip:
            for i in range(4):
                q[i] = -q[i]
        angle = 2 * np.arctan2(np.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2]), q[3])
        if angle <= small:
            a2 = angle * angle
            scale = 2 + a2 / 12 + 7 * a2 * a2 / 2880
        else:
            scale = angle / np.sin(angle / 2)
        for i in range(3):
            out[k, i] = scale * q[i]
    return out, other


# ----- compilation -------------------------------------------------------------------------
HELPERS = ("_rotate",)
_F2, _F3 = "float64[:, ::1]", "float64[:, :, ::1]"
AOT_EXPORTS = {"motion_terms_kernel": (
    f"Tuple(({_F2}, {_F2}, {_F2}, {_F2}, {_F2}))"
    f"({_F2}, {_F2}, {_F2}, {_F3}, {_F2}, {_F2}, {_F2}, {_F2}, float64[::1], float64, {_F2})"),
    "turns_kernel": f"Tuple(({_F2}, boolean[::1]))({_F3}, int64[::1], int64[::1], float64)"}
AOT_PREFIX = "_motion_aot_"


AOT_SOURCES = ("motion_kernel.py",)  # what the machine code is of: this file


def jit_kernels():
    """numba's JIT entry (cache=True) by name (``cdh_planner.aot``); the helper becomes a
    numba function here."""
    njit = aot.jit(globals(), HELPERS, inline=HELPERS)
    return {"motion_terms_kernel": njit(_motion_terms), "turns_kernel": njit(_turns)}


_entries = aot.entries(sys.modules[__name__])
motion_terms_kernel, turns_kernel = _entries["motion_terms_kernel"], _entries["turns_kernel"]


def motion_terms(robot, p, p_s, p_ss, R, w, w_s, mass, inertia):
    """``_motion_terms`` of ``robot`` (its anchors and load point) at N samples: A, B (N, 6),
    L, L_s, L_ss (N, m), the arrays typed as the kernel reads them."""
    def f(x):
        return np.ascontiguousarray(x, dtype=np.float64)
    return motion_terms_kernel(f(p), f(p_s), f(p_ss), f(R), f(w), f(w_s), f(robot.base_anchors),
                               f(robot.platform_anchors), f(robot.load_point), float(mass),
                               f(np.asarray(inertia, dtype=float).reshape(3, 3)))


def turns(R, a, b):
    """Rotation vectors (K, 3) rad of R[a]^T R[b] (R (N, 3, 3), indices a, b (K,)): the
    compiled ``_turns``, the port's own ``Rotation`` where the product needs it (not
    orthogonal to 1e-12: projected; left-handed: refused)."""
    R = np.ascontiguousarray(R, dtype=np.float64)
    a, b = np.ascontiguousarray(a, dtype=np.int64), np.ascontiguousarray(b, dtype=np.int64)
    out, other = turns_kernel(R, a, b, SMALL_ANGLE)
    if other.any():
        out[other] = Rotation.from_matrix(np.swapaxes(R[a[other]], 1, 2) @ R[b[other]]).as_rotvec()
    return out
