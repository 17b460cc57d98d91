"""The elastic equilibrium's Newton compiled by numba, one pose at a time (``elastic``'s
maths: ``wrench_balance`` is the residual and Jacobian written once in numpy, this kernel
the same algebra per pose, checked against it to 1e-9 in test_elastic_kernel.py). The
executed check solves it at every sample of a trajectory (some 10^5 poses for a slowed
eight-cable plan), where numpy's batched version spent most of its time allocating
(M, m, 6) temporaries. Plain ``njit(cache=True)``: compiled at the first call of a process
whose cache is cold, then loaded from cdh_planner/model/__pycache__. Units: m, N, N m.
"""

import numpy as np
from numba import njit


@njit(cache=True)
def _skew_into(v, out, sign):
    """out += sign [v]x (3x3)."""
    out[0, 1] -= sign * v[2]
    out[0, 2] += sign * v[1]
    out[1, 0] += sign * v[2]
    out[1, 2] -= sign * v[0]
    out[2, 0] -= sign * v[1]
    out[2, 1] += sign * v[0]


@njit(cache=True)
def _cross(a, b, out):
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@njit(cache=True)
def _balance(a, b, g, EA, L0, p, R, force, moment, arm, bilateral, res, jac, t, want_jac):
    """``elastic.wrench_balance`` at one pose into res (6,), t (m,) and, when ``want_jac``,
    jac (6, 6): the same residual, tensions and Jacobian (same order of terms)."""
    m = a.shape[0]
    r = np.empty(3)
    u = np.empty(3)
    au = np.empty(3)
    ru = np.empty(3)
    dL = np.empty(6)
    c = np.empty(3)
    cxa = np.empty(3)
    sum_tl = 0.0
    sum_wr = np.zeros(3)
    sum_tla = np.zeros(3)
    wra = np.zeros((3, 3))   # sum (t_i / L_i) r_i a_i^T
    wr_dot_a = 0.0
    for j in range(6):
        res[j] = 0.0
    if want_jac:
        for i in range(6):
            for j in range(6):
                jac[i, j] = 0.0
    for i in range(m):
        for k in range(3):
            r[k] = R[k, 0] * b[i, 0] + R[k, 1] * b[i, 1] + R[k, 2] * b[i, 2]
        d0 = p[0] + r[0] - a[i, 0]
        d1 = p[1] + r[1] - a[i, 1]
        d2 = p[2] + r[2] - a[i, 2]
        L = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        u[0], u[1], u[2] = d0 / L, d1 / L, d2 / L
        k_i = EA[i] / L0[i]
        ti = k_i * (L - L0[i])
        if not bilateral:
            if ti < 0.0:
                ti = 0.0
            if not ti > 0.0:
                k_i = 0.0
        t[i] = ti
        _cross(a[i], u, au)
        for k in range(3):
            res[k] += ti * u[k]
            res[3 + k] += ti * au[k]
        if want_jac:
            _cross(r, u, ru)
            for k in range(3):
                dL[k] = u[k]
                dL[3 + k] = ru[k]
            tl = ti / L
            for k in range(3):
                for j in range(6):
                    cu = (k_i - tl) * dL[j]
                    jac[k, j] += u[k] * cu
                    jac[3 + k, j] += au[k] * cu
            sum_tl += tl
            for k in range(3):
                sum_wr[k] += tl * r[k]
                sum_tla[k] += tl * a[i, k]
                for j in range(3):
                    wra[k, j] += tl * r[k] * a[i, j]
                wr_dot_a += tl * r[k] * a[i, k]
    for k in range(3):
        c[k] = p[k] + R[k, 0] * g[0] + R[k, 1] * g[1] + R[k, 2] * g[2]
    _cross(c, arm, cxa)
    for k in range(3):
        res[k] -= force[k]
        res[3 + k] -= moment[k] + cxa[k]
    if not want_jac:
        return
    top_r = np.zeros((3, 3))
    _skew_into(sum_wr, top_r, 1.0)
    bot_l = np.zeros((3, 3))
    _skew_into(sum_tla, bot_l, 1.0)
    arm_x = np.zeros((3, 3))
    _skew_into(arm, arm_x, 1.0)
    cp = np.empty(3)
    for k in range(3):
        cp[k] = c[k] - p[k]
    cp_x = np.zeros((3, 3))
    _skew_into(cp, cp_x, 1.0)
    for k in range(3):
        jac[k, k] += sum_tl
        for j in range(3):
            jac[k, 3 + j] -= top_r[k, j]
            jac[3 + k, j] += bot_l[k, j]
            jac[3 + k, 3 + j] -= wra[k, j] - (wr_dot_a if k == j else 0.0)
            jac[3 + k, j] += arm_x[k, j]
            ax_cp = arm_x[k, 0] * cp_x[0, j] + arm_x[k, 1] * cp_x[1, j] + arm_x[k, 2] * cp_x[2, j]
            jac[3 + k, 3 + j] -= ax_cp


