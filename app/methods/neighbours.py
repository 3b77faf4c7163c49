"""Approximate nearest neighbours by squared Euclidean distance: faiss's HNSW graph.

``best``'s novelty cues need, for every query, its nearest training samples. Exact search
compares a query with every stored sample: linear in the number of objects per query and
quadratic for the whole training set's own spacings. Above a size threshold
(``BestRecognizer.approximate_above``) a hierarchical navigable small-world graph (Malkov
and Yashunin, 2018, as faiss implements it) answers in about log time: it returns the true
nearest sample ~99 % of the time and otherwise a near one, and the distances it returns
are exact for the samples it returns. The graph is stored in model bundles as faiss's own
serialisation (a byte array, not a pickle), so a loaded model answers as the fitted one.
"""

from __future__ import annotations

import numpy as np

#: links per node (faiss's M), candidates kept while building and while searching
GRAPH_LINKS, BUILD_CANDIDATES, SEARCH_CANDIDATES = 32, 64, 32


class ApproximateNeighbours:
    """An HNSW index over ``points`` (N, d) float32; ``search`` gives squared distances."""

    def __init__(self, index, n_points: int, dim: int) -> None:
        if index.ntotal != n_points or index.d != dim:
            raise ValueError(
                f"the neighbour index holds {index.ntotal} points of {index.d} dimensions, "
                f"the reference {n_points} of {dim}"
            )
        index.hnsw.efSearch = SEARCH_CANDIDATES
        self.index = index
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
        return cls(index, *points.shape)

    def with_points(self, points: np.ndarray) -> ApproximateNeighbours:
        """A copy of this index with ``points`` added after its own (ids continue)."""
        import faiss

        index = faiss.clone_index(self.index)
        index.add(np.ascontiguousarray(points, np.float32))
        return ApproximateNeighbours(index, index.ntotal, index.d)

    def search(self, queries: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(squared distances (N, k) float64 ascending, ids (N, k); -1 and inf where the
        index holds fewer than k points)."""
        d2, ids = self.index.search(np.ascontiguousarray(queries, np.float32), k)
        d2 = np.where(ids < 0, np.inf, np.maximum(d2.astype(np.float64), 0.0))
        return d2, ids

    def to_bytes(self) -> np.ndarray:
        """faiss's serialisation, read-only: the same array on every call."""
        if self._bytes is None:
            import faiss

            data = faiss.serialize_index(self.index)
            data.flags.writeable = False
            self._bytes = data
        return self._bytes

    @classmethod
    def from_bytes(cls, data: np.ndarray, n_points: int, dim: int) -> ApproximateNeighbours:
        import faiss

        data = np.ascontiguousarray(data, np.uint8)
        if data.ndim != 1:
            raise ValueError("the neighbour index must be a 1-d byte array")
        try:
            index = faiss.deserialize_index(data)
        except RuntimeError as exc:
            raise ValueError(f"the neighbour index cannot be read: {exc}") from None
        if not hasattr(index, "hnsw"):
            raise ValueError("the neighbour index is not an HNSW index")
        out = cls(index, n_points, dim)
        if not data.flags.writeable:  # a store's part: it is the serialisation, unchanged
            out._bytes = data
        return out
