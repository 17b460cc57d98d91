"""The elastic equilibrium's Newton compiled by numba, one pose at a time (``elastic``'s
maths: ``wrench_balance`` is the residual and Jacobian written once in numpy, this kernel
the same algebra per pose, checked against it to 1e-9 in test_elastic_kernel.py). The
executed check solves it at every sample of a trajectory (some 10^5 poses for a slowed
eight-cable plan), where numpy's batched version spent most of its time allocating
(M, m, 6) temporaries. ``soft_kernel``: the same Jacobian as the platform's stiffness K
(``elastic.platform_stiffness``) and whether its least eigenvalue is below a bound, for
the stiff nominal's check of every pose (``elastic.soft_poses``). Plain Python here (no
numba import): ``equilibrium_kernel`` and ``soft_kernel`` are the build ahead of time
(``python -m cdh_planner.model.elastic_aot``, run by ``make``), else numba's JIT with
``cache=True`` (``cdh_planner.aot``). Their arguments are C-contiguous arrays and scalars
as AOT_EXPORTS says, unchecked. Units: m, N, N m.
"""

import sys

import numpy as np

from .. import aot


def _balance(a, b, g, EA, L0, p, R, force, moment, arm, bilateral, res, jac, t, want_jac):
    """``elastic.wrench_balance`` at one pose into res (6,), t (m,) and, when ``want_jac``,
    jac (6, 6): the same residual, tensions and Jacobian (scalars only: no allocation)."""
    m = a.shape[0]
    for j in range(6):
        res[j] = 0.0
    if want_jac:
        for i in range(6):
            for j in range(6):
                jac[i, j] = 0.0
    sum_tl = 0.0
    s0 = s1 = s2 = 0.0                      # sum (t_i / L_i) r_i
    a0 = a1 = a2 = 0.0                      # sum (t_i / L_i) a_i
    wr_dot_a = 0.0
    w00 = w01 = w02 = w10 = w11 = w12 = w20 = w21 = w22 = 0.0  # sum (t_i / L_i) r_i a_i^T
    for i in range(m):
        r0 = R[0, 0] * b[i, 0] + R[0, 1] * b[i, 1] + R[0, 2] * b[i, 2]
        r1 = R[1, 0] * b[i, 0] + R[1, 1] * b[i, 1] + R[1, 2] * b[i, 2]
        r2 = R[2, 0] * b[i, 0] + R[2, 1] * b[i, 1] + R[2, 2] * b[i, 2]
        d0 = p[0] + r0 - a[i, 0]
        d1 = p[1] + r1 - a[i, 1]
        d2 = p[2] + r2 - a[i, 2]
        L = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        u0, u1, u2 = d0 / L, d1 / L, d2 / L
        k_i = EA[i] / L0[i]
        ti = k_i * (L - L0[i])
        if not bilateral:
            if ti < 0.0:
                ti = 0.0
            if not ti > 0.0:
                k_i = 0.0
        t[i] = ti
        ai0, ai1, ai2 = a[i, 0], a[i, 1], a[i, 2]
        au0 = ai1 * u2 - ai2 * u1
        au1 = ai2 * u0 - ai0 * u2
        au2 = ai0 * u1 - ai1 * u0
        res[0] += ti * u0
        res[1] += ti * u1
        res[2] += ti * u2
        res[3] += ti * au0
        res[4] += ti * au1
        res[5] += ti * au2
        if want_jac:
            tl = ti / L
            kt = k_i - tl
            dL3 = (r1 * u2 - r2 * u1) * kt    # (k - t / L) [u; r x u]
            dL4 = (r2 * u0 - r0 * u2) * kt
            dL5 = (r0 * u1 - r1 * u0) * kt
            dL0, dL1, dL2 = u0 * kt, u1 * kt, u2 * kt
            for k in range(6):
                uk = (u0, u1, u2, au0, au1, au2)[k]
                jac[k, 0] += uk * dL0
                jac[k, 1] += uk * dL1
                jac[k, 2] += uk * dL2
                jac[k, 3] += uk * dL3
                jac[k, 4] += uk * dL4
                jac[k, 5] += uk * dL5
            sum_tl += tl
            s0 += tl * r0
            s1 += tl * r1
            s2 += tl * r2
            a0 += tl * ai0
            a1 += tl * ai1
            a2 += tl * ai2
            w00 += tl * r0 * ai0
            w01 += tl * r0 * ai1
            w02 += tl * r0 * ai2
            w10 += tl * r1 * ai0
            w11 += tl * r1 * ai1
            w12 += tl * r1 * ai2
            w20 += tl * r2 * ai0
            w21 += tl * r2 * ai1
            w22 += tl * r2 * ai2
            wr_dot_a += tl * (r0 * ai0 + r1 * ai1 + r2 * ai2)
    c0 = p[0] + R[0, 0] * g[0] + R[0, 1] * g[1] + R[0, 2] * g[2]
    c1 = p[1] + R[1, 0] * g[0] + R[1, 1] * g[1] + R[1, 2] * g[2]
    c2 = p[2] + R[2, 0] * g[0] + R[2, 1] * g[1] + R[2, 2] * g[2]
    res[0] -= force[0]
    res[1] -= force[1]
    res[2] -= force[2]
    res[3] -= moment[0] + c1 * arm[2] - c2 * arm[1]
    res[4] -= moment[1] + c2 * arm[0] - c0 * arm[2]
    res[5] -= moment[2] + c0 * arm[1] - c1 * arm[0]
    if not want_jac:
        return
    # top: + sum(t/L) I on dp, - [sum (t/L) r]x on dtheta
    jac[0, 0] += sum_tl
    jac[1, 1] += sum_tl
    jac[2, 2] += sum_tl
    jac[0, 4] += s2
    jac[0, 5] -= s1
    jac[1, 3] -= s2
    jac[1, 5] += s0
    jac[2, 3] += s1
    jac[2, 4] -= s0
    # bottom: + [sum (t/L) a]x + [arm]x on dp
    x0, x1, x2 = a0 + arm[0], a1 + arm[1], a2 + arm[2]
    jac[3, 1] -= x2
    jac[3, 2] += x1
    jac[4, 0] += x2
    jac[4, 2] -= x0
    jac[5, 0] -= x1
    jac[5, 1] += x0
    # bottom on dtheta: - (sum (t/L) r a^T - (sum (t/L) r . a) I) - [arm]x [c - p]x
    e0, e1, e2 = c0 - p[0], c1 - p[1], c2 - p[2]
    m0, m1, m2 = arm[0], arm[1], arm[2]
    # [arm]x [e]x = e arm^T - (arm . e) I
    ae = m0 * e0 + m1 * e1 + m2 * e2
    jac[3, 3] -= w00 - wr_dot_a + e0 * m0 - ae
    jac[3, 4] -= w01 + e0 * m1
    jac[3, 5] -= w02 + e0 * m2
    jac[4, 3] -= w10 + e1 * m0
    jac[4, 4] -= w11 - wr_dot_a + e1 * m1 - ae
    jac[4, 5] -= w12 + e1 * m2
    jac[5, 3] -= w20 + e2 * m0
    jac[5, 4] -= w21 + e2 * m1
    jac[5, 5] -= w22 - wr_dot_a + e2 * m2 - ae


