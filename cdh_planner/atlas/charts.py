"""Henderson's multiple-hypercube atlas of an implicitly defined manifold F(x) = 0.

Knows nothing of robots. The constraint gives (duck-typed, like OMPL's Constraint):
    n_vars, dim                      ambient and manifold dimensions
    residual_and_jacobian(x)         F (n_vars - dim,) and F_x (n_vars - dim, n_vars)
    periodic                         bool mask: coordinates that are 2 pi periodic
    lower, upper                     the bounded domain of x (periodic ones ignored)
    inside(x)                        optional: a predicate further restricting the domain
                                     (a region of M with no variable bound on it)
    key(x)                           a low-dimensional 1-Lipschitz embedding of x, for the
                                     spatial index (|key(x) - key(y)| <= |x - y|)

A chart i is a point x_i on M, an orthonormal basis Phi_i of its tangent space, a radius
r_i and a domain P_i in tangent coordinates s (``domain.py``: half-spaces and sampled
frontier directions, so that no chart grows without bound; exact polytopes on request). phi_i(s) = x_i + Phi_i s; psi_i(s) is its
Newton projection onto M. New charts are made at the ball's boundary towards a polytope
vertex outside the ball; the step halves where the manifold curves (distance to the tangent
space or tangent-space angle too large, or Newton not converging), and the chart then takes
that smaller radius so that its smaller neighbours can close it; radii grow back (a new
chart gets twice the step that made it, up to r). A chart that reaches the variable domain's
boundary is a frontier chart, its domain cut where the boundary is crossed.

For a search that samples (RRT-like) the atlas also gives ``sample`` (a point of M in a
chart's domain), ``owner`` (the chart whose domain holds a point) and ``traverse`` (a
discrete geodesic between two points of M). ``nbytes`` counts the memory the atlas holds
(chart centres, bases, domains, cached edge points): the search bounds it.
"""

import math

import numpy as np

from .domain import make_domain

TWO_PI = 2.0 * np.pi


class Chart:
    """A chart: centre ``x`` (on M), tangent ``basis`` (n_vars, dim), ``domain``."""

    __slots__ = ("x", "basis", "domain", "neighbours", "frontier", "index")

    def __init__(self, index, x, basis, domain):
        self.index = index
        self.x = x
        self.basis = basis
        self.domain = domain
        self.neighbours = set()
        self.frontier = False  # touches the domain boundary or a place Newton cannot reach

    @property
    def radius(self):
        return self.domain.radius

    @property
    def closed(self):
        """No frontier left. Monotone: clipping only removes, and only open charts grow
        (and shrink), so once closed a chart stays closed."""
        return self.domain.closed


