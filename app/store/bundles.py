"""Model bundles in the store: each version's small head, and its large arrays as
content-addressed parts that versions share (``bundle.split``).

An enrollment writes a few kilobytes instead of a whole bundle, and an API process that
serves one version loads the next by reading its head and only the parts it lacks.
"""

from __future__ import annotations

import itertools
import threading
from collections import OrderedDict

import numpy as np
from sqlalchemy.orm import Session

from app.framework import bundle
from app.framework.errors import BundleError
from app.framework.growing import appended, gathered
from app.framework.recognizer import TactileRecognizer
from app.store import repo

Split = tuple[bytes, dict[str, bytes]]  # what bundle.split returns


def store_model(session: Session, split: Split) -> str:
    """Store a split bundle (parts first, each once); returns the head's SHA-256, which a
    model version names as its bundle."""
    head, parts = split
    repo.store_bundles(session, parts)
    return repo.store_bundle(session, head)


class PartCache:
    """The decoded parts of the model a process serves, by SHA-256, read-only so that
    models sharing them cannot change each other's arrays.

    Threads share it (the API process's model poller and its embedded worker): each
    method holds ``lock``, and ``load_model`` holds it for a whole load, so that one
    thread's ``keep_only`` cannot drop what another's load has just read, nor a load see
    the dicts change under it."""

    def __init__(self) -> None:
        self.lock = threading.RLock()
        self._arrays: dict[str, np.ndarray] = {}
        # arrays stored in row blocks, by their blocks' SHA-256s: the same array object for
        # every version that lists the same blocks, as a part is (the models built from it
        # share what they derive from it, ``ForestCues.from_state``)
        self._joined: dict[tuple[str, ...], np.ndarray] = {}

    def get(self, session: Session, sha256: str) -> np.ndarray:
        with self.lock:
            array = self._arrays.get(sha256)
            if array is None:
                array = read_part(session, sha256)
                bundle.freeze(array)  # the array it views too: nothing can change it then
                self._arrays[sha256] = array
            return array

    def joined(self, session: Session, shas: list[str]) -> np.ndarray:
        """The array stored as the row blocks ``shas``, read-only; the blocks are held
        afterwards as views of it, so that the process holds its rows once. An array that
        begins with the rows of one held already (a promotion appended to it) is that
        array with the new rows appended behind it (``growing.appended``), so only they are
        read and held anew; any other is read block by block into one with room."""
        with self.lock:
            return self._joined_locked(session, shas)

    def _joined_locked(self, session: Session, shas: list[str]) -> np.ndarray:
        array = self._joined.get(tuple(shas))
        if array is not None:
            return array
        array = self._extended(session, shas)
        if array is None:  # every block but the last has the rows of the first
            first = self.get(session, shas[0])
            rest = (self._block(session, sha) for sha in shas[1:])
            array = gathered(itertools.chain([first], rest), len(first) * len(shas))
        bundle.freeze(array)
        rows = len(self._arrays[shas[0]])  # a block's rows (the last one's: the rest)
        for i, sha in enumerate(shas):
            self._arrays[sha] = array[i * rows : (i + 1) * rows]
        self._joined[tuple(shas)] = array
        return array

    def _block(self, session: Session, sha256: str) -> np.ndarray:
        """A block held, or read and decoded without being held."""
        held = self._arrays.get(sha256)
        return held if held is not None else read_part(session, sha256)

    def _extended(self, session: Session, shas: list[str]) -> np.ndarray | None:
        """A held array that ``shas`` extend, with their new rows appended; None if none.
        The blocks of a promoted array are those of the array before it but for the last
        one, whose rows the new last-but-more blocks begin with (checked)."""
        for key, held in self._joined.items():
            last = self._arrays.get(key[-1])
            if last is None or len(key) > len(shas) or list(key[:-1]) != shas[: len(key) - 1]:
                continue
            start = len(held) - len(last)  # where the held array's last block begins
            tail = np.concatenate([self._block(session, sha) for sha in shas[len(key) - 1 :]])
            if tail.shape[1:] != held.shape[1:] or tail.dtype != held.dtype:
                continue
            if len(tail) < len(held) - start or not np.array_equal(
                tail[: len(held) - start], held[start:]
            ):
                continue
            return appended(held, tail[len(held) - start :])
        return None

    def keep_only(self, shas: set[str]) -> None:
        with self.lock:
            self._arrays = {sha: a for sha, a in self._arrays.items() if sha in shas}
            self._joined = {k: a for k, a in self._joined.items() if shas.issuperset(k)}

    def adopt(self, encoder: bundle.PartEncoder) -> None:
        """Hold exactly the parts of the version this process has just split with
        ``encoder``, as the arrays (or row blocks) of its model: the parts it shares with
        the version before are not read again, and that version's arrays are not kept
        alive by views of them."""
        with self.lock:
            self._arrays = dict(encoder.views)
            self._joined = dict(encoder.joined)

    def __len__(self) -> int:
        return len(self._arrays)


def read_part(session: Session, sha256: str) -> np.ndarray:
    data = repo.bundle_data(session, sha256)
    if data is None:
        raise BundleError(
            f"bundle part {sha256[:12]}… is missing from the store: the store is damaged"
        )
    return bundle.decode_part(data)


class ExportCache:
    """The last ``size`` models exported, by their bundle's SHA-256. A bundle's content is
    what its SHA-256 names, so an entry is never stale: after an activation, the robots of
    a fleet that download the new version cost each API process one join (~70 ms for the
    embedded default, BENCHMARKS), not one each."""

    def __init__(self, size: int = 2) -> None:
        self.size = size
        self._files: OrderedDict[str, bytes] = OrderedDict()
        self._lock = threading.Lock()

    def export(self, session: Session, sha256: str) -> bytes:
        with self._lock:
            if (data := self._files.get(sha256)) is not None:
                self._files.move_to_end(sha256)
                return data
        data = export_model(session, sha256)  # outside the lock: a slow join blocks nobody
        with self._lock:
            self._files[sha256] = data
            while len(self._files) > self.size:
                self._files.popitem(last=False)
        return data


def export_model(session: Session, sha256: str) -> bytes:
    """The model whose bundle is ``sha256`` as one self-contained bundle file (``bundle.load``
    reads it without a store); BundleError when it is missing or damaged."""
    data = repo.bundle_data(session, sha256)
    if data is None:
        raise BundleError(f"model bundle {sha256[:12]}… is missing from the store")
    return bundle.join(data, part=lambda sha: read_part(session, sha))


def load_model(session: Session, sha256: str, cache: PartCache | None = None) -> TactileRecognizer:
    """The recognizer whose bundle (whole, or a split head) is ``sha256``; BundleError when
    it is missing, damaged or unreadable. With ``cache``, parts it holds are not read
    again, and afterwards it holds this model's parts only."""
    data = repo.bundle_data(session, sha256)
    if data is None:
        raise BundleError(f"model bundle {sha256[:12]}… is missing from the store")
    if cache is None:
        return bundle.from_bytes(data, part=lambda sha: read_part(session, sha))
    used: set[str] = set()

    def part(sha: str) -> np.ndarray:
        used.add(sha)
        return cache.get(session, sha)

    def join(shas: list[str]) -> np.ndarray:
        used.update(shas)
        return cache.joined(session, shas)

    with cache.lock:  # another thread's load neither changes nor trims it meanwhile
        model = bundle.from_bytes(data, part=part, join=join)
        cache.keep_only(used)
    return model