def _solve6(A, x, work):
    """x <- A^-1 x for A (6, 6) (copied into work), Gaussian elimination with partial
    pivoting; False where A is singular (a zero pivot)."""
    for i in range(6):
        for j in range(6):
            work[i, j] = A[i, j]
    for k in range(6):
        piv, big = k, abs(work[k, k])
        for i in range(k + 1, 6):
            if abs(work[i, k]) > big:
                piv, big = i, abs(work[i, k])
        if big == 0.0:
            return False
        if piv != k:
            for j in range(6):
                work[k, j], work[piv, j] = work[piv, j], work[k, j]
            x[k], x[piv] = x[piv], x[k]
        for i in range(k + 1, 6):
            f = work[i, k] / work[k, k]
            if f != 0.0:
                for j in range(k + 1, 6):
                    work[i, j] -= f * work[k, j]
                x[i] -= f * x[k]
    for k in range(5, -1, -1):
        acc = x[k]
        for j in range(k + 1, 6):
            acc -= work[k, j] * x[j]
        x[k] = acc / work[k, k]
    return True


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


def _max_abs(v):
    best = 0.0
    for x in v:
        if abs(x) > best:
            best = abs(x)
    return best


def _scratch(m):
    """The work arrays of ``_newton_pose`` for m cables: residual (6,), Jacobian (6, 6),
    tensions (m,), trial residual (6,), trial p (3,) and R (3, 3), the step's rotation (3, 3)
    and rotation vector (3,), the step (6,) and ``_solve6``'s copy (6, 6)."""
    return (np.empty(6), np.empty((6, 6)), np.empty(m), np.empty(6), np.empty(3),
            np.empty((3, 3)), np.empty((3, 3)), np.empty(3), np.empty(6), np.empty((6, 6)))


