"""The facet test for any number of cables m >= 6 and the tension rule's band, at poses
(maths: the package docstring, docs/more-cables.md); the compiled work is in ``kernel``
(facets) and the robot's rule (``rules``). Units: m, N, N m."""

from functools import lru_cache
from itertools import combinations

import numpy as np

from .geometry import inverse_factor
from .compiled import facet_batch, pose_geometry
from .record import (SINGULAR_DET, STATUS_EXCEEDS, STATUS_INFEASIBLE, STATUS_OK,
                     STATUS_SINGULAR, Feasibility, Margin, WrenchFeasibility, constraint_names,
                     length_margins, normalised_margins, row_min)
from .rules import rule_of, stiff_nominal, stiffness_band

NO_SUBSETS = np.empty((0, 5), dtype=np.int64)  # the kernel without the facet test


@lru_cache(maxsize=None)
def facet_subsets(m):
    """The 5-subsets of m cables, (C(m, 5), 5) int64, in itertools order."""
    return np.array(list(combinations(range(m), 5)), dtype=np.int64)


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
    names = constraint_names(m)[:2 * m].astype(object)
    binding = names[kl]
    facet = (mr < ml) & (arg >= 0)
    if facet.any():
        keys, inverse = np.unique((arg[facet] // 2) << m | hi[facet], return_inverse=True)
        facet_names = np.array([facet_name(int(k) >> m, int(k) & ((1 << m) - 1), m) for k in keys],
                               dtype=object)
        binding[facet] = facet_names[inverse.ravel()]
    return binding


def _facets(robot, p, R, subsets):
    """The kernels at poses (p (N, 3) m, R (N, 3, 3)) with the facet test over ``subsets``:
    lengths, u, J, c, and the facet kernel's sqrt(det J J^T), margins, facet, mask and
    ranked."""
    lengths, u, J, c = pose_geometry(np.ascontiguousarray(p), np.ascontiguousarray(R),
                                     robot.base_anchors, robot.platform_anchors, robot.load_point)
    return (lengths, u, J, c) + facet_batch(
        J, c, robot.wrench_center_local, inverse_factor(robot), robot.ellipsoid_frame == "load",
        robot.tension_min, robot.tension_max, subsets, SINGULAR_DET)


def _poses(robot, p, R, subsets):
    """``_facets`` and the rule: lengths, u, sqrt(det J J^T), the facet kernel's margins,
    facet and mask, and the rule's t0 and v (v of elastic cables: ``stiffness_band``). The
    rule centres where the facet test holds (every ranked pose without subsets)."""
    lengths, u, J, c, scale, mn, mr, arg, hi, ranked = _facets(robot, p, R, subsets)
    centre = ranked & (mr > 0)
    t0, v = rule_of(robot).tensions(robot, J, c, ranked, centre)
    t0 = stiff_nominal(robot, p, R, J, t0, centre)
    return lengths, u, scale, mn, mr, arg, hi, t0, stiffness_band(robot, J, c, t0, lengths, v)


def _facet_margin(robot, lengths, scale, mr, arg, hi):
    """The facet test's margin (N,) (-inf where singular), binding (N,) str and singular
    (N,) bool: the least of the length margins and the wrench margin ``mr``."""
    n, m = lengths.shape
    singular = ~(scale > SINGULAR_DET) | (row_min(lengths) <= 0)
    length_flat = np.concatenate(length_margins(robot, lengths), axis=1)
    kl = np.argmin(length_flat, axis=1)
    ml = length_flat[np.arange(n), kl]
    margin = np.where(singular, -np.inf, np.minimum(ml, mr))
    binding = np.where(singular, "singular", _binding_names(ml, kl, mr, arg, hi, m)).astype(str)
    return margin, binding, singular


def facet_margin(robot, p, R):
    """``facet_test``'s margin and binding alone (a ``Margin``), without the tension rule
    (which costs as much as the facet test): what the dense check of a motion reads."""
    lengths, _, _, _, scale, _, mr, arg, hi, _ = _facets(robot, p, R,
                                                         facet_subsets(len(robot.base_anchors)))
    margin, binding, _ = _facet_margin(robot, lengths, scale, mr, arg, hi)
    return Margin(margin=margin, binding=binding)


def facet_test(robot, p, R):
    """``WrenchFeasibility`` of poses of an m-cable robot (m >= 6): positions p (N, 3) m,
    R (N, 3, 3)."""
    n, m = p.shape[0], len(robot.base_anchors)
    lengths, u, scale, mn, mr, arg, hi, t0, v = _poses(robot, p, R, facet_subsets(m))
    margin, binding, singular = _facet_margin(robot, lengths, scale, mr, arg, hi)
    margins = normalised_margins(robot, lengths, t0, v)
    status = np.where(mr > 0, np.where(row_min(margins[:, 2:, :].reshape(n, -1)) > 0,
                                       STATUS_OK, STATUS_EXCEEDS), STATUS_INFEASIBLE)
    status = np.where(singular, STATUS_SINGULAR, status)
    mn, mr = np.where(singular, -np.inf, mn), np.where(singular, -np.inf, mr)
    t0 = np.where(singular[:, None], np.nan, t0)
    v = np.where(singular[:, None], np.inf, v)
    return WrenchFeasibility(lengths=lengths, unit_vectors=u, det_j=scale, tension_nominal=t0,
                             tension_spread=v, margins=margins, margin=margin, binding=binding,
                             margin_newtons=mn, wrench_margin=mr,
                             wrench_facet=np.where(singular | (arg < 0), -1, arg // 2),
                             wrench_facet_up=hi,
                             tension_status=status)


def _band(robot, p, R):
    """lengths (N, m), unit vectors, sqrt(det J J^T), the rule's t0 and v (N, m) and the
    length and band margins (N, 4, m) of poses, without the facet test."""
    lengths, u, scale, _, _, _, _, t0, v = _poses(robot, p, R, NO_SUBSETS)
    return lengths, u, scale, t0, v, normalised_margins(robot, lengths, t0, v)


def band_margin(robot, p, R):
    """``band_feasibility(...).margin`` (N,) alone: the atlas's domain test, where a
    Feasibility record per pose would cost more than the kernel."""
    lengths, _, scale, _, _, margins = _band(robot, p, R)
    margin = margins.reshape(len(margins), -1).min(axis=1)  # nan where singular
    ok = (scale > SINGULAR_DET) & (row_min(lengths) > 0) & ~np.isnan(margin)
    return np.where(ok, margin, -np.inf)


def band_feasibility(robot, p, R):
    """``Feasibility`` of poses of an m-cable robot by the rule's band: ``margin`` the least
    of the length margins and the band margins ``margins`` (N, 4, m), named as the closed
    form names them; positive iff the band t0 +- v is within the limits (which implies the
    facet test). The kernels without the facet test."""
    lengths, u, scale, t0, v, margins = _band(robot, p, R)
    n, m = margins.shape[0], margins.shape[2]
    singular = ~(scale > SINGULAR_DET) | (row_min(lengths) <= 0)
    flat = margins.reshape(n, -1)
    k = np.argmin(np.where(np.isnan(flat), -np.inf, flat), axis=1)
    margin = flat[np.arange(n), k]
    singular |= np.isnan(margin)
    return Feasibility(lengths=lengths, unit_vectors=u, det_j=scale,
                       tension_nominal=np.where(singular[:, None], np.nan, t0),
                       tension_spread=np.where(singular[:, None], np.inf, v), margins=margins,
                       margin=np.where(singular, -np.inf, margin),
                       binding=np.where(singular, "singular", constraint_names(m)[k]).astype(str))


def band_tensions(robot, p, R):
    """The rule's t0 (N, m) N and band v (N, m) N at poses, without the facet test (t0
    centred at every pose: equal to ``facet_test``'s where that holds); nan / inf where
    singular."""
    lengths, _, scale, t0, v, _ = _band(robot, p, R)
    singular = ~(scale > SINGULAR_DET) | (row_min(lengths) <= 0)
    return np.where(singular[:, None], np.nan, t0), np.where(singular[:, None], np.inf, v)
