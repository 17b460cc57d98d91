"""Wrench feasibility for any number of cables m >= 6 (issue 21; maths: docs/more-cables.md).

The wrenches m cables can hold form the zonotope Z = {J t : t_min <= t <= t_max} (J is
6 x m, column i = [u_i; a_i x u_i]). Its facets lie on the hyperplanes spanned by 5
independent columns: for each 5-subset S of rank 5, c is orthogonal to the columns in S
and both signs of n = c / |c| are facet normals with support value
    h(n) = sum_i max(n.J_i t_min_i, n.J_i t_max_i).
The wrench ellipsoid {w0 + L u : |u| <= 1} (L L^T = E^-1 in the base frame) lies in Z iff
for every such n
    s(n) = h(n) - n.w0 - |L^T n| >= 0      (hyperplane shifting; Bouchard et al. 2010).
``margin_newtons`` is min s(n) (N, or N m: n mixes force and moment rows); the normalised
margin divides each slack by Z's width along n, h(n) + h(-n) = sum_i |n.J_i| (t_max_i -
t_min_i), before the minimum. With m = 6 the facet test is the paper's closed form and the
normalised margin its margin, exactly (docs/more-cables.md).

Tensions are not unique when m > 6. The envelope published per cable comes from one rule
a winch controller can run, the closed-form method weighted by the tension ranges
(Pott, Bruckmann & Mikelsons 2009): the least-squares tensions toward the middle of the range,
    t(w) = t_mid + P (w - J t_mid),   P = D J^T (J D J^T)^-1,   D = diag(t_max - t_min)^2,
so J t(w) = w. It is affine in w: over the ellipsoid its tensions are exactly
t0 +- v, t0 = t(w0), v_i = |row i of P L|. With m = 6, P = J^-1: the paper's envelope. The
rule may leave [t_min, t_max] at a pose Z holds: ``tension_status`` then says
"rule_exceeds_limits" (the band is still the rule's, but no controller should use it).
Units: m, N, N m.
"""

from dataclasses import dataclass
from functools import cached_property, lru_cache
from itertools import combinations

import numpy as np
from numba import njit

from .feasibility import CONSTRAINTS, SINGULAR_DET, Feasibility, cable_vectors, \
    inverse_ellipsoid_factor, load_point, nominal_wrench, screw_jacobian
from .model.pose import rotation_tt

MIN_CABLES = 6
# a 5-subset whose last pivot is below this fraction of its first one is rank 4: it spans
# no facet (every facet hyperplane is spanned by some 5 independent columns)
RANK_TOL = 1e-12
STATUS_OK, STATUS_EXCEEDS, STATUS_INFEASIBLE, STATUS_SINGULAR = \
    "ok", "rule_exceeds_limits", "infeasible", "singular"


@lru_cache(maxsize=None)
def facet_subsets(m):
    """The 5-subsets of m cables, (C(m, 5), 5) int64, in itertools order."""
    return np.array(list(combinations(range(m), 5)), dtype=np.int64)


@njit(cache=True)
def _normal_of(J, S, A, c, perm):
    """c (6,) orthogonal to the columns J[:, S] (S: 5 indices), by Gaussian elimination of
    their transpose with complete pivoting. Returns |last pivot| / |first pivot| (0: rank 4
    or less). ``A`` (5, 6), ``perm`` (6,) are scratch."""
    for r in range(5):
        for k in range(6):
            A[r, k] = J[k, S[r]]
    for k in range(6):
        perm[k] = k
    first = 0.0
    for step in range(5):
        best, bi, bj = -1.0, step, step
        for i in range(step, 5):
            for j in range(step, 6):
                v = abs(A[i, perm[j]])
                if v > best:
                    best, bi, bj = v, i, j
        if step == 0:
            first = best
        if best <= 0.0:
            return 0.0
        if bi != step:
            for k in range(6):
                A[step, k], A[bi, k] = A[bi, k], A[step, k]
        perm[step], perm[bj] = perm[bj], perm[step]
        pc = perm[step]
        for i in range(step + 1, 5):
            f = A[i, pc] / A[step, pc]
            if f != 0.0:
                for j in range(step, 6):
                    A[i, perm[j]] -= f * A[step, perm[j]]
    free = perm[5]
    c[free] = 1.0
    for step in range(4, -1, -1):
        s = -A[step, free]
        for j in range(step + 1, 5):
            s -= A[step, perm[j]] * c[perm[j]]
        c[perm[step]] = s / A[step, perm[step]]
    return best / first