@njit(cache=True)
def _rotvec_matrix(v, out):
    """exp([v]x) (3x3) into out, Rodrigues' formula (a series near 0)."""
    th2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2]
    if th2 < 1e-16:
        s, c = 1.0 - th2 / 6.0, 0.5 - th2 / 24.0
    else:
        th = np.sqrt(th2)
        s, c = np.sin(th) / th, (1.0 - np.cos(th)) / th2
    x, y, z = v[0], v[1], v[2]
    out[0, 0] = 1.0 - c * (y * y + z * z)
    out[1, 1] = 1.0 - c * (x * x + z * z)
    out[2, 2] = 1.0 - c * (x * x + y * y)
    out[0, 1] = -s * z + c * x * y
    out[1, 0] = s * z + c * x * y
    out[0, 2] = s * y + c * x * z
    out[2, 0] = -s * y + c * x * z
    out[1, 2] = -s * x + c * y * z
    out[2, 1] = s * x + c * y * z


@njit(cache=True)
def _max_abs(v):
    best = 0.0
    for x in v:
        if abs(x) > best:
            best = abs(x)
    return best


@njit(cache=True)
def _newton_pose(a, b, g, EA, L0, p, R, force, moment, arm, bilateral, tol, iterations,
                 halvings):
    """``elastic._newton`` at one pose, in place on p (3,) and R (3, 3): converged?"""
    m = a.shape[0]
    res = np.empty(6)
    jac = np.empty((6, 6))
    t = np.empty(m)
    after = np.empty(6)
    p_try = np.empty(3)
    R_try = np.empty((3, 3))
    E = np.empty((3, 3))
    rv = np.empty(3)
    _balance(a, b, g, EA, L0, p, R, force, moment, arm, bilateral, res, jac, t, False)
    for _ in range(iterations):
        before = _max_abs(res)
        if before <= tol:
            return True
        _balance(a, b, g, EA, L0, p, R, force, moment, arm, bilateral, after, jac, t, True)
        try:
            step = -np.linalg.solve(jac, res)
        except Exception:  # exactly singular: not converged
            return False
        for x in step:
            if not np.isfinite(x):
                return False
        scale = 1.0
        moved = False
        for _h in range(halvings):
            for k in range(3):
                p_try[k] = p[k] + scale * step[k]
                rv[k] = scale * step[3 + k]
            _rotvec_matrix(rv, E)
            for i in range(3):
                for j in range(3):
                    R_try[i, j] = E[i, 0] * R[0, j] + E[i, 1] * R[1, j] + E[i, 2] * R[2, j]
            _balance(a, b, g, EA, L0, p_try, R_try, force, moment, arm, bilateral, after, jac,
                     t, False)
            if _max_abs(after) < before:
                p[:] = p_try
                R[:, :] = R_try
                res[:] = after
                moved = True
                break
            scale *= 0.5
        if not moved:  # no step lowers the residual: stuck
            return False
    return False  # as elastic's numpy Newton: convergence is seen before a step, not after the last


@njit(cache=True)
def equilibrium_kernel(a, b, g, EA, L0, p, R, force, moment, arm, tol, iterations, halvings):
    """``elastic.equilibrium_poses`` for poses p (M, 3), R (M, 3, 3) (copied), cables of
    unstretched lengths L0 (M, m), anchors a, b (m, 3), load point g (3,), stiffness EA (m,),
    load rows force, moment, arm (M, 3), convergence tolerances tol (M,) N: (p, R, tensions
    (M, m), largest residual (M,), ok (M,))."""
    n, m = p.shape[0], a.shape[0]
    p, R = p.copy(), R.copy()
    tensions = np.empty((n, m))
    residual = np.empty(n)
    ok = np.zeros(n, dtype=np.bool_)
    res = np.empty(6)
    jac = np.empty((6, 6))
    for q in range(n):
        _newton_pose(a, b, g, EA, L0[q], p[q], R[q], force[q], moment[q], arm[q], True, tol[q],
                     iterations, halvings)
        ok[q] = _newton_pose(a, b, g, EA, L0[q], p[q], R[q], force[q], moment[q], arm[q], False,
                             tol[q], iterations, halvings)
        _balance(a, b, g, EA, L0[q], p[q], R[q], force[q], moment[q], arm[q], False, res, jac,
                 tensions[q], False)
        residual[q] = _max_abs(res)
    return p, R, tensions, residual, ok
