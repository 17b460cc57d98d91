"""Closed-form wrench feasibility (paper Sec. 2, App. A), vectorised over poses.

A pose q = (p, R) is wrench-feasible iff for every cable i
    dmin_i < d_i < dmax_i,  f0_i - v_ii > fmin_i,  f0_i + v_ii < fmax_i,
with f0 = J^-1 w0 the tensions balancing the nominal wrench and v_ii = sqrt((B^-1)_ii),
B^-1 = J^-1 E^-1 J^-T, the largest change of tension i over the wrench ellipsoid.
(f0 - v, f0, f0 + v) is the tension envelope. Units: m, N, N m.
"""

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from .errors import InputError
from .model.pose import rotation_tt

CONSTRAINTS = ("length_min", "length_max", "tension_min", "tension_max")
# |det J| below this (J has unit-vector columns, so |det J| <= 1 * moment arms) is singular.
SINGULAR_DET = 1e-12


def skew(v):
    """Cross-product matrices [v]x, shape (..., 3, 3)."""
    v = np.asarray(v, dtype=float)
    S = np.zeros(v.shape[:-1] + (3, 3))
    S[..., 0, 1], S[..., 0, 2] = -v[..., 2], v[..., 1]
    S[..., 1, 0], S[..., 1, 2] = v[..., 2], -v[..., 0]
    S[..., 2, 0], S[..., 2, 1] = -v[..., 1], v[..., 0]
    return S


def cable_vectors(robot, p, R):
    """d_i = p + R b_i - a_i (from base anchor to platform anchor), shape (N, m, 3), m."""
    return p[:, None, :] + np.einsum("nij,kj->nki", R, robot.platform_anchors) - robot.base_anchors


def screw_jacobian(robot, u):
    """J with column i = [u_i; a_i x u_i] (moments about the base origin), shape (N, 6, m)."""
    J = np.empty(u.shape[:-2] + (6, u.shape[-2]))
    J[..., :3, :] = np.swapaxes(u, -1, -2)
    J[..., 3:, :] = np.swapaxes(np.cross(robot.base_anchors, u), -1, -2)
    return J


def load_point(robot, p, R):
    """c = p + R g, the load point in the base frame, shape (N, 3), m."""
    return p + np.einsum("nij,j->ni", R, robot.load_point)


def wrench_transform(c):
    """e(c) = [[I, 0], [-[c]x, I]]: maps F1 wrench coordinates to the load frame F3."""
    e = np.zeros(c.shape[:-1] + (6, 6))
    e[..., :3, :3] = np.eye(3)
    e[..., 3:, 3:] = np.eye(3)
    e[..., 3:, :3] = -skew(c)
    return e


def nominal_wrench(robot, c):
    """w0 in F1 (force; moment about O), shape (N, 6)."""
    w = np.broadcast_to(robot.wrench_center_local, c.shape[:-1] + (6,)).copy()
    if robot.ellipsoid_frame == "load":
        w[..., 3:] += np.cross(c, w[..., :3])
    return w


def ellipsoid_matrix(robot, c):
    """E in F1, shape (N, 6, 6): e^T E_F3 e for a load-frame ellipsoid, else constant."""
    if robot.ellipsoid_frame == "base":
        return np.broadcast_to(robot.ellipsoid_matrix, c.shape[:-1] + (6, 6))
    e = wrench_transform(c)
    return np.swapaxes(e, -1, -2) @ robot.ellipsoid_matrix @ e


def inverse_ellipsoid_factor(robot, c):
    """L with L L^T = E_F1^-1, shape (N, 6, 6), without inverting E per pose.

    E_F1^-1 = e^-1 E3^-1 e^-T and e(c)^-1 = e(-c), so L = e(-c) chol(E3^-1).
    """
    L3 = np.linalg.cholesky(np.linalg.inv(robot.ellipsoid_matrix))
    if robot.ellipsoid_frame == "base":
        return np.broadcast_to(L3, c.shape[:-1] + (6, 6))
    return wrench_transform(-c) @ L3


