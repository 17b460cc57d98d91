"""The centred tension rule (package docstring): per pose its nominal t0 and band v, t0
centred in the null space of J by ``_centre``'s Newton. Units: m, N, N m. Plain Python
compiled by numba (``compiled``: ahead of time, else the JIT; no numba import here).

The rule's map is P = D J^T (J D J^T)^-1 (``rules.weighted_pseudo_inverse``, the one place
it is written). This kernel applies the same map in an equivalent algebraic form, from the
QR factorisation K^T = D^(1/2) J^T = Q R (J D J^T = R^T R): P x = D J^T R^-1 R^-T x. It is
kept so that the published tensions stay bit-identical to those plans were made with (and
it solves with R, whose condition number is J's, not J D J^T's, the square).
"""

import numpy as np

from .kernel import load_wrench
from .linalg import cholesky_solve, forward_substitute, householder_r, null_basis

# barrier weight of the centred nominal (normalised tensions): its least band slack is within
# 2 m CENTRE_MU of the best any null-space shift achieves. Numba freezes these constants into
# the machine code: the ahead-of-time build is named after this file's digest (rebuilt by
# make); numba's JIT cache only sees a file's own time stamp, and make clears it (``aot``).
CENTRE_MU = 1e-4
CENTRE_TOL = 1e-9  # Newton decrement^2 / mu at which the centring stops
CENTRE_ITERATIONS = 50  # Newton steps at most (bounded work)
POLISH = 2  # full Newton steps after CENTRE_TOL is met (start-independent to rounding)