class Atlas:
    """A growing atlas. ``radius`` is the chart radius r in the constraint's scaled units."""

    def __init__(self, constraint, radius=0.1, epsilon=0.25, max_angle=0.5, min_radius_ratio=1 / 16,
                 newton_tol=1e-9, newton_iters=12, exact_max_dim=0, directions=384):
        self.c = constraint
        self.exact_max_dim = exact_max_dim
        self.directions = directions
        self.radius = float(radius)
        self.epsilon = epsilon
        self.cos_max_angle = np.cos(max_angle)
        self.min_radius = self.radius * min_radius_ratio
        self.newton_tol = newton_tol
        self.newton_iters = newton_iters
        self.charts = []
        self.periodic = np.asarray(constraint.periodic, dtype=bool)
        self._periodic_at = np.flatnonzero(self.periodic)  # faster to index than the mask
        self._inside = getattr(constraint, "inside", None)  # the domain's predicate part
        self._index = _KeyIndex()
        self._centres = _Rows()  # chart centres (N, n_vars), for vectorised distances
        self._radii = _Rows()  # chart radii (N,), kept equal to charts[i].radius
        self._edges = {}  # (i, j), i < j -> points on M from chart i to chart j, or None
        self.nbytes = 0

    # ----- geometry --------------------------------------------------------------------
    def diff(self, x, y):
        """y - x with periodic coordinates wrapped to [-pi, pi)."""
        d = y - x
        d[self._periodic_at] = _wrap_angle(d[self._periodic_at])
        return d

    def wrap(self, x):
        x = x.copy()
        x[self.periodic] = _wrap_angle(x[self.periodic])
        return x

    def in_domain(self, x):
        return self._in_box(x) and (self._inside is None or bool(self._inside(x)))

    def _all_in_domain(self, xs):
        """Are all the points xs in the domain? (with the constraint's ``inside_many``, one
        call for all)"""
        many = getattr(self.c, "inside_many", None)
        if many is None:
            return all(self.in_domain(x) for x in xs)
        return all(self._in_box(x) for x in xs) and bool(np.all(many(np.array(xs))))

    def _in_box(self, x):
        free = ~self.periodic
        return bool(np.all(x[free] >= self.c.lower[free]) and np.all(x[free] <= self.c.upper[free]))

    def tangent_basis(self, x):
        """Orthonormal basis of ker F_x(x), shape (n_vars, dim)."""
        _, Fx = self.c.residual_and_jacobian(x)
        q, _ = np.linalg.qr(Fx.T, mode="complete")
        return q[:, Fx.shape[0]:]

    def newton(self, x0, basis, s_target, x_start):
        """psi: solve F(x) = 0, basis^T (x - x0) = s_target from x_start; None if no convergence."""
        x = x_start.copy()
        m = self.c.n_vars - self.c.dim
        A = np.empty((self.c.n_vars, self.c.n_vars))
        rhs = np.empty(self.c.n_vars)
        A[m:] = basis.T
        with np.errstate(all="ignore"):
            for _ in range(self.newton_iters):
                F, Fx = self.c.residual_and_jacobian(x)
                rhs[:m] = F
                rhs[m:] = basis.T @ self.diff(x0, x) - s_target
                largest = np.abs(rhs).max()  # nan or inf if any entry is
                if not math.isfinite(largest):
                    return None
                if largest < self.newton_tol:
                    return x
                A[:m] = Fx
                try:
                    step = np.linalg.solve(A, rhs)
                except np.linalg.LinAlgError:
                    return None
                if not math.isfinite(np.abs(step).max()):
                    return None
                x = x - step
            F, _ = self.c.residual_and_jacobian(x)  # diverged iterates overflow: quietly
        largest = np.abs(F).max()
        return x if math.isfinite(largest) and largest < 1e3 * self.newton_tol else None

    def psi(self, i, s):
        """Projection onto M of the point with tangent coordinates s in chart i."""
        ch = self.charts[i]
        return self.newton(ch.x, ch.basis, s, ch.x + ch.basis @ s)

    def coordinates(self, i, x):
        """Tangent coordinates of x in chart i (the inverse of psi_i near x_i)."""
        ch = self.charts[i]
        return ch.basis.T @ self.diff(ch.x, x)

    # ----- growth ----------------------------------------------------------------------
    def add_chart(self, x, radius=None, basis=None):
        """Add a chart at x (a point on M); links and clips its neighbours. Returns its index."""
        x = self.wrap(np.asarray(x, dtype=float))
        radius = self.radius if radius is None else radius
        i = len(self.charts)
        basis = self.tangent_basis(x) if basis is None else basis
        ch = Chart(i, x, basis, make_domain(basis.shape[1], radius, self.exact_max_dim, self.directions))
        self.charts.append(ch)
        self.nbytes += x.nbytes + basis.nbytes + ch.domain.nbytes + 64 * 8
        key = self.c.key(x)
        near, d, dist = self._near(x, key, radius + self.radius)
        overlap = dist < radius + self._radii.rows[near]  # the balls overlap: neighbours
        # nearest first: their planes cut most, so later clips mostly find nothing to cut
        order = np.flatnonzero(overlap)[np.argsort(dist[overlap], kind="stable")]
        self._link_new(i, near[order], d[order])
        self._index.add(key)
        self._centres.add(x)
        self._radii.add(radius)
        return i

    def _link_new(self, i, js, d):
        """Link the new chart i to the charts js (their balls overlap i's; d: x_j - x_i,
        wrapped): i is clipped by all of them at once (as one clip after another would,
        nearest first, until closed), then each open one of them by i (a Python loop over
        the open ones only: the cost of a chart follows its open neighbours, not the
        atlas's size)."""
        ci = self.charts[i]
        rj = self._radii.rows[js]
        for j in js.tolist():
            ci.neighbours.add(j)
            self.charts[j].neighbours.add(i)
        s = d @ ci.basis
        ds = np.linalg.norm(s, axis=1)
        ok = ds >= 1e-12
        beta = (ds[ok] ** 2 + ci.radius ** 2 - rj[ok] ** 2) / (2.0 * ds[ok])
        # keep a core around the centre: a chart never loses its own centre
        before = ci.domain.nbytes
        ci.domain.clip_many(s[ok] / ds[ok, None], np.maximum(beta, 0.05 * ci.radius))
        self.nbytes += ci.domain.nbytes - before
        for k, j in enumerate(js.tolist()):
            cj = self.charts[j]
            if not cj.closed:  # clipping a closed chart cannot change anything the search uses
                self._clip_by(cj, ci, -d[k])

    def _near(self, x, key, bound):
        """Charts whose centre's key lies within ``bound`` of ``key`` (a superset of those
        within wrapped distance ``bound`` of x: the key is 1-Lipschitz): (indices, their
        wrapped differences centre - x (k, n_vars), distances (k,))."""
        near = np.asarray(self._index.query(key, bound), dtype=int)
        if near.size == 0:
            return near, np.empty((0, x.size)), np.empty(0)
        d = self._centres.rows[near] - x
        d[:, self.periodic] = _wrap_angle(d[:, self.periodic])
        return near, d, np.linalg.norm(d, axis=1)

    def _link(self, i, j, d=None):
        """Link charts i and j if their balls overlap and clip each by the other; ``d``:
        the wrapped difference x_j - x_i if known."""
        ci, cj = self.charts[i], self.charts[j]
        d = self.diff(ci.x, cj.x) if d is None else d
        if np.linalg.norm(d) >= ci.radius + cj.radius:
            return
        ci.neighbours.add(j)
        cj.neighbours.add(i)
        for a, b, dab in ((ci, cj, d), (cj, ci, -d)):
            if not a.closed:  # clipping a closed chart cannot change anything the search uses
                self._clip_by(a, b, dab)

    def _clip_by(self, a, b, dab):
        """Clip chart a's domain by the half-space of its neighbour b (dab: x_b - x_a)."""
        s = a.basis.T @ dab
        ds = np.linalg.norm(s)
        if ds >= 1e-12:
            beta = (ds * ds + a.radius ** 2 - b.radius ** 2) / (2.0 * ds)
            # keep a core around the centre: a chart never loses its own centre
            self._clip(a, s / ds, max(beta, 0.05 * a.radius))

    def _clip(self, ch, a, beta):
        before = ch.domain.nbytes
        ch.domain.clip(a, beta)
        self.nbytes += ch.domain.nbytes - before

    def expand(self, i, toward=None):
        """One growth step from chart i, on the frontier direction best aligned with the
        point ``toward`` (if given). Returns the new chart's index, or None if no chart
        was made (the chart is closed, or the chosen direction was closed off)."""
        ch = self.charts[i]
        t = None if toward is None else ch.basis.T @ self.diff(ch.x, toward)
        u = ch.domain.frontier(t)
        if u is None:
            return None
        step = ch.radius
        while step >= self.min_radius * (1 - 1e-9):
            x_new = self.psi(i, step * u)
            basis = None if x_new is None else self._acceptable_basis(ch, step * u, x_new, step)
            if basis is not None and not self.in_domain(x_new):
                # the domain boundary (or the margin floor) is crossed: this chart ends there
                ch.frontier = True
                self._clip(ch, u, max(self._inside_fraction(ch.x, x_new) * step, 0.05 * ch.radius))
                return None
            if basis is not None:
                if step < ch.radius * (1 - 1e-9):
                    self.shrink(i, step)
                j = self.add_chart(x_new, radius=min(self.radius, 2.0 * step), basis=basis)
                ch.domain.drop(u)
                return j
            step *= 0.5
        ch.frontier = True
        self._clip(ch, u, ch.radius)
        ch.domain.drop(u)
        return None

    def shrink(self, i, radius):
        """The manifold curves too much for chart i's radius: make its ball the radius at
        which a new chart could be made, so that small neighbours can close it."""
        ch = self.charts[i]
        before = ch.domain.nbytes
        ch.domain.set_radius(radius)
        self._radii.rows[i] = radius
        self.nbytes += ch.domain.nbytes - before
        for j in list(ch.neighbours):  # balls that no longer overlap are no longer linked
            other = self.charts[j]
            if np.linalg.norm(self.diff(ch.x, other.x)) >= radius + other.radius:
                ch.neighbours.discard(j)
                other.neighbours.discard(i)

    def _inside_fraction(self, x0, x1):
        """Fraction of the chord x0 -> x1 (x0 inside the domain) before it leaves the domain:
        exact for the box; where only the predicate ``inside`` fails, its boundary found by
        bisection on the chord to 1/16."""
        if self._inside is not None and self._in_box(x1):
            lo, hi, d = 0.0, 1.0, self.diff(x0, x1)
            for _ in range(4):
                mid = 0.5 * (lo + hi)
                lo, hi = (mid, hi) if self._inside(x0 + mid * d) else (lo, mid)
            return lo
        d = self.diff(x0, x1)
        free = ~self.periodic
        t = 1.0
        with np.errstate(divide="ignore", invalid="ignore"):
            for bound, sign in ((self.c.lower, -1.0), (self.c.upper, 1.0)):
                over = free & (sign * (x1 - bound) > 0)
                if over.any():
                    t = min(t, float(np.min((bound[over] - x0[over]) / d[over])))
        return max(t, 0.0)

    def _acceptable_basis(self, ch, s, x_new, step):
        """The tangent basis at x_new if the manifold is flat enough between, else None."""
        if np.linalg.norm(self.diff(ch.x + ch.basis @ s, x_new)) > self.epsilon * step:
            return None
        basis_new = self.tangent_basis(x_new)
        sv = np.linalg.svd(ch.basis.T @ basis_new, compute_uv=False)
        return basis_new if sv.min() >= self.cos_max_angle else None

    def closest(self, x, k_radius=None):
        """Indices of charts whose centre is within (wrapped) distance of its radius of x."""
        near, _, dist = self._near(x, self.c.key(x), self.radius if k_radius is None else k_radius)
        return near[dist < self._radii.rows[near]].tolist()

    def segment(self, i, j, n_points, first=None):
        """Points on M from the centre of chart i to that of its neighbour j: the first half
        projected from i's tangent space, the second from j's. None if Newton fails, or if
        the point ``first`` (an index, projected before the others) fails ``in_domain``:
        a link that crosses an obstacle mostly does so in its middle, and then the other
        points need no Newton."""
        si = self.coordinates(i, self.charts[j].x)
        sj = self.coordinates(j, self.charts[i].x)
        ts = np.linspace(0.0, 1.0, n_points)
        pts = [None] * n_points
        order = list(range(n_points)) if first is None else \
            [first] + [k for k in range(n_points) if k != first]
        for k in order:
            t = ts[k]
            x = self.psi(i, t * si) if t <= 0.5 else self.psi(j, (1.0 - t) * sj)
            if x is None or (k == first and not self.in_domain(x)):
                return None
            pts[k] = x
        return pts

    def edge_points(self, a, b, spacing=0.25):
        """Points on M from chart a's centre to chart b's, about ``spacing`` chart radii
        apart (cached: charts never move); None if the link does not carry a path (Newton
        failed, a point left the domain, or the points jumped)."""
        key = (min(a, b), max(a, b))
        if key not in self._edges:
            self._edges[key] = self._edge_points(*key, spacing)
            if self._edges[key] is not None:
                self.nbytes += sum(x.nbytes for x in self._edges[key])
        pts = self._edges[key]
        return None if pts is None else (pts if a < b else pts[::-1])

    def _edge_points(self, a, b, spacing):
        gap = np.linalg.norm(self.diff(self.charts[a].x, self.charts[b].x))
        n = max(3, int(math.ceil(gap / (spacing * self.radius))) + 1)
        pts = self.segment(a, b, n, first=n // 2)
        if pts is None or not self._all_in_domain(pts):
            return None
        steps = [np.linalg.norm(self.diff(u, v)) for u, v in zip(pts, pts[1:])]
        return pts if max(steps) <= 3.0 * gap / (n - 1) + 1e-12 else None

    def unlink(self, i, j):
        """Charts i and j are no longer neighbours (their link was found not to carry a path)."""
        self.charts[i].neighbours.discard(j)
        self.charts[j].neighbours.discard(i)
        self._edges.pop((min(i, j), max(i, j)), None)

    def chart_at(self, x):
        """The chart centred at x (a point on M), made if there is none."""
        for j in self.closest(x):
            if np.linalg.norm(self.diff(self.charts[j].x, x)) < 1e-9:
                return j
        return self.add_chart(x)

    # ----- what a sampling search needs ---------------------------------------------------
    def owner(self, x):
        """The chart whose domain holds x (nearest centre first), or None."""
        near = self.closest(x, k_radius=2.0 * self.radius)
        near.sort(key=lambda j: float(np.linalg.norm(self.diff(self.charts[j].x, x))))
        for j in near:
            if self.charts[j].domain.contains(self.coordinates(j, x))[0]:
                return j
        return None

    def sample(self, i, rng, tries=32):
        """A random point of M in chart i's domain (uniform in tangent coordinates), or
        None if ``tries`` draws all fell outside it or Newton failed."""
        ch = self.charts[i]
        n = ch.basis.shape[1]
        g = rng.standard_normal((tries, n))
        s = g / np.linalg.norm(g, axis=1, keepdims=True) * ch.radius * rng.random((tries, 1)) ** (1.0 / n)
        for si in s[ch.domain.contains(s)]:
            x = self.psi(i, si)
            if x is not None and self.in_domain(x):
                return x
        return None

    def traverse(self, x_a, x_b, step=None, max_steps=1000):
        """A discrete geodesic from x_a towards x_b (OMPL's discreteGeodesic): steps of at
        most ``step`` (default r / 4) in the tangent space at the current point, each
        projected onto M. Returns (points, reached): the walk stops where Newton fails, the
        domain is left or the distance to x_b stops decreasing."""
        step = 0.25 * self.radius if step is None else step
        pts = [np.asarray(x_a, dtype=float)]
        dist = np.linalg.norm(self.diff(pts[0], x_b))
        for _ in range(max_steps):
            if dist <= step:
                return pts + [np.asarray(x_b, dtype=float)], True
            x = pts[-1]
            basis = self.tangent_basis(x)
            s = basis.T @ self.diff(x, x_b)
            norm = np.linalg.norm(s)
            if norm < 1e-12:
                break
            s *= min(step, dist) / norm
            x_new = self.newton(x, basis, s, x + basis @ s)
            if x_new is None or not self.in_domain(x_new):
                break
            x_new = self.wrap(x_new)
            d_new = np.linalg.norm(self.diff(x_new, x_b))
            if d_new >= dist:
                break
            pts.append(x_new)
            dist = d_new
        return pts, False


class _Rows:
    """A growable array of rows (capacity doubles): ``rows`` is the filled part, a view."""

    def __init__(self):
        self._a = None
        self.n = 0

    def add(self, row):
        row = np.asarray(row, dtype=float)
        if self._a is None:
            self._a = np.empty((64,) + row.shape)
        elif self.n == self._a.shape[0]:
            self._a = np.concatenate([self._a, np.empty_like(self._a)])
        self._a[self.n] = row
        self.n += 1

    @property
    def rows(self):
        return self._a[:self.n] if self._a is not None else np.empty((0,))


class _KeyIndex:
    """Chart centres' keys for fixed-radius queries: a k-d tree of the keys up to the last
    rebuild plus a brute-force tail of those added since, rebuilt when the tail passes
    TAIL_MIN or 1/TAIL_FRACTION of the tree (a query costs O(log N + tail), an insertion
    O(log N) amortised). The union is exact: every key within the radius, tree or tail."""

    TAIL_MIN = 128
    TAIL_FRACTION = 8

    def __init__(self):
        self.keys = _Rows()
        self.tree = None
        self.n_tree = 0

    def add(self, key):
        self.keys.add(key)
        if self.keys.n - self.n_tree > max(self.TAIL_MIN, self.n_tree // self.TAIL_FRACTION):
            from scipy.spatial import cKDTree  # here, not at import: start-up time

            self.tree = cKDTree(self.keys.rows.copy())
            self.n_tree = self.keys.n

    def query(self, key, radius):
        """Indices (insertion order numbers) of the keys within ``radius`` of ``key``."""
        found = self.tree.query_ball_point(key, radius) if self.tree is not None else []
        if self.keys.n > self.n_tree:
            tail = self.keys.rows[self.n_tree:]
            near = np.flatnonzero(np.linalg.norm(tail - key, axis=1) <= radius) + self.n_tree
            found = list(found) + near.tolist()
        return found


def _wrap_angle(a):
    """Angles to [-pi, pi) (the atlas's own: it imports nothing of the robot model)."""
    return (a + np.pi) % TWO_PI - np.pi
