"""A chart's domain: the part of its tangent ball that no neighbour covers.

Henderson's atlas clips each chart's domain by one half-space {s : a . s <= beta} per
neighbour; the domain's frontier (where new charts go) is what lies outside the ball of
radius r. Two representations, one interface (``clip``, ``set_radius``, ``frontier``,
``drop``, ``closed``, ``close``, ``contains``, ``nbytes``):

- ``PolytopeDomain`` (exact): the clipped cube as vertices. The frontier
  is the set of vertices outside the ball; closed means the polytope lies in the ball. Its
  vertex count grows with the number of facets as O(k^floor(n/2)): fine in 2-D and 3-D,
  an explosion in 6-D (hundreds of thousands of vertices per chart).
- ``SampledDomain`` (bounded; the default in every dimension): the half-spaces only, as OMPL's
  AtlasChart keeps them, plus a fixed set of K directions on the unit sphere of the
  tangent space. A direction u is on the frontier while r u satisfies every half-space;
  closed means no direction is left. Memory is K bits plus one half-space per neighbour,
  whatever the dimension. What it can miss: an uncovered cap of the ball's boundary that
  holds none of the K directions (angular width below the directions' spacing, about
  0.5 rad for K = 384 in 6-D, 0.016 rad in 2-D). So "closed" means "closed at this
  angular resolution", and "no path at resolution r" means: every chart of the exhausted
  component had each of its K boundary directions covered by a neighbour (or cut by the
  domain's boundary) at chart radius r. With exact polytopes it means the balls cover the
  component's boundary-free part exactly. Measured (benchmarks/chart_domains.py): the
  sampled domain makes fewer charts and is faster in 2-D, 3-D and 6-D alike, so it is the
  default everywhere; the polytope stays for comparison (``Atlas(exact_max_dim=...)``).

Half-spaces are kept by both, so a point can be tested against the domain (``contains``).
"""

from pathlib import Path

import numpy as np

from .polytope import Polytope

TOL = 1e-10
_DIRECTIONS = {}  # (n, K) -> (K, n) unit vectors, shared by every chart of that dimension
# numpy.random.default_rng(1000 n).standard_normal(384 n) for n = 1 .. 6, one after the
# other: the draws of unit_directions written out, so that the first chart does not import
# numpy.random (~9 ms of a plan's process); test_domains checks them against the generator.
DRAWS_FILE = Path(__file__).with_name("directions.npy")
DRAWS_MAX_DIM, DRAWS_MAX_COUNT = 6, 384


def unit_directions(n, count, seed=0):
    """``count`` fixed pseudo-random unit vectors in R^n (the same on every machine)."""
    key = (n, count)
    if key not in _DIRECTIONS:
        g = _normal_draws(seed + 1000 * n, (count, n))
        _DIRECTIONS[key] = g / np.linalg.norm(g, axis=1, keepdims=True)
    return _DIRECTIONS[key]


def _normal_draws(seed, shape):
    """numpy.random.default_rng(seed).standard_normal(shape): read from DRAWS_FILE when it
    holds them (the first count * n numbers of the seed's stream, row by row)."""
    count, n = shape
    if seed == 1000 * n and 1 <= n <= DRAWS_MAX_DIM and count <= DRAWS_MAX_COUNT:
        start = DRAWS_MAX_COUNT * n * (n - 1) // 2  # after the draws of dimensions 1 .. n - 1
        return np.load(DRAWS_FILE)[start:start + count * n].reshape(count, n)
    import numpy.random  # only here: other seeds, dimensions or counts
    return numpy.random.default_rng(seed).standard_normal(shape)


class HalfSpaces:
    """Rows {s : a . s <= beta} in growable arrays (doubling)."""

    def __init__(self, n):
        self.a = np.empty((8, n))
        self.beta = np.empty(8)
        self.count = 0

    def add(self, a, beta):
        self.add_many(np.asarray(a)[None], np.atleast_1d(beta))

    def add_many(self, A, betas):
        """Rows A (m, n), betas (m,), in order (capacity doubles as one add after another would)."""
        while self.count + len(betas) > self.beta.size:
            self.a = np.concatenate([self.a, np.empty_like(self.a)])
            self.beta = np.concatenate([self.beta, np.empty_like(self.beta)])
        self.a[self.count:self.count + len(betas)] = A
        self.beta[self.count:self.count + len(betas)] = betas
        self.count += len(betas)

    def satisfied(self, S):
        """Which rows of S (m, n) satisfy every half-space."""
        k = self.count
        if k == 0:
            return np.ones(S.shape[0], dtype=bool)
        return np.all(S @ self.a[:k].T <= self.beta[:k] * (1 + TOL) + TOL, axis=1)

    @property
    def nbytes(self):
        return self.a.nbytes + self.beta.nbytes


class _Domain:
    """What both representations keep: the ball's ``radius`` and the ``halfspaces``."""

    def __init__(self, n, radius):
        self.radius = radius
        self.halfspaces = HalfSpaces(n)

    def clip_many(self, A, betas):
        """``clip`` by each row of A (m, n) and betas (m,) in turn until the domain is closed."""
        for a, beta in zip(A, betas):
            if self.closed:
                return
            self.clip(a, beta)

    def contains(self, S):
        """Which rows of S (m, n) lie in the ball and satisfy every half-space."""
        S = np.atleast_2d(S)
        return (np.linalg.norm(S, axis=1) <= self.radius * (1 + TOL)) & self.halfspaces.satisfied(S)