@dataclass
class Feasibility:
    """Closed-form feasibility of N poses. Arrays have N rows; per-cable ones 6 columns.

    ``margins`` (N, 4, 6) are the signed distances to each bound, normalised by the bound's
    range (dmax - dmin or fmax - fmin), in the order of CONSTRAINTS; ``margin`` (N,) is
    their minimum (-inf where J is singular), positive iff the pose is feasible;
    ``binding`` (N,) names the constraint attaining it, e.g. "tension_min[3]" (cables
    numbered from 1) or "singular".
    """

    lengths: np.ndarray  # (N, 6) m
    unit_vectors: np.ndarray  # (N, 6, 3)
    det_j: np.ndarray  # (N,)
    tension_nominal: np.ndarray  # (N, 6) N, f0
    tension_spread: np.ndarray  # (N, 6) N, v_ii
    margins: np.ndarray  # (N, 4, 6)
    margin: np.ndarray  # (N,)
    binding: np.ndarray  # (N,) str

    # Computed once: a report reads them per pose (each a whole-array operation).
    @cached_property
    def tension_min(self):
        return self.tension_nominal - self.tension_spread

    @cached_property
    def tension_max(self):
        return self.tension_nominal + self.tension_spread

    @cached_property
    def feasible(self):
        return self.margin > 0

    @cached_property
    def singular(self):
        return ~np.isfinite(self.margin)


def evaluate(robot, p, tau=None, R=None):
    """Feasibility of poses: positions p (N, 3) m and either tau (N, 3) rad or R (N, 3, 3).

    Six cables only (J square); ``zonotope.evaluate`` handles any m >= 6. An m-cable robot
    here is refused naming its winch names: the callers not yet ported to ``zonotope``."""
    if len(robot.base_anchors) != 6:
        raise InputError("robot.winch_names", list(robot.winch_names),
                         f"{len(robot.winch_names)} cables: this command handles 6-cable robots "
                         "for now (cdh_planner.zonotope tests any m >= 6: docs/more-cables.md)")
    p = np.atleast_2d(np.asarray(p, dtype=float))
    if R is None:
        R = rotation_tt(np.atleast_2d(tau))
    R = np.asarray(R, dtype=float).reshape(-1, 3, 3)
    n = p.shape[0]
    dvec = cable_vectors(robot, p, R)
    lengths = np.linalg.norm(dvec, axis=-1)
    u = dvec / np.where(lengths > 0, lengths, 1.0)[..., None]
    J = screw_jacobian(robot, u)
    with np.errstate(divide="ignore", invalid="ignore"):  # singular J: reported below
        det = np.linalg.det(J)
    singular = ~(np.abs(det) > SINGULAR_DET) | (lengths.min(axis=1) <= 0)
    J_safe = np.where(singular[:, None, None], np.eye(6), J)
    c = load_point(robot, p, R)
    J_inv = np.linalg.inv(J_safe)
    f0 = np.einsum("nij,nj->ni", J_inv, nominal_wrench(robot, c))
    spread = np.linalg.norm(J_inv @ inverse_ellipsoid_factor(robot, c), axis=-1)

    margins = np.stack([
        (lengths - robot.length_min) / (robot.length_max - robot.length_min),
        (robot.length_max - lengths) / (robot.length_max - robot.length_min),
        (f0 - spread - robot.tension_min) / (robot.tension_max - robot.tension_min),
        (robot.tension_max - f0 - spread) / (robot.tension_max - robot.tension_min),
    ], axis=1)
    flat = margins.reshape(n, -1)
    k = np.argmin(flat, axis=1)
    margin = flat[np.arange(n), k]
    names = np.array([f"{CONSTRAINTS[j // 6]}[{j % 6 + 1}]" for j in range(24)])
    binding = names[k]
    margin = np.where(singular, -np.inf, margin)
    binding = np.where(singular, "singular", binding)
    f0 = np.where(singular[:, None], np.nan, f0)
    spread = np.where(singular[:, None], np.inf, spread)
    return Feasibility(lengths=lengths, unit_vectors=u, det_j=det, tension_nominal=f0,
                       tension_spread=spread, margins=margins, margin=margin, binding=binding)