def _newton_pose(a, b, g, EA, L0, p, R, force, moment, arm, bilateral, tol, iterations,
                 halvings, scratch):
    """``elastic._newton`` at one pose, in place on p (3,) and R (3, 3): converged?
    ``scratch``: ``_scratch(m)``'s arrays, overwritten (allocated once per batch, not per
    pose: the allocations cost as much as the arithmetic)."""
    res, jac, t, after, p_try, R_try, E, rv, step, work = scratch
    _balance(a, b, g, EA, L0, p, R, force, moment, arm, bilateral, res, jac, t, False)
    for _ in range(iterations):
        before = _max_abs(res)
        if before <= tol:
            return True
        _balance(a, b, g, EA, L0, p, R, force, moment, arm, bilateral, after, jac, t, True)
        for k in range(6):
            step[k] = -res[k]
        if not _solve6(jac, step, work):  # singular: not converged
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


def _equilibrium_poses(a, b, g, EA, L0, p, R, force, moment, arm, tol, iterations, halvings):
    """``elastic.equilibrium_poses`` for poses p (M, 3), R (M, 3, 3) (copied), cables of
    unstretched lengths L0 (M, m), anchors a, b (m, 3), load point g (3,), stiffness EA (m,),
    load rows force, moment, arm (M, 3), convergence tolerances tol (M,) N: (p, R, tensions
    (M, m), largest residual (M,), ok (M,))."""
    n, m = p.shape[0], a.shape[0]
    p, R = p.copy(), R.copy()
    tensions = np.empty((n, m))
    residual = np.empty(n)
    ok = np.zeros(n, dtype=np.bool_)
    scratch = _scratch(m)
    res, jac, t = scratch[0], scratch[1], scratch[2]
    for q in range(n):
        # a converged Newton leaves the residual and tensions of its pose in scratch; where
        # no pushing cable was needed the tension-only pass would stop at once with the
        # same numbers, so it is not run
        pushing = not _newton_pose(a, b, g, EA, L0[q], p[q], R[q], force[q], moment[q], arm[q],
                                   True, tol[q], iterations, halvings, scratch)
        for i in range(m):
            pushing = pushing or t[i] < 0.0
        ok[q] = not pushing or _newton_pose(a, b, g, EA, L0[q], p[q], R[q], force[q], moment[q],
                                            arm[q], False, tol[q], iterations, halvings, scratch)
        if not ok[q]:  # stuck: scratch may hold a rejected trial's
            _balance(a, b, g, EA, L0[q], p[q], R[q], force[q], moment[q], arm[q], False, res, jac,
                     t, False)
        tensions[q] = t
        residual[q] = _max_abs(res)
    return p, R, tensions, residual, ok


def _below_kappa(K, kappa, work):
    """Whether the least eigenvalue of the symmetric K (6, 6) is below kappa, decided by
    Cholesky: K - kappa I has a factor (every pivot positive) iff it is positive definite."""
    for j in range(6):
        for i in range(j, 6):
            s = K[i, j] - (kappa if i == j else 0.0)
            for k in range(j):
                s -= work[i, k] * work[j, k]
            if i == j:
                if not s > 0.0:
                    return True
                work[j, j] = np.sqrt(s)
            else:
                work[i, j] = s / work[j, j]
    return False