class PolytopeDomain(_Domain):
    """Exact Henderson domain: the cube [-r, r]^n clipped, kept as a vertex set."""

    def __init__(self, n, radius):
        super().__init__(n, radius)
        self.polytope = Polytope(n, radius)
        self._closed = False

    def clip(self, a, beta):
        self.halfspaces.add(a, beta)
        self.polytope.clip(a, beta)

    def set_radius(self, radius):
        """Shrink the ball, and the box with it (so that small neighbours can close it)."""
        self.radius = radius
        for k in range(self.polytope.n):
            e = np.zeros(self.polytope.n)
            e[k] = 1.0
            self.clip(e, radius)
            self.clip(-e, radius)

    def frontier(self, toward=None):
        """A unit direction towards a vertex outside the ball (the farthest one, or the one
        best aligned with ``toward``), or None when closed."""
        out = self.polytope.outside_vertices(self.radius)
        if out.size == 0:
            return None
        v = self.polytope.vertices[out]
        u = v / np.linalg.norm(v, axis=1, keepdims=True)
        k = 0 if toward is None else int(np.argmax(u @ toward))
        self._last = v[k]
        return u[k]

    def drop(self, u):
        """The last frontier vertex was used: cut it off if no clip removed it already."""
        vs = self.polytope.vertices
        if vs.shape[0] and np.any(np.all(np.isclose(vs, self._last), axis=1)):
            self.polytope.clip(u, self.radius)

    @property
    def closed(self):
        """Monotone: clipping only removes, so once closed a chart stays closed."""
        if not self._closed:
            self._closed = self.polytope.outside_vertices(self.radius).size == 0
        return self._closed

    def close(self):
        self.polytope.close()
        self._closed = True

    @property
    def nbytes(self):
        return self.halfspaces.nbytes + self.polytope.vertices.nbytes + self.polytope.bits.nbytes


class SampledDomain(_Domain):
    """Bounded domain: half-spaces plus which of K fixed unit directions are still free."""

    def __init__(self, n, radius, directions=384):
        super().__init__(n, radius)
        self.u = unit_directions(n, directions)
        self.alive = np.ones(directions, dtype=bool)

    def clip(self, a, beta):
        self.halfspaces.add(a, beta)
        idx = np.flatnonzero(self.alive)
        if idx.size:
            self.alive[idx[self.radius * (self.u[idx] @ a) > beta * (1 + TOL) + TOL]] = False

    def clip_many(self, A, betas):
        """What ``clip`` by each row in turn until closed does, in one product: each row's
        cut directions, and the half-spaces up to the row that closes the domain."""
        if len(betas) == 0 or not self.alive.any():
            return
        cut = (self.radius * (A @ self.u.T) > betas[:, None] * (1 + TOL) + TOL) & self.alive
        first = np.where(cut.any(axis=0), cut.argmax(axis=0), len(betas))  # first row cutting u
        last = int(first[self.alive].max())  # the row that closes the domain (if < m)
        keep = len(betas) if last >= len(betas) else last + 1
        self.halfspaces.add_many(A[:keep], betas[:keep])
        self.alive &= first >= keep

    def set_radius(self, radius):
        """A smaller ball: directions cut off only beyond the new radius come back."""
        self.radius = radius
        self.alive = self.halfspaces.satisfied(radius * self.u)

    def frontier(self, toward=None):
        """A free unit direction (the best aligned with ``toward``), or None when closed."""
        idx = np.flatnonzero(self.alive)
        if idx.size == 0:
            return None
        k = idx[0] if toward is None else idx[int(np.argmax(self.u[idx] @ toward))]
        return self.u[k]

    def drop(self, u):
        self.alive[self.u @ u > 1.0 - 1e-12] = False

    @property
    def closed(self):
        return not self.alive.any()

    def close(self):
        self.alive[:] = False

    @property
    def nbytes(self):
        return self.halfspaces.nbytes + self.alive.nbytes


def make_domain(n, radius, exact_max_dim=0, directions=384):
    """The exact polytope up to ``exact_max_dim`` dimensions, the sampled domain above
    (default: sampled in every dimension, the cheaper one in 2-D to 6-D: README)."""
    return PolytopeDomain(n, radius) if n <= exact_max_dim else SampledDomain(n, radius, directions)


def outline_2d(domain, count=180):
    """Points (count, 2) on the boundary of a 2-D domain's ball cut by its half-spaces,
    one per direction (for pictures)."""
    t = np.linspace(-np.pi, np.pi, count, endpoint=False)
    u = np.stack([np.cos(t), np.sin(t)], axis=1)
    h = domain.halfspaces
    rho = np.full(count, float(domain.radius))
    if h.count:
        au = u @ h.a[:h.count].T
        with np.errstate(divide="ignore", invalid="ignore"):
            cut = np.where(au > 1e-12, h.beta[:h.count] / au, np.inf)
        rho = np.minimum(rho, cut.min(axis=1))
    return np.maximum(rho, 0.0)[:, None] * u