@njit(cache=True)
def facet_margins(J, w0, L, tmin, tmax, subsets):
    """Least facet slack of each pose: J (N, 6, m), w0 (N, 6), L (N, 6, 6), tension bounds
    (m,), subsets (K, 5). Returns (margin in N, normalised margin, its facet, its cables at
    t_max): facet = 2 k + (0 for +c, 1 for -c), k the subset, -1 (margins +inf) when no
    subset has rank 5; the last is a bit mask (bit i: cable i sits at t_max_i on that facet,
    the other cables off the subset at t_min)."""
    n, m = J.shape[0], J.shape[2]
    K = subsets.shape[0]
    out_n = np.full(n, np.inf)
    out_r = np.full(n, np.inf)
    arg_r = np.full(n, -1, np.int64)
    hi_r = np.zeros(n, np.int64)
    A = np.empty((5, 6))
    c = np.empty(6)
    perm = np.empty(6, np.int64)
    inS = np.zeros(m, np.bool_)
    for q in range(n):
        Jq, Lq, wq = J[q], L[q], w0[q]
        for k in range(K):
            S = subsets[k]
            if _normal_of(Jq, S, A, c, perm) <= RANK_TOL:
                continue
            for r in range(5):
                inS[S[r]] = True
            hp, hm, width = 0.0, 0.0, 0.0
            up, down = 0, 0  # cables at t_max on the +c facet, on the -c facet
            for i in range(m):
                if inS[i]:
                    continue  # c.J_i = 0 for the spanning columns: exactly, not rounded
                p = 0.0
                for r in range(6):
                    p += c[r] * Jq[r, i]
                a, b = p * tmin[i], p * tmax[i]
                if a > b:
                    hp += a
                    hm -= b
                else:
                    hp += b
                    hm -= a
                if p > 0.0:
                    up |= 1 << i
                else:
                    down |= 1 << i
                width += abs(p) * (tmax[i] - tmin[i])
            for r in range(5):
                inS[S[r]] = False
            cw, cc, lt = 0.0, 0.0, 0.0
            for r in range(6):
                cw += c[r] * wq[r]
                cc += c[r] * c[r]
                s = 0.0
                for j in range(6):
                    s += Lq[j, r] * c[j]
                lt += s * s
            lt = np.sqrt(lt)
            norm = np.sqrt(cc)
            for sign in range(2):
                slack = (hp - cw - lt) if sign == 0 else (hm + cw - lt)
                sn = slack / norm
                if sn < out_n[q]:
                    out_n[q] = sn
                sr = slack / width if width > 0.0 else (-np.inf if slack < 0.0 else np.inf)
                if sr < out_r[q]:
                    out_r[q], arg_r[q] = sr, 2 * k + sign
                    hi_r[q] = up if sign == 0 else down
    return out_n, out_r, arg_r, hi_r


@dataclass
class WrenchFeasibility(Feasibility):
    """Feasibility of N poses of an m-cable robot (``Feasibility`` with m columns).

    ``margin`` (N,): the least of the length margins and the normalised facet margin
    (dimensionless, > 0 iff feasible; for m = 6 the closed form's margin). ``margin_newtons``
    (N,): the least facet slack, N (a facet normal is a unit 6-vector mixing N and N m).
    ``margins`` (N, 4, m): rows length_min, length_max as in ``Feasibility``; rows
    tension_min, tension_max are the tension rule's band margins (normalised by the range):
    the facet test, not them, decides feasibility when m > 6. ``binding``: "length_max[3]",
    a facet "tension_max[2]+tension_min[7,8]" (the cables off the facet's spanning set and
    the bound they sit at on it; for m = 6 the closed form's name) or "singular".
    ``tension_nominal`` / ``tension_spread``: the rule's t0 and v (module doc);
    ``tension_status`` (N,): STATUS_OK, STATUS_EXCEEDS, STATUS_INFEASIBLE or STATUS_SINGULAR.
    """

    margin_newtons: np.ndarray  # (N,) N
    wrench_margin: np.ndarray  # (N,) normalised facet margin alone (no lengths)
    tension_status: np.ndarray  # (N,) str

    @cached_property
    def band_ok(self):
        """True where the rule's band lies within the tension limits (controller-usable)."""
        return self.tension_status == STATUS_OK


def jacobian_scale(J):
    """sqrt(det(J J^T)) (N,): |det J| for m = 6, 0 iff rank J < 6 (Cauchy-Binet)."""
    with np.errstate(invalid="ignore", over="ignore"):
        d = np.linalg.det(J @ np.swapaxes(J, -1, -2))
    return np.sqrt(np.maximum(d, 0.0))


def tension_rule(robot, J, w0, L):
    """The weighted closed-form rule (module doc) at N poses: t0 (N, m) N, v (N, m) N."""
    tmin, tmax = robot.tension_min, robot.tension_max
    mid, D = 0.5 * (tmin + tmax), (tmax - tmin) ** 2
    JD = J * D  # J D, (N, 6, m)
    G = JD @ np.swapaxes(J, -1, -2)  # J D J^T (N, 6, 6), symmetric positive definite
    P = np.swapaxes(np.linalg.solve(G, JD), -1, -2)  # D J^T G^-1 (N, m, 6)
    t0 = mid + np.einsum("nij,nj->ni", P, w0 - J @ mid)
    v = np.linalg.norm(P @ L, axis=-1)
    return t0, v


