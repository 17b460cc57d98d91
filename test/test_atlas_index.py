"""The atlas' spatial index: its neighbour sets are exactly the brute-force ones (random
charts, periodic coordinates across the seam, after batches of insertions that cross tree
rebuilds), and a search restarted on a cut link reuses what it computed."""

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from cdh_planner.atlas.charts import Atlas, _KeyIndex
from cdh_planner.atlas.domain import SampledDomain
from cdh_planner.search.strategies import Stop, run
from cdh_planner.status import Status


class Wave:
    """A 2-D manifold in R^3 for the atlas alone: x2 = A sin(x0) + B x1, x0 2 pi periodic
    (duck-typed like TaskConstraint)."""

    n_vars, dim = 3, 2
    periodic = np.array([True, False, False])
    lower = np.array([-np.inf, -3.0, -10.0])
    upper = np.array([np.inf, 3.0, 10.0])
    A, B = 0.3, 0.2

    def residual_and_jacobian(self, x):
        F = np.array([x[2] - self.A * np.sin(x[0]) - self.B * x[1]])
        return F, np.array([[-self.A * np.cos(x[0]), -self.B, 1.0]])

    def key(self, x):
        """1-Lipschitz: the chord of an angle is at most the angle."""
        return np.array([np.cos(x[0]), np.sin(x[0]), x[1], x[2]])

    def point(self, u, v):
        return np.array([u, v, self.A * np.sin(u) + self.B * v])


def brute_force_neighbours(atlas, i):
    ci = atlas.charts[i]
    return {j for j, cj in enumerate(atlas.charts)
            if j != i and np.linalg.norm(atlas.diff(ci.x, cj.x)) < ci.radius + cj.radius}


@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2 ** 32 - 1), batches=st.lists(st.integers(1, 150), min_size=1, max_size=6),
       dim=st.integers(1, 6))
def test_key_index_returns_exactly_the_keys_within_the_radius(seed, batches, dim):
    rng = np.random.default_rng(seed)
    index, keys = _KeyIndex(), []
    for size in batches:  # the tree is rebuilt between some batches: tree + tail must agree
        for key in rng.uniform(-1.0, 1.0, (size, dim)):
            index.add(key)
            keys.append(key)
        K = np.array(keys)
        for q in rng.uniform(-1.2, 1.2, (10, dim)):
            radius = rng.uniform(0.0, 1.0)
            want = set(np.flatnonzero(np.linalg.norm(K - q, axis=1) <= radius).tolist())
            assert set(index.query(q, radius)) == want
    assert index.n_tree > 0 or len(keys) <= _KeyIndex.TAIL_MIN


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2 ** 32 - 1), count=st.integers(2, 400))
def test_chart_neighbours_are_exactly_the_overlapping_balls(seed, count):
    """Charts with random centres (a third within 0.3 rad of the seam phi = +-pi) and
    random radii: each chart's neighbours are the charts whose balls overlap its own in the
    wrapped distance, and ``closest`` finds every chart whose ball holds a point."""
    rng = np.random.default_rng(seed)
    c = Wave()
    atlas = Atlas(c, radius=0.4)
    u = rng.uniform(-np.pi, np.pi, count)
    seam = rng.random(count) < 1 / 3
    u[seam] = np.pi + rng.uniform(-0.3, 0.3, seam.sum())  # wraps past pi
    v = rng.uniform(-1.0, 1.0, count)
    for k in range(count):
        atlas.add_chart(c.point(u[k], v[k]), radius=rng.uniform(0.05, 0.4))
    for i in range(count):
        assert atlas.charts[i].neighbours == brute_force_neighbours(atlas, i)
    for x in (c.point(a, b) for a, b in zip(rng.uniform(-4, 4, 20), rng.uniform(-1.0, 1.0, 20))):
        want = {j for j, ch in enumerate(atlas.charts) if np.linalg.norm(atlas.diff(ch.x, x)) < ch.radius}
        assert set(atlas.closest(x)) == want


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2 ** 32 - 1), n=st.integers(1, 6), m=st.integers(0, 300),
       reach=st.floats(0.0, 1.2))
