"""Convex polytopes in a chart's tangent space, kept as vertices with facet incidences.

Henderson's multiple-hypercube atlas starts each chart's domain as the cube of side 2r and
clips it by half-spaces {s : a . s <= beta}. Vertices carry the set of facets they lie on
(packed bits), so clipping finds the cut edges as pairs of vertices, one on each side, that
share n - 1 facets (exact for simple polytopes; degenerate extra vertices stay inside).
"""

import itertools

import numpy as np

EPS = 1e-10
# Weights of the rows' 1-D keys: numpy.random.default_rng(0).uniform(1.0, 2.0, 16), written
# out so that importing the atlas does not import numpy.random (~9 ms of a process's start);
# test_domains checks them against the generator.
_HASH = np.array((
    1.6369616873214543, 1.2697867137638703, 1.0409735239361946, 1.016527635528529,
    1.8132702392002724, 1.9127555772777218, 1.6066357757671799, 1.7294965609839985,
    1.543624991465423, 1.9350724237877683, 1.8158535541215322, 1.002738500170148,
    1.8574042765875693, 1.0335855753054644, 1.729655446429944, 1.175655620602559))


class Polytope:
    """Cube [-r, r]^n clipped by half-spaces; ``vertices`` (V, n); ``bits`` (V, W) uint64:
    the facets each vertex lies on, packed 64 to a word (facet k is bit k % 64 of word
    k // 64), so shared facets are counted with AND and popcount."""

    def __init__(self, n, r):
        self.n = n
        signs = np.array(list(itertools.product((1.0, -1.0), repeat=n)))
        self.vertices = r * signs
        # facet 2k: s_k <= r, facet 2k + 1: -s_k <= r
        bit = (2 * np.arange(n))[None, :] + (signs < 0)
        self.bits = np.bitwise_or.reduce(np.left_shift(np.uint64(1), bit.astype(np.uint64)),
                                         axis=1, keepdims=True).astype(np.uint64)
        self.n_facets = 2 * n

    def clip(self, a, beta):
        """Intersect with {s : a . s <= beta}; returns True if any vertex was removed."""
        side = self.vertices @ a - beta
        tol = EPS * max(1.0, abs(beta))
        outside = side > tol
        if not outside.any():
            return False
        on_plane = np.abs(side) <= tol
        word, bit = divmod(self.n_facets, 64)
        self.n_facets += 1
        if word == self.bits.shape[1]:
            self.bits = np.concatenate([self.bits, np.zeros((self.bits.shape[0], 1), np.uint64)], axis=1)
        facet = np.zeros(self.bits.shape[1], np.uint64)
        facet[word] = np.uint64(1) << np.uint64(bit)
        # cut edges: a vertex strictly inside and one outside that share n - 1 facets; only
        # the outside vertices' facets matter, and only inside vertices on n - 1 of them
        out_idx = np.flatnonzero(outside)
        out_bits = self.bits[out_idx]
        union = np.bitwise_or.reduce(out_bits, axis=0)
        cand = np.flatnonzero(~outside & ~on_plane)
        cand_bits = self.bits[cand] & union
        near = np.bitwise_count(cand_bits).sum(axis=1) >= self.n - 1
        cand, cand_bits = cand[near], cand_bits[near]
        shared = np.zeros((cand.size, out_idx.size), dtype=np.int32)
        for w in range(self.bits.shape[1]):
            shared += np.bitwise_count(cand_bits[:, w, None] & out_bits[None, :, w])
        ii, jj = np.nonzero(shared >= self.n - 1)
        vi, vo = cand[ii], out_idx[jj]
        t = (-side[vi] / (side[vo] - side[vi]))[:, None]
        new_v = self.vertices[vi] + t * (self.vertices[vo] - self.vertices[vi])
        new_bits = (self.bits[vi] & self.bits[vo]) | facet
        keep = ~outside
        kept_bits = self.bits[keep]
        kept_bits[on_plane[keep]] |= facet
        verts = np.concatenate([self.vertices[keep], new_v], axis=0)
        bits = np.concatenate([kept_bits, new_bits], axis=0)
        self.vertices, self.bits = _merge_duplicates(verts, bits)
        return True

    def close(self):
        """Give up on the rest of this polytope: no vertices, so the chart counts as closed."""
        self.vertices = self.vertices[:0]
        self.bits = self.bits[:0]

    def outside_vertices(self, r):
        """Indices of vertices outside the ball of radius r, farthest first."""
        norms = np.linalg.norm(self.vertices, axis=1)
        idx = np.flatnonzero(norms > r * (1.0 + 1e-6))
        return idx[np.argsort(-norms[idx])]


def _merge_duplicates(vertices, bits, decimals=10):
    """Vertices that coincide (degenerate cuts) become one, on the union of their facets."""
    if vertices.shape[0] < 2:
        return vertices, bits
    rounded = np.round(vertices, decimals)
    key = rounded @ _HASH[:vertices.shape[1]]  # 1-D keys: equal rows give equal keys
    if np.unique(key).size == key.size:
        return vertices, bits
    _, first, inverse = np.unique(rounded, axis=0, return_index=True, return_inverse=True)
    merged = np.zeros((first.size, bits.shape[1]), dtype=np.uint64)
    np.bitwise_or.at(merged, inverse.ravel(), bits)
    return vertices[first], merged