def _soft_poses(a, b, g, EA, p, R, t, force, moment, arm, ok, kappa):
    """``elastic.soft_poses``: at the poses p (M, 3), R (M, 3, 3) where ``ok`` (M,), the
    platform's stiffness K (``elastic.platform_stiffness``, the same algebra: ``_balance``'s
    Jacobian of cables held at L0 = L / (1 + t / EA), bilateral, moments moved to p,
    symmetrised) under the load rows force, moment, arm (3,) at tensions t (M, m): soft (M,)
    where K is finite and its least eigenvalue below kappa."""
    n, m = p.shape[0], a.shape[0]
    soft = np.zeros(n, dtype=np.bool_)
    res = np.empty(6)
    jac = np.empty((6, 6))
    K = np.empty((6, 6))
    work = np.empty((6, 6))
    tv = np.empty(m)
    L0 = np.empty(m)
    for q in range(n):
        if not ok[q]:
            continue
        P, Rq = p[q], R[q]
        usable = True  # numpy's K is not finite where a length is 0 or L0 not finite
        for i in range(m):
            r0 = Rq[0, 0] * b[i, 0] + Rq[0, 1] * b[i, 1] + Rq[0, 2] * b[i, 2]  # as _balance
            r1 = Rq[1, 0] * b[i, 0] + Rq[1, 1] * b[i, 1] + Rq[1, 2] * b[i, 2]
            r2 = Rq[2, 0] * b[i, 0] + Rq[2, 1] * b[i, 1] + Rq[2, 2] * b[i, 2]
            d0, d1, d2 = P[0] + r0 - a[i, 0], P[1] + r1 - a[i, 1], P[2] + r2 - a[i, 2]
            L = np.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
            stretch = 1.0 + t[q, i] / EA[i]
            if L == 0.0 or stretch == 0.0:
                usable = False
                break
            L0[i] = L / stretch
            if not (L0[i] != 0.0 and np.isfinite(L0[i])):
                usable = False
                break
        if not usable:  # (numba raises on a division by zero: not reached)
            continue
        _balance(a, b, g, EA, L0, P, Rq, force, moment, arm, True, res, jac, tv, True)
        for j in range(6):  # moments about p: M_p = M_o - p x F
            f0, f1, f2 = jac[0, j], jac[1, j], jac[2, j]
            jac[3, j] -= P[1] * f2 - P[2] * f1
            jac[4, j] -= P[2] * f0 - P[0] * f2
            jac[5, j] -= P[0] * f1 - P[1] * f0
        finite = True
        for i in range(6):
            for j in range(6):
                K[i, j] = 0.5 * (jac[i, j] + jac[j, i])
                finite = finite and np.isfinite(K[i, j])
        soft[q] = finite and _below_kappa(K, kappa, work)
    return soft


# ----- compilation -------------------------------------------------------------------------
HELPERS = ("_balance", "_solve6", "_rotvec_matrix", "_max_abs", "_scratch", "_newton_pose",
           "_below_kappa")
_F1, _F2, _F3 = "float64[::1]", "float64[:, ::1]", "float64[:, :, ::1]"
AOT_EXPORTS = {"equilibrium_kernel": (
    f"Tuple(({_F2}, {_F3}, {_F2}, {_F1}, boolean[::1]))"
    f"({_F2}, {_F2}, {_F1}, {_F1}, {_F2}, {_F2}, {_F3}, {_F2}, {_F2}, {_F2}, {_F1}, int64, int64)"),
    "soft_kernel": (f"boolean[::1]({_F2}, {_F2}, {_F1}, {_F1}, {_F2}, {_F3}, {_F2}, {_F1}, {_F1}, "
                    f"{_F1}, boolean[::1], float64)")}
AOT_PREFIX = "_elastic_aot_"


AOT_SOURCES = ("elastic_kernel.py",)  # what the machine code is of: this file


def jit_kernels():
    """numba's JIT entry (cache=True) by name (``cdh_planner.aot``); the helpers become
    numba functions here."""
    njit = aot.jit(globals(), HELPERS)
    return {"equilibrium_kernel": njit(_equilibrium_poses), "soft_kernel": njit(_soft_poses)}


_entries = aot.entries(sys.modules[__name__])
equilibrium_kernel, soft_kernel = _entries["equilibrium_kernel"], _entries["soft_kernel"]
