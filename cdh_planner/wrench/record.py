"""The result records of the wrench tests (``Feasibility``, ``WrenchFeasibility``) and the
names they give constraints ("tension_max[3]", a facet "tension_max[2]+tension_min[7,8]").
Units: m, N, N m."""

from dataclasses import dataclass, fields
from functools import cached_property, lru_cache, reduce

import numpy as np

CONSTRAINTS = ("length_min", "length_max", "tension_min", "tension_max")
# |det J| (six cables) or sqrt(det J J^T) (more) at or below this is singular (J has
# unit-vector columns, so its scale is at most 1 * moment arms).
SINGULAR_DET = 1e-12
STATUS_OK, STATUS_EXCEEDS, STATUS_INFEASIBLE, STATUS_SINGULAR = \
    "ok", "rule_exceeds_limits", "infeasible", "singular"


@dataclass
class Feasibility:
    """Feasibility of N poses. Arrays have N rows; per-cable ones m columns.

    ``margins`` (N, 4, m) are the signed distances to each bound, normalised by the bound's
    range (dmax - dmin or fmax - fmin), in the order of CONSTRAINTS; ``margin`` (N,) is
    their minimum (-inf where J is singular), positive iff the pose is feasible;
    ``binding`` (N,) names the constraint attaining it, e.g. "tension_min[3]" (cables
    numbered from 1) or "singular". ``tension_nominal`` (N, m) N and ``tension_spread``
    (N, m) N: the tension envelope's centre f0 (t0) and half-width v.
    """

    lengths: np.ndarray  # (N, m) m
    unit_vectors: np.ndarray  # (N, m, 3)
    det_j: np.ndarray  # (N,)
    tension_nominal: np.ndarray  # (N, m) N, f0
    tension_spread: np.ndarray  # (N, m) N, v_ii
    margins: np.ndarray  # (N, 4, m)
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


def joined(records):
    """One record (a Feasibility or a subclass) of the poses of ``records`` in order."""
    if len(records) == 1:
        return records[0]
    return type(records[0])(**{f.name: np.concatenate([getattr(r, f.name) for r in records])
                               for f in fields(records[0])})


@dataclass
class WrenchFeasibility(Feasibility):
    """The facet test's record of N poses of an m-cable robot (``Feasibility`` with m columns).

    ``margin`` (N,): the least of the length margins and the normalised facet margin
    (dimensionless, > 0 iff feasible; for m = 6 the closed form's margin). ``margin_newtons``
    (N,): the least facet slack, N (a facet normal is a unit 6-vector mixing N and N m).
    ``margins`` (N, 4, m): rows length_min, length_max as in ``Feasibility``; rows
    tension_min, tension_max are the tension rule's band margins (normalised by the range):
    the facet test, not them, decides feasibility when m > 6. ``binding``: "length_max[3]",
    a facet "tension_max[2]+tension_min[7,8]" (the cables off the facet's spanning set and
    the bound they sit at on it; for m = 6 the closed form's name) or "singular".
    ``tension_nominal`` / ``tension_spread``: the robot's tension rule's t0 and v;
    ``tension_status`` (N,): STATUS_OK, STATUS_EXCEEDS, STATUS_INFEASIBLE or STATUS_SINGULAR.
    ``det_j``: sqrt(det(J J^T)) >= 0 (|det J| for m = 6), singular at or below SINGULAR_DET.
    """

    margin_newtons: np.ndarray  # (N,) N
    wrench_margin: np.ndarray  # (N,) normalised facet margin alone (no lengths)
    wrench_facet: np.ndarray  # (N,) int: the subset of the facet attaining it, -1 if none
    wrench_facet_up: np.ndarray  # (N,) int: bit i set if cable i is at t_max on that facet
    tension_status: np.ndarray  # (N,) str

    @cached_property
    def band_ok(self):
        """True where the rule's band lies within the tension limits (controller-usable)."""
        return self.tension_status == STATUS_OK


@lru_cache(maxsize=None)
def constraint_names(m):
    """Names of the 4m margins of ``Feasibility.margins`` flattened: "length_min[1]", ...,
    "tension_max[m]"."""
    return np.array([f"{CONSTRAINTS[j // m]}[{j % m + 1}]" for j in range(4 * m)])


@dataclass(frozen=True)
class Margin:
    """A wrench test's ``margin`` (N,) and ``binding`` (N,) alone, as in its Feasibility."""

    margin: np.ndarray
    binding: np.ndarray


def row_min(a):
    """The least entry of each row of ``a`` (N, k >= 1), nan where a row holds one, for
    comparisons: k - 1 elementwise minima of its columns (numpy's own reduction along a
    short last axis is ~10x slower: 1 ms for 20,000 rows of 8). The sign a zero result
    has may differ from a.min(axis=1)'s."""
    return reduce(np.minimum, a.T)


def length_margins(robot, lengths):
    """The length_min and length_max rows of ``normalised_margins``, each (N, m)."""
    span_l = robot.length_max - robot.length_min
    return (lengths - robot.length_min) / span_l, (robot.length_max - lengths) / span_l


def normalised_margins(robot, lengths, t0, v):
    """``Feasibility.margins`` (N, 4, m) of cable lengths (N, m) m and a band t0 +- v (N, m) N."""
    span_t = robot.tension_max - robot.tension_min
    return np.stack([*length_margins(robot, lengths),
                     (t0 - v - robot.tension_min) / span_t, (robot.tension_max - t0 - v) / span_t],
                    axis=1)
