"""Convex polytopes in a chart's tangent space, kept as vertices with facet incidences.

Henderson's multiple-hypercube atlas starts each chart's domain as the cube of side 2r and
clips it by half-spaces {s : a . s <= beta}. Vertices carry the set of facets they lie on
(a bit mask), so clipping finds the cut edges as pairs of vertices, one on each side, that
share n - 1 facets (exact for simple polytopes; degenerate extra vertices stay inside).
"""

import itertools

import numpy as np

EPS = 1e-10


class Polytope:
    """Cube [-r, r]^n clipped by half-spaces; ``vertices`` is (V, n)."""

    def __init__(self, n, r):
        self.n = n
        signs = np.array(list(itertools.product((1.0, -1.0), repeat=n)))
        self.vertices = r * signs
        # facet 2k: s_k <= r, facet 2k + 1: -s_k <= r
        self.masks = [sum(1 << (2 * k + int(sgn < 0)) for k, sgn in enumerate(row)) for row in signs]
        self.n_facets = 2 * n

    def clip(self, a, beta):
        """Intersect with {s : a . s <= beta}; returns True if any vertex was removed."""
        side = self.vertices @ a - beta
        tol = EPS * max(1.0, abs(beta))
        outside = side > tol
        if not outside.any():
            return False
        facet = 1 << self.n_facets
        self.n_facets += 1
        on_plane = np.abs(side) <= tol
        inside = np.flatnonzero(~outside)
        out_idx = np.flatnonzero(outside)
        new_v, new_m = [], []
        # cut edges: an inside vertex strictly inside and an outside one sharing n - 1 facets
        for i in np.flatnonzero(~outside & ~on_plane).tolist():
            mi = self.masks[i]
            for j in out_idx.tolist():
                shared = mi & self.masks[j]
                if shared.bit_count() >= self.n - 1:
                    t = -side[i] / (side[j] - side[i])
                    new_v.append(self.vertices[i] + t * (self.vertices[j] - self.vertices[i]))
                    new_m.append(shared | facet)
        keep_m = [self.masks[i] | (facet if on_plane[i] else 0) for i in inside.tolist()]
        verts = np.concatenate([self.vertices[inside]] + ([np.array(new_v)] if new_v else []), axis=0)
        self.vertices, self.masks = _merge_duplicates(verts, keep_m + new_m)
        return True

    def outside_vertices(self, r):
        """Indices of vertices outside the ball of radius r, farthest first."""
        norms = np.linalg.norm(self.vertices, axis=1)
        idx = np.flatnonzero(norms > r * (1.0 + 1e-6))
        return idx[np.argsort(-norms[idx])]


def _merge_duplicates(vertices, masks, decimals=10):
    """Vertices that coincide (degenerate cuts) become one, on the union of their facets."""
    if vertices.shape[0] < 2:
        return vertices, masks
    _, first, inverse = np.unique(np.round(vertices, decimals), axis=0, return_index=True,
                                  return_inverse=True)
    if first.size == vertices.shape[0]:
        return vertices, masks
    merged = [0] * first.size
    for k, g in enumerate(inverse.ravel().tolist()):
        merged[g] |= masks[k]
    return vertices[first], merged
