"""C2 splines in numpy alone: scipy's ``CubicSpline`` (natural or clamped ends) and
``RotationSpline``, with scipy's formulas, so that answers agree with scipy's to rounding
(test_rotation_splines.py).

Why not scipy's: ``scipy.interpolate`` imports scipy.optimize, special and sparse (about
0.1 s of a 0.55 s plan), and RotationSpline lives in ``scipy.spatial``. The
linear systems are banded: a tridiagonal one by LAPACK's own algorithm (``solve_tridiagonal``),
a wider one up to ``DENSE_MAX`` unknowns densely by numpy (LU with partial pivoting, as
LAPACK's banded solver), beyond it by LAPACK's dgbsv through scipy's own wrapper, as
``scipy.linalg.solve_banded`` calls it (the same numbers), loaded without importing
``scipy.linalg`` (``lapack_gbsv``: 7 ms instead of 0.15 s of CPU, 5 - 15 % of an eight-cable
plan whose path has more than 200 waypoints).

    p = CubicSpline(s, points, bc_type="natural");  p(s_new, 1)   # value, or derivative
    R = RotationSpline(s, Rotation.from_quat(q));   R(s_new).as_matrix(), R(s_new, 1)
"""

import importlib.machinery
import importlib.util
import sys
from pathlib import Path

import numpy as np

from .rotation import Rotation

DENSE_MAX = 600  # unknowns: a dense solve is faster than importing scipy.linalg up to here


def solve_banded(l_and_u, ab, b):
    """x with A x = b, A given in LAPACK's banded storage ``ab`` (l + u + 1, n), as
    ``scipy.linalg.solve_banded``; b (n,) or (n, k)."""
    lower, upper = l_and_u
    n = ab.shape[1]
    if l_and_u == (1, 1):
        return solve_tridiagonal(ab[2, :-1], ab[1], ab[0, 1:], b)
    if n > DENSE_MAX:
        gbsv = lapack_gbsv()
        if gbsv is None:  # scipy laid out otherwise: its own function, imported now
            from scipy.linalg import solve_banded as scipy_solve_banded
            return scipy_solve_banded(l_and_u, ab, b, check_finite=False)
        a2 = np.zeros((2 * lower + upper + 1, n))       # dgbsv's room for the LU's fill
        a2[lower:, :] = ab
        _, _, x, info = gbsv(lower, upper, a2, np.asarray(b, dtype=float), overwrite_ab=True,
                             overwrite_b=False)
        if info > 0:
            raise np.linalg.LinAlgError("singular matrix")
        if info < 0:
            raise ValueError(f"illegal value in {-info}-th argument of internal gbsv")
        return x
    dense = np.zeros((n, n))
    for row in range(lower + upper + 1):
        offset = upper - row                  # dense[i, i + offset] = ab[row, i + offset]
        j = np.arange(max(offset, 0), min(n, n + offset))
        dense[j - offset, j] = ab[row, j]
    return np.linalg.solve(dense, b)


_GBSV = []  # [dgbsv or None] once looked for


def lapack_gbsv():
    """LAPACK's dgbsv (banded LU with partial pivoting, and its solve) as scipy's f2py
    wrapper ``scipy.linalg._flapack.dgbsv``, the function ``scipy.linalg.solve_banded``
    calls, with scipy's calling convention; loaded from its extension file alone (it needs
    only numpy), not through ``scipy.linalg``'s package import. None when there is no such
    file (then the caller imports scipy.linalg)."""
    if not _GBSV:
        _GBSV.append(_load_gbsv())
    return _GBSV[0]


def _load_gbsv():
    if "scipy.linalg" in sys.modules:  # imported already: its own module, nothing to load
        from scipy.linalg import _flapack
        return _flapack.dgbsv
    return gbsv_from_file()