def centred_kernel(J, c, w_local, L3, load_frame, tmin, tmax, ranked, centre, chunk):
    """The centred rule's t0 and v (N, m) N at poses with J (N, 6, m) and load points
    c (N, 3) (ellipsoid as ``kernel.facet_kernel``), where ``ranked`` (N,) (J of rank 6;
    elsewhere nan, inf); t0 centred where ``centre`` (N,) (the facet test holds), else the
    closed form's tensions toward mid range. Poses in chunks of ``chunk`` (>= 1): a chunk's
    first pose starts Newton cold, the others from their predecessor's answer."""
    n, m = J.shape[0], J.shape[2]
    t0, v = np.full((n, m), np.nan), np.full((n, m), np.inf)
    for k in range((n + chunk - 1) // chunk):
        _centred_poses(k * chunk, min(n, (k + 1) * chunk), J, c, w_local, L3, load_frame, tmin,
                       tmax, ranked, centre, t0, v)
    return t0, v


def _centred_poses(q0, q1, J, c, w_local, L3, load_frame, tmin, tmax, ranked, centre, t0, v):
    """``centred_kernel`` for poses q0 <= q < q1, into t0 and v."""
    m = J.shape[2]
    A = np.empty((m, 6))
    R = np.empty((6, 6))
    w0 = np.empty(6)
    L = np.empty((6, 6))
    Y = np.empty((6, 6))
    hv0 = np.empty(6)
    hvv = np.empty(6)
    Y_J = np.empty((6, m))  # R^-T J, a cable a column
    Q2 = np.empty((m, max(m - 6, 0)))
    room_lo = np.empty(m)
    room_hi = np.empty(m)
    zc = np.zeros(max(m - 6, 0) + 1)  # the shift z, then the last centring's gap
    scratch = _centre_scratch(m, max(m - 6, 0))
    col = np.empty((6, 1))
    a = np.empty((6, 1))
    mid = 0.5 * (tmin + tmax)
    sqd = tmax - tmin  # D^(1/2)
    shift = np.zeros(m)  # the last centred pose's normalised null-space shift Q2 z
    centred = q0 - 2     # which pose that was
    for q in range(q0, q1):
        if not ranked[q]:
            continue
        Jq = J[q]
        load_wrench(q, c, w_local, L3, load_frame, w0, L)
        # the tension rule: R from K^T = D^(1/2) J^T = Q R, so J D J^T = R^T R
        for i in range(m):
            for r in range(6):
                A[i, r] = sqd[i] * Jq[r, i]
        householder_r(A, R, hv0, hvv)
        forward_substitute(R, L, Y)  # Y = R^-T L
        for r in range(6):  # col = R^-T (w0 - J mid)
            s = w0[r]
            for i in range(m):
                s -= Jq[r, i] * mid[i]
            a[r, 0] = s
        forward_substitute(R, a, col)
        forward_substitute(R, Jq, Y_J)  # column i: R^-T J_i
        for i in range(m):
            d = sqd[i] * sqd[i]
            s = 0.0
            for r in range(6):
                s += Y_J[r, i] * col[r, 0]
            t0[q, i] = mid[i] + d * s
            vv = 0.0
            for j in range(6):
                s = 0.0
                for r in range(6):
                    s += Y_J[r, i] * Y[r, j]
                vv += s * s
            v[q, i] = d * np.sqrt(vv)
        # the centred nominal (wrench-feasible poses): t0 + D^(1/2) Q2 z, Q2 spanning
        # null(J D^(1/2))
        if m > 6 and centre[q]:
            null_basis(A, hv0, hvv, Q2)
            for i in range(m):
                room_lo[i] = (t0[q, i] - v[q, i] - tmin[i]) / sqd[i]
                room_hi[i] = (tmax[i] - v[q, i] - t0[q, i]) / sqd[i]
            # warm start from the previous pose's shift projected on this pose's null space
            # (Householder bases of neighbours need not agree; the shift itself is smooth)
            warm = centred == q - 1
            if warm:
                for kk in range(m - 6):
                    d = 0.0
                    for i in range(m):
                        d += Q2[i, kk] * shift[i]
                    zc[kk] = d
            _centre(room_lo, room_hi, Q2, zc, warm, scratch)
            for i in range(m):
                d = 0.0
                for kk in range(m - 6):
                    d += Q2[i, kk] * zc[kk]
                shift[i] = d
                t0[q, i] += sqd[i] * d
            centred = q


def _centre_scratch(m, k):
    """``_centre``'s work arrays for m cables and a null space of dimension k, made once a
    chunk (made per pose they cost as much as a tenth of the rule's time)."""
    n = k + 1
    return (np.empty(n), np.empty(2 * m), np.empty(n), np.empty((n, n)), np.empty(n),
            np.empty(n), np.empty(2 * m))


def _centre(lo, hi, Q2, z, warm, scratch):
    """The null-space shift z (k,) of the centred nominal (module doc): the maximiser of
    s + CENTRE_MU sum_j log(r_j) over (z, s), r the 2m slacks lo_i + Q2_i z - s and
    hi_i - Q2_i z - s (lo, hi: the normalised room below and above the band at z = 0), by
    Newton's method with an Armijo line search that stays inside. Strictly concave, so the
    maximiser is unique and smooth in the data; defined whether or not the band fits
    (s < 0 then). At most CENTRE_ITERATIONS steps (about 12 for 8 cables from z = 0).
    ``warm``: start from the given z[:k] (a neighbouring pose's answer) with s below the
    least slack by z[k], that pose's gap (along a motion Newton then needs a few steps; the
    maximiser is the same, the start only changes rounding). z[k] <- this answer's gap: its
    least slack less s (> 0). ``scratch``: ``_centre_scratch(m, k)``'s arrays."""
    m, k = Q2.shape
    n = k + 1
    mu = CENTRE_MU
    x, r, g, H, dx, xt, rt = scratch
    x[:] = 0.0  # (z, s)
    if warm:
        for a in range(k):
            x[a] = z[a]
        _slacks(lo, hi, Q2, x, r)
        x[k] = r.min() - (z[k] if z[k] > 0.0 else mu)  # strictly inside
    else:
        x[k] = min(lo.min(), hi.min()) - mu  # strictly inside
    polished = 0
    for _ in range(CENTRE_ITERATIONS):
        _slacks(lo, hi, Q2, x, r)
        g[:] = 0.0
        H[:, :] = 0.0
        g[k] = 1.0
        for j in range(2 * m):  # gradient g and minus the Hessian H (lower triangle)
            i, sg = (j, 1.0) if j < m else (j - m, -1.0)
            w1, w2 = mu / r[j], mu / (r[j] * r[j])
            for a in range(k):
                g[a] += sg * w1 * Q2[i, a]
                for b in range(a + 1):
                    H[a, b] += w2 * Q2[i, a] * Q2[i, b]
                H[k, a] -= sg * w2 * Q2[i, a]
            g[k] -= w1
            H[k, k] += w2
        for a in range(n):
            for b in range(a + 1, n):
                H[a, b] = H[b, a]
        cholesky_solve(H, g, n, dx)
        dec = 0.0  # the Newton decrement squared: twice the rise left, about
        for a in range(n):
            dec += g[a] * dx[a]
        if dec <= CENTRE_TOL * mu:
            # POLISH more full steps: Newton converges quadratically here (an error e becomes
            # ~e^2 / r), so the answer is the maximiser to rounding whatever the start (cold,
            # or a neighbour's warm one; one step left 2e-11 of the range between them)
            polished += 1
            for a in range(n):
                xt[a] = x[a] + dx[a]
            _slacks(lo, hi, Q2, xt, rt)
            if not rt.min() > 0.0:
                break
            x[:] = xt
            if polished == POLISH:
                break  # (a gradient at the last step's end would only be looked at)
            continue
        phi = x[k] + mu * _log_product(r)
        # the slacks are affine in x: start the line search inside (ratio test), so that
        # it halves for the rise only, not to find the interior (21 halvings a pose before)
        _slacks(lo, hi, Q2, dx, rt)  # rt = r(dx) = r(0) + slope, r(0) = (lo, hi)
        step = 1.0
        for j in range(2 * m):
            slope = rt[j] - (lo[j] if j < m else hi[j - m])
            if slope < 0.0 and -0.99 * r[j] / slope < step:
                step = -0.99 * r[j] / slope
        accepted = False
        for _ in range(60):  # halve until inside and rising enough (Armijo)
            for a in range(n):
                xt[a] = x[a] + step * dx[a]
            _slacks(lo, hi, Q2, xt, rt)
            if rt.min() > 0.0:
                phit = xt[k] + mu * _log_product(rt)
                if phit >= phi + 0.25 * step * dec:
                    accepted = True
                    break
            step *= 0.5
        if not accepted:
            break  # no rise left above rounding
        x[:] = xt
    for a in range(k):
        z[a] = x[a]
    _slacks(lo, hi, Q2, x, r)
    z[k] = r.min()

def _log_product(r):
    """sum_j log(r_j) of positive r, by one log per 8 factors (the line search's hot loop);
    the sum of logs itself if a partial product leaves the double range."""
    total, prod = 0.0, 1.0
    for j in range(r.size):
        prod *= r[j]
        if j % 8 == 7:
            total += np.log(prod)
            prod = 1.0
    total += np.log(prod)
    if np.isfinite(total):
        return total
    total = 0.0
    for j in range(r.size):
        total += np.log(r[j])
    return total

def _slacks(lo, hi, Q2, x, r):
    """r (2m,): lo_i + Q2_i z - s, then hi_i - Q2_i z - s, at x = (z, s)."""
    m, k = Q2.shape
    for i in range(m):
        d = 0.0
        for a in range(k):
            d += Q2[i, a] * x[a]
        r[i] = lo[i] + d - x[k]
        r[m + i] = hi[i] - d - x[k]