def facet_name(k, hi, m):
    """Name of facet k's side whose cables at t_max are the bit mask ``hi``: the cables off
    the spanning subset k at the bound they take on it (1-based), e.g.
    "tension_max[2]+tension_min[7,8]"; for m = 6 one cable, the closed form's name."""
    S = set(facet_subsets(m)[k].tolist())
    off = [i for i in range(m) if i not in S]
    up = [str(i + 1) for i in off if hi >> i & 1]
    down = [str(i + 1) for i in off if not hi >> i & 1]
    return "+".join(([f"tension_max[{','.join(up)}]"] if up else [])
                    + ([f"tension_min[{','.join(down)}]"] if down else []))


def _binding_names(ml, kl, mr, arg, hi, m):
    """The binding constraint per pose: a length bound or a facet (named once per kind)."""
    names = np.array([f"{CONSTRAINTS[j // m]}[{j % m + 1}]" for j in range(2 * m)], dtype=object)
    binding = names[kl]
    facet = (mr < ml) & (arg >= 0)
    if facet.any():
        keys, inverse = np.unique(np.stack([arg[facet] // 2, hi[facet]], axis=1), axis=0,
                                  return_inverse=True)
        facet_names = np.array([facet_name(int(k), int(h), m) for k, h in keys], dtype=object)
        binding[facet] = facet_names[inverse.ravel()]
    return binding


def evaluate(robot, p, tau=None, R=None):
    """Feasibility of poses of an m-cable robot (m >= 6): positions p (N, 3) m and either tau
    (N, 3) rad or R (N, 3, 3). A ``WrenchFeasibility``."""
    p = np.atleast_2d(np.asarray(p, dtype=float))
    if R is None:
        R = rotation_tt(np.atleast_2d(tau))
    R = np.asarray(R, dtype=float).reshape(-1, 3, 3)
    n, m = p.shape[0], len(robot.base_anchors)
    dvec = cable_vectors(robot, p, R)
    lengths = np.linalg.norm(dvec, axis=-1)
    u = dvec / np.where(lengths > 0, lengths, 1.0)[..., None]
    J = screw_jacobian(robot, u)
    scale = jacobian_scale(J)
    singular = ~(scale > SINGULAR_DET) | (lengths.min(axis=1) <= 0)
    J = np.where(singular[:, None, None], _regular_jacobian(m), J)
    c = load_point(robot, p, R)
    w0 = nominal_wrench(robot, c)
    L = np.ascontiguousarray(np.broadcast_to(inverse_ellipsoid_factor(robot, c), (n, 6, 6)))
    mn, mr, arg, hi = facet_margins(np.ascontiguousarray(J), np.ascontiguousarray(w0), L,
                                    robot.tension_min, robot.tension_max, facet_subsets(m))
    t0, v = tension_rule(robot, J, w0, L)
    span_l = robot.length_max - robot.length_min
    span_t = robot.tension_max - robot.tension_min
    margins = np.stack([(lengths - robot.length_min) / span_l, (robot.length_max - lengths) / span_l,
                        (t0 - v - robot.tension_min) / span_t, (robot.tension_max - t0 - v) / span_t],
                       axis=1)
    length_flat = margins[:, :2, :].reshape(n, -1)
    kl = np.argmin(length_flat, axis=1)
    ml = length_flat[np.arange(n), kl]
    margin = np.minimum(ml, mr)
    binding = _binding_names(ml, kl, mr, arg, hi, m)
    status = np.where(mr > 0, np.where(margins[:, 2:, :].reshape(n, -1).min(axis=1) > 0,
                                       STATUS_OK, STATUS_EXCEEDS), STATUS_INFEASIBLE)
    status = np.where(singular, STATUS_SINGULAR, status).astype(object)
    margin = np.where(singular, -np.inf, margin)
    binding = np.where(singular, "singular", binding).astype(str)
    mn, mr = np.where(singular, -np.inf, mn), np.where(singular, -np.inf, mr)
    t0 = np.where(singular[:, None], np.nan, t0)
    v = np.where(singular[:, None], np.inf, v)
    return WrenchFeasibility(lengths=lengths, unit_vectors=u, det_j=scale, tension_nominal=t0,
                             tension_spread=v, margins=margins, margin=margin, binding=binding,
                             margin_newtons=mn, wrench_margin=mr, tension_status=status.astype(str))


@lru_cache(maxsize=None)
def _regular_jacobian(m):
    """A rank-6 stand-in (6, m) for singular poses, so that no solve fails (their results
    are replaced)."""
    J = np.zeros((6, m))
    J[:, :6] = np.eye(6)
    J[:, 6:] = 1.0
    return J