def gbsv_from_file():
    """scipy's ``_flapack.dgbsv`` loaded from its extension file, or None."""
    spec = importlib.util.find_spec("scipy")
    if spec is None or spec.origin is None:
        return None
    for file in sorted((Path(spec.origin).parent / "linalg").glob("_flapack.*")):
        if not file.name.endswith(tuple(importlib.machinery.EXTENSION_SUFFIXES)):
            continue
        loader = importlib.machinery.ExtensionFileLoader("_flapack", str(file))
        module = importlib.util.module_from_spec(
            importlib.util.spec_from_file_location("_flapack", file, loader=loader))
        loader.exec_module(module)
        return getattr(module, "dgbsv", None)
    return None


def solve_tridiagonal(dl, d, du, b):
    """x with A x = b for A with sub-, main and super-diagonals dl (n-1,), d (n,), du (n-1,);
    b (n,) or (n, k). LAPACK's dgtsv (Gaussian elimination, rows swapped where the
    sub-diagonal is the larger), which scipy's solve_banded calls for one band each side:
    the same operations in the same order, so the same numbers. Raises
    numpy.linalg.LinAlgError when A is singular."""
    d, du, x = np.array(d, dtype=float), np.array(du, dtype=float), np.array(b, dtype=float)
    dl = np.array(dl, dtype=float)
    n = len(d)
    du2 = np.zeros(max(n - 2, 0))     # the second super-diagonal a row swap fills
    for i in range(n - 1):
        if abs(d[i]) >= abs(dl[i]):
            if d[i] == 0:
                raise np.linalg.LinAlgError("singular tridiagonal matrix")
            fact = dl[i] / d[i]
            d[i + 1] = d[i + 1] - fact * du[i]
            x[i + 1] = x[i + 1] - fact * x[i]
        else:
            fact = d[i] / dl[i]
            d[i] = dl[i]
            temp = d[i + 1]
            d[i + 1] = du[i] - fact * temp
            if i < n - 2:
                du2[i] = du[i + 1]
                du[i + 1] = -fact * du2[i]
            du[i] = temp
            temp = x[i].copy()
            x[i] = x[i + 1]
            x[i + 1] = temp - fact * x[i + 1]
    if d[n - 1] == 0:
        raise np.linalg.LinAlgError("singular tridiagonal matrix")
    x[n - 1] = x[n - 1] / d[n - 1]
    if n > 1:
        x[n - 2] = (x[n - 2] - du[n - 2] * x[n - 1]) / d[n - 2]
    for i in range(n - 3, -1, -1):
        x[i] = (x[i] - du[i] * x[i + 1] - du2[i] * x[i + 2]) / d[i]
    return x


class PiecewiseCubic:
    """Cubic pieces c (4, n - 1, ...) on breakpoints x (n,), scipy's PPoly: evaluated by
    a power sum from the lowest term, extrapolated by the end pieces."""

    def __init__(self, c, x):
        self.c, self.x = c, x

    def __call__(self, xs, nu=0):
        """Values (nu = 0) or nu-th derivatives at xs (M,): shape (M, ...)."""
        xs = np.asarray(xs, dtype=float)
        single = xs.ndim == 0
        xs = np.atleast_1d(xs)
        res = self._power_sum(*self._pieces(xs), nu)
        return res[0] if single else res

    def derivatives(self, xs, orders=(0, 1, 2)):
        """[``self(xs, nu)`` for nu in orders] at xs (M,), the pieces found once (the same
        numbers)."""
        xs = np.atleast_1d(np.asarray(xs, dtype=float))
        i, s = self._pieces(xs)
        return [self._power_sum(i, s, nu) for nu in orders]

    def _pieces(self, xs):
        """The piece of each x (M,) and x's offset in it (M, 1, ...)."""
        i = np.clip(np.searchsorted(self.x, xs, side="right") - 1, 0, len(self.x) - 2)
        return i, (xs - self.x[i]).reshape((-1,) + (1,) * (self.c.ndim - 2))

    def _power_sum(self, i, s, nu):
        """The nu-th derivative (M, ...) of pieces i at offsets s."""
        degree = self.c.shape[0] - 1
        res, z = 0.0, 1.0
        for kp in range(degree + 1):
            if kp < nu:
                continue
            prefactor = float(np.prod(np.arange(kp, kp - nu, -1))) if nu else 1.0
            res = res + self.c[degree - kp, i] * z * prefactor
            if kp < degree:
                z = z * s
        return np.broadcast_to(res, (len(i),) + self.c.shape[2:]) + 0.0