def test_clipping_by_many_half_spaces_at_once_is_clipping_one_after_another(seed, n, m, reach):
    """A new chart is clipped by all its neighbours in one product: the same free
    directions and the same half-spaces (up to the one that closes it) as one clip after
    another that stops once the domain is closed."""
    rng = np.random.default_rng(seed)
    A = rng.standard_normal((m, n))
    A /= np.linalg.norm(A, axis=1, keepdims=True)
    betas = rng.uniform(0.05, reach + 0.05, m)  # small reach: the domain closes part-way
    one, many = SampledDomain(n, 0.5, 96), SampledDomain(n, 0.5, 96)
    for a, beta in zip(A, betas):
        if one.closed:
            break
        one.clip(a, beta)
    many.clip_many(A, betas)
    np.testing.assert_array_equal(many.alive, one.alive)
    assert many.halfspaces.count == one.halfspaces.count
    np.testing.assert_array_equal(many.halfspaces.a[:many.halfspaces.count], one.halfspaces.a[:one.halfspaces.count])
    np.testing.assert_array_equal(many.halfspaces.beta[:many.halfspaces.count],
                                  one.halfspaces.beta[:one.halfspaces.count])
    assert many.nbytes == one.nbytes


def test_neighbours_stay_exact_as_charts_grow_and_shrink():
    """The atlas grown by expansion (charts made at the frontier, balls shrunk where the
    manifold curves, the index rebuilt several times): links are the overlapping balls."""
    c = Wave()
    c.A = 2.0  # curved enough that some steps halve and charts shrink
    atlas = Atlas(c, radius=0.5)
    atlas.add_chart(c.point(3.0, 0.0))
    for _ in range(600):
        open_charts = [ch.index for ch in atlas.charts if not ch.closed]
        if not open_charts:
            break
        atlas.expand(open_charts[0])
    assert atlas._index.n_tree > _KeyIndex.TAIL_MIN  # rebuilt more than once
    assert any(ch.radius < atlas.radius for ch in atlas.charts)
    for i in range(len(atlas.charts)):
        # shrinking only removes links: every link is an overlap, and an overlap of two
        # balls at their radii when the later chart was made is a link
        assert atlas.charts[i].neighbours <= brute_force_neighbours(atlas, i)
        for j in atlas.charts[i].neighbours:
            assert i in atlas.charts[j].neighbours
    rows = np.array([ch.x for ch in atlas.charts])
    np.testing.assert_array_equal(atlas._centres.rows, rows)
    np.testing.assert_array_equal(atlas._radii.rows, [ch.radius for ch in atlas.charts])


def test_a_restarted_search_reuses_its_heuristic_and_link_checks():
    """A cut link restarts the search: h of a chart and the check of a link are computed
    once per query, however many restarts (they were recomputed at each: the query slowed
    as the atlas grew)."""
    c = Wave()
    atlas = Atlas(c, radius=0.3)
    calls = {"h": 0, "link": 0}
    bad = {"left": 3}

    def heuristic(xa, xb):
        calls["h"] += 1
        return float(np.linalg.norm(atlas.diff(xa, xb)))

    def link_ok(points):
        calls["link"] += 1
        if bad["left"] and len(points) > 2:  # cut the first three links checked
            bad["left"] -= 1
            return False
        return True

    xs, xg = c.point(-1.0, 0.0), c.point(1.0, 0.5)
    out = run(atlas, xs, xg, heuristic, Stop(max_charts=5000), "gbf", link_ok=link_ok)
    assert out.status == Status.OK
    n_links = sum(len(ch.neighbours) for ch in atlas.charts) // 2 + 3  # + the cut ones
    assert calls["link"] <= n_links
    assert calls["h"] <= 2 * len(atlas.charts) + 2 * len(out.charts)  # per side, + route costs


