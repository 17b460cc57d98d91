"""The dynamic timing's per-sample geometry compiled by numba (``dynamics._terms``): at
each sample of the path, from its pose p, R and their s-derivatives (p_s, p_ss; the body
rates w, w_s of R), the load's inertial wrench coefficients A, B (w_in = A s'' + B s'^2) and
the cable lengths with their s-derivatives. The timing evaluates them at every
millisecond of a motion (some 10^4 samples), where numpy spent its time on (N, 3) and
(N, m, 3) temporaries. Plain Python here (no numba import): ``motion_terms_kernel`` is the
build ahead of time (``python -m cdh_planner.trajectory.motion_aot``, run by ``make``),
else numba's JIT with ``cache=True`` (``cdh_planner.aot``). Its arguments are C-contiguous
float64 arrays and a float, as AOT_EXPORTS says (``motion_terms`` passes them so).
Units: m, rad, kg, kg m^2, N, per m of path parameter s.
"""

import sys

import numpy as np

from .. import aot


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


# ----- compilation -------------------------------------------------------------------------
HELPERS = ("_rotate",)
_F2, _F3 = "float64[:, ::1]", "float64[:, :, ::1]"
AOT_EXPORTS = {"motion_terms_kernel": (
    f"Tuple(({_F2}, {_F2}, {_F2}, {_F2}, {_F2}))"
    f"({_F2}, {_F2}, {_F2}, {_F3}, {_F2}, {_F2}, {_F2}, {_F2}, float64[::1], float64, {_F2})")}
AOT_PREFIX = "_motion_aot_"


AOT_SOURCES = ("motion_kernel.py",)  # what the machine code is of: this file


def jit_kernels():
    """numba's JIT entry (cache=True) by name (``cdh_planner.aot``); the helper becomes a
    numba function here."""
    return {"motion_terms_kernel": aot.jit(globals(), HELPERS, inline=HELPERS)(_motion_terms)}


motion_terms_kernel = aot.entries(sys.modules[__name__])["motion_terms_kernel"]


def motion_terms(robot, p, p_s, p_ss, R, w, w_s, mass, inertia):
    """``_motion_terms`` of ``robot`` (its anchors and load point) at N samples: A, B (N, 6),
    L, L_s, L_ss (N, m), the arrays typed as the kernel reads them."""
    def f(x):
        return np.ascontiguousarray(x, dtype=np.float64)
    return motion_terms_kernel(f(p), f(p_s), f(p_ss), f(R), f(w), f(w_s), f(robot.base_anchors),
                               f(robot.platform_anchors), f(robot.load_point), float(mass),
                               f(np.asarray(inertia, dtype=float).reshape(3, 3)))
