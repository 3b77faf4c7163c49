"""Approximate nearest neighbours by squared Euclidean distance: faiss's HNSW graph.

``best``'s novelty cues need, for every query, its nearest training samples. Exact search
compares a query with every stored sample: linear in the number of objects per query and
quadratic for the whole training set's own spacings. Above a size threshold
(``BestRecognizer.approximate_above``) a hierarchical navigable small-world graph (Malkov
and Yashunin, 2018, as faiss implements it) answers in about log time: it returns the true
nearest sample ~99 % of the time and otherwise a near one, and the distances it returns
are exact for the samples it returns. The graph is stored in model bundles as faiss's own
serialisation (a byte array, not a pickle), so a loaded model answers as the fitted one.

Points learnt after the graph was built (a promotion's samples) are not inserted into it:
an insertion rewrites links all through the graph, so the stored index would be new bytes
(tens of MB at 10,000 objects) for every promotion. They are the ``tail`` of the
reference, searched exactly and merged with the graph's answer, until the tail outgrows
``TAIL_POINTS`` or ``TAIL_SHARE`` of the graph; then a copy of the graph takes them in.
"""

from __future__ import annotations

import numpy as np

from app.framework.growing import WhileAlive

#: links per node (faiss's M), candidates kept while building and while searching
GRAPH_LINKS, BUILD_CANDIDATES, SEARCH_CANDIDATES = 32, 64, 32
#: points searched exactly beside the graph before a copy of it takes them in
TAIL_POINTS, TAIL_SHARE = 4096, 0.05


class ApproximateNeighbours:
    """An HNSW index over the first points of a reference (N, d) float32, the rest of them
    (the tail) searched exactly; ``search`` gives squared distances and ids into it."""

    def __init__(self, index, points: np.ndarray) -> None:
        n, dim = points.shape
        if index.ntotal > n or index.d != dim:
            raise ValueError(
                f"the neighbour index holds {index.ntotal} points of {index.d} dimensions, "
                f"the reference {n} of {dim}"
            )
        index.hnsw.efSearch = SEARCH_CANDIDATES
        self.index = index
        self.tail = np.ascontiguousarray(points[index.ntotal :], np.float32)
        # what every search reads of the tail, once: converting and squaring it per query
        # took most of a search's 5 ms against a tail of 15,000 points (the bound at 30,000
        # objects), 0.2 ms without, on the Xeon VM
        self._tail64 = self.tail.astype(np.float64)
        self._tail_sq = (self._tail64**2).sum(axis=1)
        # its serialisation, once: the index never changes (``with_points`` makes a copy),
        # and every model version stored is split again (tens of MB at 10,000 objects)
        self._bytes: np.ndarray | None = None

    @classmethod
    def build(cls, points: np.ndarray) -> ApproximateNeighbours:
        import faiss

        points = np.ascontiguousarray(points, np.float32)
        index = faiss.IndexHNSWFlat(points.shape[1], GRAPH_LINKS)
        index.hnsw.efConstruction = BUILD_CANDIDATES
        index.add(points)
        return cls(index, points)

    def with_points(self, points: np.ndarray) -> ApproximateNeighbours:
        """This index over ``points``, which begin with the points it was built on: the same
        graph with a longer tail, or, once the tail outgrows its bound, a copy of the graph
        that has taken the tail in (this one unchanged)."""
        index = self.index
        tail = points[index.ntotal :]
        if len(tail) > max(TAIL_POINTS, TAIL_SHARE * index.ntotal):
            import faiss

            index = faiss.clone_index(index)
            index.add(np.ascontiguousarray(tail, np.float32))
        out = ApproximateNeighbours(index, points)
        if index is self.index:
            out._bytes = self.to_bytes()  # the same graph: the same stored part
        return out

    def search(self, queries: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(squared distances (N, k) float64 ascending, ids (N, k); -1 and inf where the
        index holds fewer than k points): the graph's k nearest and the tail's, merged."""
        q = np.ascontiguousarray(queries, np.float32)
        d2, ids = self.index.search(q, k)
        d2 = np.where(ids < 0, np.inf, np.maximum(d2.astype(np.float64), 0.0))
        if not len(self.tail):
            return d2, ids
        # |q - t|^2 from products: (N, T) memory, where the differences took N x T x d (a
        # GB for a batch of 1,024 against a full tail)
        q64 = q.astype(np.float64)
        tail_d2 = np.maximum(
            (q64**2).sum(axis=1)[:, None] + self._tail_sq[None, :] - 2.0 * q64 @ self._tail64.T,
            0.0,
        )
        tail_ids = np.broadcast_to(self.index.ntotal + np.arange(len(self.tail)), tail_d2.shape)
        d2, ids = np.concatenate([d2, tail_d2], axis=1), np.concatenate([ids, tail_ids], axis=1)
        order = np.argsort(d2, axis=1, kind="stable")[:, :k]
        return np.take_along_axis(d2, order, axis=1), np.take_along_axis(ids, order, axis=1)

    def to_bytes(self) -> np.ndarray:
        """faiss's serialisation, read-only: the same array on every call."""
        if self._bytes is None:
            import faiss

            data = faiss.serialize_index(self.index)
            data.flags.writeable = False
            self._bytes = data
        return self._bytes

    @classmethod
    def from_bytes(cls, data: np.ndarray, points: np.ndarray) -> ApproximateNeighbours:
        """The index ``to_bytes`` stored, over ``points`` (its graph's first, then its tail)."""
        import faiss

        data = np.ascontiguousarray(data, np.uint8)
        if data.ndim != 1:
            raise ValueError("the neighbour index must be a 1-d byte array")
        stored = not data.flags.writeable  # a store's part: it is the serialisation, unchanged
        index = _GRAPHS.get(data) if stored else None
        if index is None:
            try:
                index = faiss.deserialize_index(data)
            except RuntimeError as exc:
                raise ValueError(f"the neighbour index cannot be read: {exc}") from None
            if not hasattr(index, "hnsw"):
                raise ValueError("the neighbour index is not an HNSW index")
        out = cls(index, points)
        if stored:
            out._bytes = data
            _GRAPHS.put(data, index)
        return out


#: graphs read from a store's parts in this process, by the part's array (while it lives):
#: a promotion that kept the graph stores the same part (``with_points``), and the process
#: that loads that version takes the graph it read for the version before (reading it again
#: took 0.7 s at 10,000 objects). A graph is never changed once built, so versions share it.
_GRAPHS = WhileAlive()