def test_a_route_motion_the_caller_refuses_cuts_its_link_and_the_search_goes_on():
    """route_check names motion k of a route: the link that made it is cut and the
    search answers with a route whose every motion passes."""
    c = Wave()
    atlas = Atlas(c, radius=0.3)
    refused = []

    def route_check(points, direct):
        for k in range(len(points) - 1):
            if len(refused) < 2 and k not in direct:  # refuse the first motion, twice
                refused.append((points[k].copy(), points[k + 1].copy()))
                return k
        return None

    def cost(xa, xb):
        return float(np.linalg.norm(atlas.diff(xa, xb)))

    xs, xg = c.point(-1.0, 0.0), c.point(1.0, 0.5)
    out = run(atlas, xs, xg, cost, Stop(max_charts=5000), "gbf", route_check=route_check)
    assert out.status == Status.OK and len(refused) == 2
    for a, b in refused:  # no motion the caller refused is in the answer
        assert not any(np.array_equal(a, p) and np.array_equal(b, q) for p, q in zip(out.points, out.points[1:]))
    for i, j in zip(out.charts, out.charts[1:]):
        assert j in atlas.charts[i].neighbours


def crosses_wall(p, q, gap=1.0):
    """Does the chord p -> q cross the wall x0 = 0 below x1 = gap (short arcs only)?"""
    if (p[0] < 0) == (q[0] < 0) or abs(p[0] - q[0]) > np.pi:
        return False
    t = p[0] / (p[0] - q[0])
    return p[1] + t * (q[1] - p[1]) < gap


def test_sides_that_meet_across_a_wall_cut_that_link_and_go_on(monkeypatch):
    """``check_meetings``: the link where the two sides meet is checked before the search
    answers; across a thin wall (which no chart centre is in, but charts overlap) that link
    is cut and the same search goes on; a restart walks the charts there are before it
    grows more. The answer never crosses the wall, and it needs fewer searches and fewer
    charts than finding each such link in a route and restarting from the roots."""
    from cdh_planner.search import strategies

    def link_ok(points):
        return not any(crosses_wall(p, q) for p, q in zip(points, points[1:]))

    searches, charts = {}, {}
    for check in (False, True):
        c = Wave()
        atlas = Atlas(c, radius=0.3)
        count = [0]
        inner = strategies.Bidirectional.run

        def counted(self, *args, count=count, inner=inner):
            count[0] += 1
            return inner(self, *args)

        monkeypatch.setattr(strategies.Bidirectional, "run", counted)
        xs, xg = c.point(-0.5, 0.0), c.point(0.5, 0.0)
        cost = lambda a, b, atlas=atlas: float(np.linalg.norm(atlas.diff(a, b)))
        out = run(atlas, xs, xg, cost, Stop(max_charts=5000), "gbf", link_ok=link_ok,
                  check_meetings=check)
        assert out.status == Status.OK
        assert not any(crosses_wall(p, q) for p, q in zip(out.points, out.points[1:]))
        assert max(p[1] for p in out.points) >= 1.0  # through the gap
        searches[check], charts[check] = count[0], len(atlas.charts)
        monkeypatch.undo()
    assert searches[True] < searches[False] and charts[True] < charts[False]


def test_a_walk_grows_no_chart():
    """A restart's walk answers from the charts there are: a route when they hold one, else
    NO_PATH, and never a new chart."""
    from cdh_planner.search.strategies import Bidirectional, GreedyBestFirst, _Memo

    c = Wave()
    atlas = Atlas(c, radius=0.3)
    cost = lambda a, b: float(np.linalg.norm(atlas.diff(a, b)))
    i, j = atlas.add_chart(c.point(-1.0, 0.0)), atlas.add_chart(c.point(1.0, 0.0))
    walk = Bidirectional(atlas, cost, GreedyBestFirst(), None, None, _Memo({}), walk=True)
    assert walk.run(i, j, Stop())[0] == Status.NO_PATH and len(atlas.charts) == 2
    out = run(atlas, atlas.charts[i].x, atlas.charts[j].x, cost, Stop(max_charts=5000), "gbf")
    assert out.status == Status.OK
    n = len(atlas.charts)
    walk = Bidirectional(atlas, cost, GreedyBestFirst(), None, None, _Memo({}), walk=True)
    status, route, _ = walk.run(i, j, Stop())
    assert status == Status.OK and route[0] == i and route[-1] == j and len(atlas.charts) == n
    assert all(b in atlas.charts[a].neighbours for a, b in zip(route, route[1:]))