def hermite_coefficients(x, y, dydx):
    """Cubic pieces through y with slopes dydx at x (scipy's CubicHermiteSpline)."""
    dx = np.diff(x).reshape((-1,) + (1,) * (y.ndim - 1))
    slope = np.diff(y, axis=0) / dx
    t = (dydx[:-1] + dydx[1:] - 2 * slope) / dx
    return np.stack((t / dx, (slope - dydx[:-1]) / dx - t, dydx[:-1], y[:-1]))


class CubicSpline(PiecewiseCubic):
    """The C2 cubic spline through y (n, ...) at increasing x (n,), with zero second
    derivative ("natural") or zero first derivative ("clamped") at both ends."""

    def __init__(self, x, y, bc_type="natural"):
        x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
        order = {"natural": 2, "clamped": 1}[bc_type]
        if x.ndim != 1 or len(x) < 2 or len(y) != len(x) or np.any(np.diff(x) <= 0):
            raise ValueError("CubicSpline needs n >= 2 increasing x and n values")
        n, dx = len(x), np.diff(x)
        dxr = dx.reshape((-1,) + (1,) * (y.ndim - 1))
        slope = np.diff(y, axis=0) / dxr
        A = np.zeros((3, n))
        b = np.empty_like(y)
        A[1, 1:-1] = 2 * (dx[:-1] + dx[1:])
        A[0, 2:] = dx[:-1]
        A[-1, :-2] = dx[1:]
        b[1:-1] = 3 * (dxr[1:] * slope[:-1] + dxr[:-1] * slope[1:])
        if order == 1:
            A[1, 0], A[0, 1], b[0] = 1, 0, 0.0
            A[1, -1], A[-1, -2], b[-1] = 1, 0, 0.0
        else:
            A[1, 0], A[0, 1], b[0] = 2 * dx[0], dx[0], 3 * (y[1] - y[0])
            A[1, -1], A[-1, -2], b[-1] = 2 * dx[-1], dx[-1], 3 * (y[-1] - y[-2])
        s = solve_banded((1, 1), A, b.reshape(n, -1)).reshape(y.shape)
        super().__init__(hermite_coefficients(x, y, s), x)


# RotationSpline: scipy's port (its reference: "Smooth Attitude Interpolation", the
# rotation vectors between neighbours are cubic in time, angular rate and acceleration
# continuous, found by a fixed-point iteration on the banded system).

def _skew(x):
    out = np.zeros((len(x), 3, 3))
    out[:, 0, 1], out[:, 0, 2] = -x[:, 2], x[:, 1]
    out[:, 1, 0], out[:, 1, 2] = x[:, 2], -x[:, 0]
    out[:, 2, 0], out[:, 2, 1] = -x[:, 1], x[:, 0]
    return out


def _matvec(A, b):
    return np.einsum("ijk,ik->ij", A, b)


def _rate_to_rotvec_dot(rotvecs):
    norm = np.linalg.norm(rotvecs, axis=1)
    k = np.empty_like(norm)
    big = norm > 1e-4
    nm = norm[big]
    k[big] = (1 - 0.5 * nm / np.tan(0.5 * nm)) / nm ** 2
    nm = norm[~big]
    k[~big] = 1 / 12 + 1 / 720 * nm ** 2
    skew = _skew(rotvecs)
    out = np.empty((len(rotvecs), 3, 3))
    out[:] = np.identity(3)
    out[:] += 0.5 * skew
    out[:] += k[:, None, None] * np.matmul(skew, skew)
    return out


