"""Candidate prototypes of each sample through faiss (``PrototypeSearch``).

The prototypes of a fit are indexed once: exactly (``IndexFlatL2`` over every coordinate)
while there are at most ``exact_below`` of them, else by an HNSW graph over the leading
``search_dims`` coordinates (the embedding puts the directions along which prototypes differ
most first), which hands ``RERANK`` x k candidates on. Either way each candidate's squared
distance is then computed exactly in every coordinate and the k nearest are kept, so the
approximate search can only miss a candidate, never mis-score one. Prototypes added later
(promotions without a refit) are kept beside the index and searched exactly, which costs
every sample a distance to each of them: once more than ``fold_above`` wait there, they are
folded into a copy of the index (the index the served model searches is never written), so
a backlog of promotions costs one copy and insertion per ``fold_above`` of them instead of a
brute-force search that grows with each (``bench/grown_backlog.py``).
"""

from __future__ import annotations

import numpy as np

from app.framework.growing import appended

#: the approximate search hands this many times ``k`` candidates to the exact re-ranking:
#: its leading coordinates alone rank the true k nearest lower than k now and then
RERANK = 4
_ROWS = 256  # query rows scored at a time


class PrototypeSearch:
    """The ``k`` nearest prototypes of each sample (module docstring).

    Parameters
    ----------
    points : (S, D) float32
        the prototypes of the fit, in the embedding's coordinates.
    exact_below : int
        at most this many prototypes are searched exactly; more take the HNSW graph.
    search_dims : int
        coordinates the HNSW graph is built on (every one if fewer).
    hnsw_links : int
        links per node of the graph (faiss's ``M``).
    ef_search : int
        candidates the graph search keeps (faiss's ``efSearch``).
    fold_above : int
        prototypes added later (``with_points``) are searched exactly beside the index while
        there are at most this many; past it they are folded into a copy of the index.
    """

    def __init__(
        self,
        points: np.ndarray,
        exact_below: int = 4096,
        search_dims: int = 64,
        hnsw_links: int = 32,
        ef_search: int = 128,
        index: np.ndarray | None = None,
        fold_above: int = 256,
    ) -> None:
        import faiss

        if int(fold_above) < 0:
            raise ValueError(f"fold_above must be a non-negative integer, got {fold_above!r}")
        self.fold_above = int(fold_above)
        self.points = np.ascontiguousarray(points, np.float32)
        if index is not None:  # a stored index (``index_bytes``): read, not built again
            self.index = faiss.deserialize_index(np.asarray(index, np.uint8))
            self.exact = not isinstance(self.index, faiss.IndexHNSW)
            self.dims = self.index.d
            if self.index.ntotal != len(self.points) or self.dims > self.points.shape[1]:
                raise ValueError("the stored prototype index does not match the prototypes")
            self.extra = np.zeros((0, self.points.shape[1]), np.float32)
            return
        self.exact = len(self.points) <= exact_below
        d = self.points.shape[1]
        self.dims = d if self.exact else min(d, search_dims)
        if self.exact:
            self.index = faiss.IndexFlatL2(d)
        else:
            self.index = faiss.IndexHNSWFlat(self.dims, hnsw_links)
            self.index.hnsw.efConstruction = max(ef_search, 40)
        self.index.add(np.ascontiguousarray(self.points[:, : self.dims]))
        if not self.exact:
            self.index.hnsw.efSearch = ef_search
        self.extra = np.zeros((0, d), np.float32)  # added after the fit: searched exactly

    def __deepcopy__(self, memo: dict) -> PrototypeSearch:
        # the index and the fit's prototypes never change: copies share them
        new = object.__new__(PrototypeSearch)
        new.__dict__.update(self.__dict__)
        new.extra = self.extra.copy()
        return new

    def index_bytes(self) -> np.ndarray:
        """The index as faiss serialises it (uint8), for a model bundle: loading it takes
        milliseconds where building an HNSW graph takes seconds at tens of thousands."""
        import faiss

        return faiss.serialize_index(self.index)

    def __len__(self) -> int:
        return len(self.points) + len(self.extra)

    def with_points(self, points: np.ndarray) -> PrototypeSearch:
        """A search that also finds ``points`` (ids after the existing ones); past
        ``fold_above`` of them beside the index, the new search indexes them all."""
        new = self.__deepcopy__({})
        new.extra = np.concatenate([self.extra, np.asarray(points, np.float32)])
        if len(new.extra) > new.fold_above:
            new._fold()
        return new

    def _fold(self) -> None:
        """The prototypes beside the index into a copy of it (ids unchanged: they follow
        the indexed ones). The prototypes' array grows by ``appended``: after the first
        fold, into room behind it, not by a copy of every row."""
        import faiss

        index = faiss.clone_index(self.index)
        index.add(np.ascontiguousarray(self.extra[:, : self.dims]))
        self.index = index
        self.points = appended(self.points, self.extra)
        self.extra = np.zeros((0, self.points.shape[1]), np.float32)

    def nearest(self, e: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        """(ids, squared distances), each (N, min(k, len(self))), nearest first; the
        distances exact in every coordinate. Rows go ``_ROWS`` at a time: the candidates'
        coordinates of a block are rows x candidates x D floats."""
        e = np.ascontiguousarray(e, np.float32)
        k = min(k, len(self))
        parts = [self._nearest(e[lo : lo + _ROWS], k) for lo in range(0, len(e), _ROWS)]
        if len(parts) == 1:
            return parts[0]
        return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])

    def squared_to_all(self, e: np.ndarray) -> np.ndarray | None:
        """(N, len(self)) float32 squared distances from each row of ``e`` to every
        prototype, by ``squared``'s function (the exact distances ``nearest`` re-ranks its
        candidates by: the same bits); None for an HNSW index, which a few rows search as
        ``nearest`` does. The small-batch path ranks these itself: faiss's search (an
        OpenMP region and a heap) cost more than the distances for one row."""
        if not self.exact:
            return None
        n_fit, n_extra = len(self.points), len(self.extra)
        ids = getattr(self, "_all_ids", None)
        if ids is None or ids[0].shape != (len(e), n_fit) or ids[1].shape != (len(e), n_extra):
            ids = tuple(
                np.ascontiguousarray(np.broadcast_to(np.arange(m, dtype=np.int64), (len(e), m)))
                for m in (n_fit, n_extra)
            )
            if len(e) == 1:  # one row's ids, kept: a robot sends one touch a request
                self._all_ids = ids
        e = np.ascontiguousarray(e, np.float32)
        out = _squared_by_id(e, self.points, ids[0])
        if n_extra:
            out = np.concatenate([out, _squared_by_id(e, self.extra, ids[1])], axis=1)
        return out

    def _nearest(self, e: np.ndarray, k: int) -> tuple[np.ndarray, np.ndarray]:
        fitted = min(k if self.exact else k * RERANK, len(self.points))
        _, ids = self.index.search(np.ascontiguousarray(e[:, : self.dims]), fitted)
        ids = ids.astype(np.int64)
        if len(self.extra):
            extra = np.broadcast_to(
                np.arange(len(self.points), len(self)), (len(e), len(self.extra))
            )
            ids = np.concatenate([ids, extra], axis=1)
        found = ids >= 0  # HNSW may return fewer than asked (-1)
        safe = np.where(found, ids, 0)
        dist = self.squared(e, safe)
        dist[~found] = np.inf
        order = np.argsort(dist, axis=1, kind="stable")[:, :k]
        rows = np.arange(len(e))[:, None]
        return safe[rows, order], dist[rows, order]

    def squared(self, e: np.ndarray, ids: np.ndarray) -> np.ndarray:
        """(N, k) float64 squared distances from each row of ``e`` to prototypes ``ids``.
        faiss computes them from the prototypes' rows where they lie: gathering 128
        candidates' rows of 960 coordinates and summing in numpy cost ten times as much,
        most of a sample's search at 30,000 objects."""
        e = np.ascontiguousarray(e, np.float32)
        ids = np.ascontiguousarray(ids, np.int64)
        n_fit = len(self.points)
        out = _squared_by_id(e, self.points, np.where(ids < n_fit, ids, -1))
        if len(self.extra):
            added = _squared_by_id(e, self.extra, np.where(ids >= n_fit, ids - n_fit, -1))
            out = np.where(ids < n_fit, out, added)
        return out.astype(np.float64)


def _squared_by_id(e: np.ndarray, points: np.ndarray, ids: np.ndarray) -> np.ndarray:
    """(N, k) float32: row i's squared distance to ``points[ids[i, j]]``; inf where the id
    is negative (faiss's ``fvec_L2sqr_by_idx``)."""
    import faiss

    out = np.empty(ids.shape, np.float32)
    faiss.fvec_L2sqr_by_idx(
        faiss.swig_ptr(out),
        faiss.swig_ptr(e),
        faiss.swig_ptr(points),
        faiss.swig_ptr(ids),
        points.shape[1],
        len(e),
        ids.shape[1],
    )
    return out
