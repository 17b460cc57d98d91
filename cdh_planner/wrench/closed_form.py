"""Closed-form wrench feasibility of six-cable robots (paper Sec. 2, App. A), vectorised.

A pose q = (p, R) is wrench-feasible iff for every cable i
    dmin_i < d_i < dmax_i,  f0_i - v_ii > fmin_i,  f0_i + v_ii < fmax_i,
with f0 = J^-1 w0 the tensions balancing the nominal wrench and v_ii = sqrt((B^-1)_ii),
B^-1 = J^-1 E^-1 J^-T, the largest change of tension i over the wrench ellipsoid.
(f0 - v, f0, f0 + v) is the tension envelope. Units: m, N, N m.
"""

import numpy as np

from .geometry import cable_vectors, inverse_ellipsoid_factor, load_point, nominal_wrench, screw_jacobian
from ..parallel import map_blocks
from .record import SINGULAR_DET, Feasibility, constraint_names, joined, normalised_margins, row_min


def inverse_jacobian(robot, p, R):
    """The six-cable pose quantities: lengths (N, 6) m, unit vectors u (N, 6, 3), det J (N,),
    J^-1 (N, 6, 6) (the identity's inverse where singular), load points c (N, 3) m and the
    singular mask (N,)."""
    dvec = cable_vectors(robot, p, R)
    lengths = np.linalg.norm(dvec, axis=-1)
    u = dvec / np.where(lengths > 0, lengths, 1.0)[..., None]
    J = screw_jacobian(robot, u)
    det, singular = _singular(J, lengths)
    J_safe = np.where(singular[:, None, None], np.eye(6), J)
    return lengths, u, det, np.linalg.inv(J_safe), load_point(robot, p, R), singular


def _singular(J, lengths):
    """det J (N,) and where the pose is singular (N,): |det J| not above SINGULAR_DET, or a
    cable of no length (lengths (N, 6) m)."""
    with np.errstate(divide="ignore", invalid="ignore"):  # singular J: reported by callers
        det = np.linalg.det(J)
    return det, ~(np.abs(det) > SINGULAR_DET) | (row_min(lengths) <= 0)


def _envelope(robot, J_inv, c):
    """f0 = J^-1 w0 (N, 6) N and v = |rows of J^-1 L| (N, 6) N at load points c (N, 3) m
    (compiled for many poses, with wrenches of the caller's: ``kernel.six_cable_kernel``)."""
    w = nominal_wrench(robot, c)
    f0 = np.einsum("nij,nj->ni", J_inv, w)
    return f0, np.linalg.norm(J_inv @ inverse_ellipsoid_factor(robot, c), axis=-1)


def closed_form(robot, p, R):
    """``Feasibility`` of poses of a six-cable robot: positions p (N, 3) m, R (N, 3, 3). A
    large batch in blocks on threads (numpy's loops and LAPACK release the GIL; each
    pose's numbers are its own, whatever the block)."""
    return joined(map_blocks(lambda a, b: _closed_form(robot, p[a:b], R[a:b]), len(p)))


def _closed_form(robot, p, R):
    n = p.shape[0]
    lengths, u, det, J_inv, c, singular = inverse_jacobian(robot, p, R)
    f0, spread = _envelope(robot, J_inv, c)
    margins = normalised_margins(robot, lengths, f0, spread)
    flat = margins.reshape(n, -1)
    k = np.argmin(flat, axis=1)
    margin = flat[np.arange(n), k]
    binding = constraint_names(6)[k]
    margin = np.where(singular, -np.inf, margin)
    binding = np.where(singular, "singular", binding)
    f0 = np.where(singular[:, None], np.nan, f0)
    spread = np.where(singular[:, None], np.inf, spread)
    return Feasibility(lengths=lengths, unit_vectors=u, det_j=det, tension_nominal=f0,
                       tension_spread=spread, margins=margins, margin=margin, binding=binding)