def _rotvec_dot_to_rate(rotvecs):
    norm = np.linalg.norm(rotvecs, axis=1)
    k1, k2 = np.empty_like(norm), np.empty_like(norm)
    big = norm > 1e-4
    nm = norm[big]
    k1[big] = (1 - np.cos(nm)) / nm ** 2
    k2[big] = (nm - np.sin(nm)) / nm ** 3
    nm = norm[~big]
    k1[~big] = 0.5 - nm ** 2 / 24
    k2[~big] = 1 / 6 - nm ** 2 / 120
    skew = _skew(rotvecs)
    out = np.empty((len(rotvecs), 3, 3))
    out[:] = np.identity(3)
    out[:] -= k1[:, None, None] * skew
    out[:] += k2[:, None, None] * np.matmul(skew, skew)
    return out


def _acceleration_nonlinear_term(rotvecs, rotvecs_dot):
    norm = np.linalg.norm(rotvecs, axis=1)
    dp = np.sum(rotvecs * rotvecs_dot, axis=1)
    cp = np.cross(rotvecs, rotvecs_dot)
    ccp = np.cross(rotvecs, cp)
    dccp = np.cross(rotvecs_dot, cp)
    k1, k2, k3 = np.empty_like(norm), np.empty_like(norm), np.empty_like(norm)
    big = norm > 1e-4
    nm = norm[big]
    k1[big] = (-nm * np.sin(nm) - 2 * (np.cos(nm) - 1)) / nm ** 4
    k2[big] = (-2 * nm + 3 * np.sin(nm) - nm * np.cos(nm)) / nm ** 5
    k3[big] = (nm - np.sin(nm)) / nm ** 3
    nm = norm[~big]
    k1[~big] = 1 / 12 - nm ** 2 / 180
    k2[~big] = -1 / 60 + nm ** 2 / 12604
    k3[~big] = 1 / 6 - nm ** 2 / 120
    return dp[:, None] * (k1[:, None] * cp + k2[:, None] * ccp) + k3[:, None] * dccp


def _angular_rate(rotvecs, rotvecs_dot):
    return _matvec(_rotvec_dot_to_rate(rotvecs), rotvecs_dot)


def _block_tridiagonal(A, B, d):
    """Banded storage (11, 3 (n + 1)) of the matrix with blocks A below, d I on and B
    above the diagonal."""
    ind, blocks = np.arange(3), np.arange(len(A))
    A_i = np.empty_like(A, dtype=int)
    A_i[:] = ind[:, None]
    A_i += 3 * (1 + blocks[:, None, None])
    A_j = np.empty_like(A, dtype=int)
    A_j[:] = ind
    A_j += 3 * blocks[:, None, None]
    B_i = np.empty_like(B, dtype=int)
    B_i[:] = ind[:, None]
    B_i += 3 * blocks[:, None, None]
    B_j = np.empty_like(B, dtype=int)
    B_j[:] = ind
    B_j += 3 * (1 + blocks[:, None, None])
    diag = np.arange(3 * len(d))
    i = np.hstack((A_i.ravel(), B_i.ravel(), diag))
    j = np.hstack((A_j.ravel(), B_j.ravel(), diag))
    values = np.hstack((A.ravel(), B.ravel(), np.repeat(d, 3)))
    out = np.zeros((11, 3 * len(d)))
    out[5 + i - j, j] = values
    return out


