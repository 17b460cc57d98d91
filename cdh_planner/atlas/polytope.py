"""Convex polytopes in a chart's tangent space, kept as vertices with facet incidences.

Henderson's multiple-hypercube atlas starts each chart's domain as the cube of side 2r and
clips it by half-spaces {s : a . s <= beta}. Vertices carry the set of facets they lie on
(an incidence matrix), so clipping finds the cut edges as pairs of vertices, one on each side, that
share n - 1 facets (exact for simple polytopes; degenerate extra vertices stay inside).
"""

import itertools

import numpy as np

EPS = 1e-10
_HASH = np.random.default_rng(0).uniform(1.0, 2.0, 16)


class Polytope:
    """Cube [-r, r]^n clipped by half-spaces; ``vertices`` (V, n), ``incidence`` (V, F)
    bool: which facets each vertex lies on (facets no vertex lies on are dropped)."""

    def __init__(self, n, r):
        self.n = n
        signs = np.array(list(itertools.product((1.0, -1.0), repeat=n)))
        self.vertices = r * signs
        # facet 2k: s_k <= r, facet 2k + 1: -s_k <= r
        self.incidence = np.zeros((signs.shape[0], 2 * n), dtype=bool)
        for k in range(n):
            self.incidence[:, 2 * k] = signs[:, k] > 0
            self.incidence[:, 2 * k + 1] = signs[:, k] < 0

    def clip(self, a, beta):
        """Intersect with {s : a . s <= beta}; returns True if any vertex was removed."""
        side = self.vertices @ a - beta
        tol = EPS * max(1.0, abs(beta))
        outside = side > tol
        if not outside.any():
            return False
        on_plane = np.abs(side) <= tol
        strict = ~outside & ~on_plane
        # cut edges: a vertex strictly inside and one outside that share n - 1 facets
        # only facets of outside vertices matter, and only inside vertices on n - 1 of them
        out_idx = np.flatnonzero(outside)
        cols = self.incidence[out_idx].any(axis=0)
        inc_out = self.incidence[np.ix_(out_idx, cols)]
        cand = np.flatnonzero(strict)
        inc_in = self.incidence[np.ix_(cand, cols)]
        near = inc_in.sum(axis=1) >= self.n - 1
        cand, inc_in = cand[near], inc_in[near]
        shared = inc_in.astype(np.float32) @ inc_out.T.astype(np.float32)  # BLAS
        ii, jj = np.nonzero(shared >= self.n - 1.5)
        vi, vo = cand[ii], out_idx[jj]
        t = (-side[vi] / (side[vo] - side[vi]))[:, None]
        new_v = self.vertices[vi] + t * (self.vertices[vo] - self.vertices[vi])
        new_inc = self.incidence[vi] & self.incidence[vo]
        keep = ~outside
        verts = np.concatenate([self.vertices[keep], new_v], axis=0)
        inc = np.concatenate([self.incidence[keep], new_inc], axis=0)
        facet = np.concatenate([on_plane[keep], np.ones(new_v.shape[0], dtype=bool)])
        inc = np.concatenate([inc, facet[:, None]], axis=1)
        verts, inc = _merge_duplicates(verts, inc)
        self.vertices, self.incidence = verts, inc[:, inc.any(axis=0)]
        return True

    def close(self):
        """Give up on the rest of this polytope: no vertices, so the chart counts as closed."""
        self.vertices = self.vertices[:0]
        self.incidence = self.incidence[:0]

    def outside_vertices(self, r):
        """Indices of vertices outside the ball of radius r, farthest first."""
        norms = np.linalg.norm(self.vertices, axis=1)
        idx = np.flatnonzero(norms > r * (1.0 + 1e-6))
        return idx[np.argsort(-norms[idx])]


def _merge_duplicates(vertices, incidence, decimals=10):
    """Vertices that coincide (degenerate cuts) become one, on the union of their facets."""
    if vertices.shape[0] < 2:
        return vertices, incidence
    rounded = np.round(vertices, decimals)
    key = rounded @ _HASH[:vertices.shape[1]]  # 1-D keys: equal rows give equal keys
    if np.unique(key).size == key.size:
        return vertices, incidence
    _, first, inverse = np.unique(rounded, axis=0, return_index=True, return_inverse=True)
    if first.size == vertices.shape[0]:
        return vertices, incidence
    merged = np.zeros((first.size, incidence.shape[1]), dtype=bool)
    np.logical_or.at(merged, inverse.ravel(), incidence)
    return vertices[first], merged
