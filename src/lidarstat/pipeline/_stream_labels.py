"""Label fields of a tiled run: ids unique over the area, joined across tiles.

A label field (``segment_id``, ``ridge_line``; 0 = none) numbers what a method found in
one tile from 1. The tiled runs give every tile's labels a *node* number unique over the
area (the tile's base plus its label) and, for a field that is *joined*, record the
labels of the points that two tiles share (a point of one tile's halo or buffer is a
core point of another): two labels of neighbouring tiles name one thing when they hold
the same shared points. One file in square tiles
(:func:`lidarstat.pipeline.process_file`) and a catalogue of tile files
(:func:`lidarstat.pipeline.process_catalogue`, a point named by its file and its place
in the file) use the same records (:data:`LINK`), the same nodes (:class:`Labels`) and
the same rule.

The rule, for labels ``a`` of tile T and ``b`` of tile U: ``n(a, b)`` points of the
overlap of T and U are labelled ``a`` by T and ``b`` by U, ``s(a, U)`` points of that
overlap are labelled ``a`` by T (whatever U says), ``s(b, T)`` likewise. ``a`` and ``b``
are joined when ``n(a, b)`` is at least half of ``s(a, U)`` and at least half of
``s(b, T)``: most of the overlap of each is the other. A surface crossing a tile border
is labelled in both tiles' runs on the points of the overlap (the halo is as wide as the
method's reach), so its two labels are joined; two surfaces meeting at a border share
only their boundary points, and stay apart, as does a sliver of a surface that just
enters the overlap and that the other tile gives to its neighbour (the rule asks a
majority on both sides, so a join never rests on a few points). Where two tiles cut one
surface differently (one label in T, two in U, each with less than half of T's), the
surface keeps one id per tile, cut at the border. Joined labels are connected
components over the area (``scipy.sparse.csgraph``), numbered 1.. in the order of their
first node, counting only those with a core point.

Memory: the records of the shared points (25 bytes each), and per node two integers;
nothing per point of a tile's interior.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: A shared point's label in one tile: point number (unique over the area), node, tile
#: (the run's tile number), core flag.
LINK = np.dtype([("i", "<i8"), ("node", "<i8"), ("tile", "<i8"), ("core", "u1")])


@dataclass(frozen=True)
class LabelMap:
    """The final ids of one label field of a tiled run.

    Attributes
    ----------
    final : (n_nodes + 1,) ndarray of int64
        Id written for each node (a tile's base plus its label; node 0 is "none").
    core_points : (n_nodes + 1,) ndarray of int64
        Core points (written points) of each node.
    """

    final: np.ndarray
    core_points: np.ndarray

    def __call__(self, nodes) -> np.ndarray:
        """The final ids of `nodes`."""
        return self.final[np.asarray(nodes, dtype=np.int64)]


class Labels:
    """Node numbers, core counts and shared points of one label field over the tiles."""

    def __init__(self, name: str, join: bool):
        self.name = name
        self.join = join
        self.next = 0  # nodes used so far (node 0 = none)
        self.counts = np.zeros(1, np.int64)

    def add_tile(self, top: int, core_counts) -> int:
        """Nodes for one tile's labels ``1..top``; `core_counts` ``(top + 1,)`` its core
        points per label (label 0 ignored). Returns the tile's base: node = base + label."""
        base = self.next
        top = max(int(top), 0)
        self.next += top
        if self.counts.size < self.next + 1:
            grown = np.zeros(max(self.next + 1, 2 * self.counts.size), np.int64)
            grown[:self.counts.size] = self.counts
            self.counts = grown
        counts = np.asarray(core_counts, dtype=np.int64)[1:top + 1]
        self.counts[base + 1:base + 1 + counts.size] += counts
        return base

    def finish(self, links: np.ndarray | None) -> LabelMap:
        """The final ids: nodes joined over the shared points `links` (LINK records)."""
        n = self.next + 1
        counts = np.zeros(n, np.int64)
        counts[:min(n, self.counts.size)] = self.counts[:n]
        if not self.join:  # unique over the file, not joined
            return LabelMap(np.arange(n, dtype=np.int64), counts)
        comp = _components(links, n) if links is not None and len(links) else np.arange(n)
        present = np.bincount(comp, weights=counts, minlength=int(comp.max()) + 1) > 0
        present[comp[0]] = False  # node 0: none
        rank = np.zeros(present.size, np.int64)
        rank[present] = np.arange(1, int(present.sum()) + 1)
        final = rank[comp]
        final[0] = 0
        return LabelMap(final, counts)


def _components(links: np.ndarray, n: int) -> np.ndarray:
    """Connected components of the nodes joined by the rule of the module docstring."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    core = links[links["core"] == 1]
    halo = links[links["core"] == 0]
    if not len(core) or not len(halo):
        return np.arange(n)
    core = core[np.argsort(core["i"], kind="stable")]
    at = np.minimum(np.searchsorted(core["i"], halo["i"]), len(core) - 1)
    ok = core["i"][at] == halo["i"]
    x, tx = halo["node"][ok], halo["tile"][ok]
    y, ty = core["node"][at[ok]], core["tile"][at[ok]]
    ntile = int(max(tx.max(initial=0), ty.max(initial=0))) + 1
    # s(node, other tile): shared points of the node's tile and the other tile it holds
    sx = np.r_[x[x > 0] * ntile + ty[x > 0], y[y > 0] * ntile + tx[y > 0]]
    skeys, scounts = np.unique(sx, return_counts=True)
    both = (x > 0) & (y > 0)
    lo, hi = np.minimum(x[both], y[both]), np.maximum(x[both], y[both])
    pairs, n_ab = np.unique(np.c_[lo, hi], axis=0, return_counts=True)
    if not len(pairs):
        return np.arange(n)
    a, b = pairs[:, 0], pairs[:, 1]
    tile_of = np.zeros(n, np.int64)  # the tile of each node that appears in a pair
    tile_of[x[x > 0]] = tx[x > 0]
    tile_of[y[y > 0]] = ty[y > 0]

    def s(node, other):
        return scounts[np.searchsorted(skeys, node * ntile + other)]

    keep = 2 * n_ab >= np.maximum(s(a, tile_of[b]), s(b, tile_of[a]))
    graph = coo_matrix((np.ones(int(keep.sum())), (a[keep], b[keep])), shape=(n, n))
    return connected_components(graph, directed=False)[1]