class RotationSpline:
    """C2 interpolation of rotations (a Rotation stack of n >= 2) at increasing times:
    ``spline(t)`` a Rotation, ``spline(t, 1)`` the angular rate and ``spline(t, 2)`` the
    angular acceleration (rad/s, rad/s^2, in the frame scipy's RotationSpline uses)."""

    MAX_ITER = 10
    TOL = 1e-9

    def __init__(self, times, rotations):
        times = np.asarray(times, dtype=float)
        dt = np.diff(times)
        if np.any(dt <= 0) or len(times) != len(rotations) or len(times) < 2:
            raise ValueError("RotationSpline needs n >= 2 increasing times and n rotations")
        rotvecs = (rotations[:-1].inv() * rotations[1:]).as_rotvec()
        rates = rotvecs / dt[:, None]
        if len(rotations) == 2:
            rotvecs_dot = rates
        else:
            rates, rotvecs_dot = self._solve_for_rates(dt, rates, rotvecs)
        dt = dt[:, None]
        coeff = np.empty((4, len(times) - 1, 3))
        coeff[0] = (-2 * rotvecs + dt * rates + dt * rotvecs_dot) / dt ** 3
        coeff[1] = (3 * rotvecs - 2 * dt * rates - dt * rotvecs_dot) / dt ** 2
        coeff[2] = rates
        coeff[3] = 0
        self.times, self.rotations = times, rotations
        self.interpolator = PiecewiseCubic(coeff, times)

    def _solve_for_rates(self, dt, rates, rotvecs):
        first = rates[0].copy()
        A = _rate_to_rotvec_dot(rotvecs)
        A_inv = _rotvec_dot_to_rate(rotvecs)
        M = _block_tridiagonal(2 * A_inv[1:-1] / dt[1:-1, None, None],
                               2 * A[1:-1] / dt[1:-1, None, None], 4 * (1 / dt[:-1] + 1 / dt[1:]))
        b0 = 6 * (rotvecs[:-1] * dt[:-1, None] ** (-2) + rotvecs[1:] * dt[1:, None] ** (-2))
        b0[0] -= 2 / dt[0] * A_inv[0].dot(first)
        b0[-1] -= 2 / dt[-1] * A[-1].dot(rates[-1])
        for _ in range(self.MAX_ITER):
            rotvecs_dot = _matvec(A, rates)
            b = b0 - _acceleration_nonlinear_term(rotvecs[:-1], rotvecs_dot[:-1])
            new = solve_banded((5, 5), M, b.ravel()).reshape((-1, 3))
            delta = np.abs(new - rates[:-1])
            rates[:-1] = new
            if np.all(delta < self.TOL * (1 + np.abs(new))):
                break
        rotvecs_dot = _matvec(A, rates)
        return np.vstack((first, rates[:-1])), rotvecs_dot

    def __call__(self, times, order=0):
        times = np.asarray(times, dtype=float)
        single = times.ndim == 0
        times = np.atleast_1d(times)
        rotvecs = self.interpolator(times)
        if order == 0:
            index = np.clip(np.searchsorted(self.times, times, side="right") - 1, 0,
                            len(self.times) - 2)
            result = self.rotations[index] * Rotation.from_rotvec(rotvecs)
        elif order == 1:
            result = _angular_rate(rotvecs, self.interpolator(times, 1))
        elif order == 2:
            rotvecs_dot = self.interpolator(times, 1)
            result = (_angular_rate(rotvecs, self.interpolator(times, 2))
                      + _acceleration_nonlinear_term(rotvecs, rotvecs_dot))
        else:
            raise ValueError("`order` must be 0, 1 or 2.")
        return result[0] if single else result

    def derivatives(self, times):
        """(``self(times)``, ``self(times, 1)``, ``self(times, 2)``) at times (M,): the
        rotation vectors and their rate matrix computed once (the same numbers)."""
        times = np.atleast_1d(np.asarray(times, dtype=float))
        rotvecs, rotvecs_dot, rotvecs_ddot = self.interpolator.derivatives(times)
        index = np.clip(np.searchsorted(self.times, times, side="right") - 1, 0,
                        len(self.times) - 2)
        rate = _rotvec_dot_to_rate(rotvecs)
        return (self.rotations[index] * Rotation.from_rotvec(rotvecs), _matvec(rate, rotvecs_dot),
                _matvec(rate, rotvecs_ddot) + _acceleration_nonlinear_term(rotvecs, rotvecs_dot))
