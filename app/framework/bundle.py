"""The model bundle: one versioned file holding everything a recognizer needs.

Layout: a zip archive with ``manifest.json`` (format version, method, input
shape, attribute vocabulary, classes with their kind, novelty threshold and its
tuning, training config, metrics) and ``arrays.npz`` (weights and other
arrays). No pickle: loading a bundle never executes code from the file.

A model fitted on raw BioTac trials also stores its fitted ``TactileImageFeaturizer``:
the manifest's ``featurizer`` entry holds its JSON-able parameters (``get_state``'s
metadata: kind, version, options, channel names) and ``arrays.npz`` its four arrays under
``featurizer/`` (``pca_mean``, ``pca_components``, ``image_mean``, ``image_scale``). A
bundle without the entry (every bundle of a model of fixed-shape samples, and all written
before raw trials were supported) loads as a model of fixed-shape samples, as before.
Written to a temporary file in the target folder, then renamed into place.

A model fitted since 2026-11-28 also stores its ``InputProfile`` (the training samples'
channel ranges, ``app.framework.input_health``): the manifest's ``input_profile`` entry
and five small arrays under ``input_profile/``. A bundle without them loads with no
profile, and its answers carry ``input_outlier`` and ``input_outlier_score`` as None (null
over HTTP): not measured, rather than healthy; fitting the model again measures them. The
entry needs no new format version: a build older than it reads the bundle and ignores it.

A store that keeps many versions of one model writes them ``split``: the large
arrays go into parts of their own, named by the SHA-256 of their bytes and
listed in the manifest's ``parts``, and the rest is a small head bundle. An
enrollment changes the class registry, not the forest or the encoder, so
successive versions share those parts, and a process that already holds them
loads a new version by reading the head alone. An array of more than
``BLOCK_BYTES`` (2 MiB) is listed as the parts of its consecutive row blocks, so that a
version that appended rows to it shares all but its last blocks.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import tempfile
import zipfile
import zlib
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from app.framework.errors import BundleError
from app.framework.input_health import InputProfile
from app.framework.recognizer import ClassRegistry, NoveltyTuning, TactileRecognizer
from app.framework.registry import UnknownMethodError, method_class

FORMAT_VERSION = 1
# a bundle whose model takes raw trials (it carries a featurizer) is written as version 2:
# a build older than the featurizer refuses it clearly instead of serving it as a model of
# samples; bundles without one stay version 1, which every build reads
RAW_TRIALS_FORMAT_VERSION = 2
# a split bundle whose arrays are stored in row blocks is written as version 3 (and, until
# 2026-11-26, one holding a forest a promotion grew): a build older than them would not
# find the blocks, or serve the forest without its grown leaves, instead of refusing it
GROWN_FORMAT_VERSION = 3
# a bundle holding a forest as one record per node (``app.methods.forest``, 2026-11-26),
# grown or not, is written as version 4: a build older than the records would not find the
# forest's node arrays
RECORDS_FORMAT_VERSION = 4
READS = (FORMAT_VERSION, RAW_TRIALS_FORMAT_VERSION, GROWN_FORMAT_VERSION, RECORDS_FORMAT_VERSION)
_MANIFEST = "manifest.json"
_ARRAYS = "arrays.npz"
_REG = "registry/"  # prefix of the registry's arrays inside arrays.npz
_FEATURIZER = "featurizer/"  # prefix of the raw-trial featurizer's arrays
_PROFILE = "input_profile/"  # prefix of the input profile's arrays
# an array is deflated when its first 64 kB shrink below 80 % at level 1
_PROBE_BYTES = 64 * 1024
_WORTH_IT = 0.8
_NPY_MAGIC = b"\x93NUMPY"
# arrays of this size or more become parts of their own in a split bundle
PART_MIN_BYTES = 16 * 1024
# larger arrays are stored in row blocks of about this size, each a part: a promotion only
# appends rows to the large arrays (``FlatForest.with_samples``, the reference samples), so
# a new version writes their last and new blocks, not the gigabytes before them
BLOCK_BYTES = 2 * 1024 * 1024


def to_bytes(model: TactileRecognizer) -> bytes:
    """Serialise a fitted recognizer to bundle bytes (one self-contained file)."""
    manifest, arrays = _contents(model)
    return _zip(manifest, arrays)


def split(
    model: TactileRecognizer, min_bytes: int = PART_MIN_BYTES
) -> tuple[bytes, dict[str, bytes]]:
    """The bundle as a head and its parts: ``(head bytes, {sha256: part bytes})``.

    Every array of ``min_bytes`` or more becomes a part (its ``.npy`` bytes, zlib-deflated
    when that pays), and the head's manifest maps the array's name to the part's SHA-256.
    ``from_bytes(head, part=...)`` loads it.
    """
    return PartEncoder(min_bytes).split(model)


class PartEncoder:
    """``split`` for a process that writes one version after another: arrays that are
    byte for byte those of its previous split keep their encoded part instead of being
    deflated again (an enrollment changes kilobytes; writing a version of the default model
    takes ~38 ms from scratch and ~6 ms through the encoder, bench/model_swap.py), and
    read-only arrays that are the very objects of its previous split are not even read.
    ``freeze``: make the arrays it splits read-only (the worker's: a version, once stored,
    never changes, and the models enrolment derives from it share its arrays). After a
    split, ``views`` maps each part's SHA-256 to the array or row block of the model it
    came from, and ``joined`` each array stored in row blocks by their SHA-256s
    (``PartCache.adopt``)."""

    def __init__(self, min_bytes: int = PART_MIN_BYTES, freeze: bool = False) -> None:
        self.min_bytes = min_bytes
        self.freeze = freeze
        # digest of .npy bytes -> (SHA-256, bytes of the part, None where a store has it)
        self._previous: dict[bytes, tuple[str, bytes | None]] = {}
        # read-only arrays of the previous split by name (each held) -> their blocks' digests:
        # the very same array is neither read nor hashed again, and a new one that begins
        # with its rows (a promotion appends) is compared with it block by block
        self._named: dict[str, tuple[np.ndarray, list[bytes]]] = {}
        self.views: dict[str, np.ndarray] = {}
        self.joined: dict[tuple[str, ...], np.ndarray] = {}

    def prime(self, model: TactileRecognizer, head: bytes) -> None:
        """Take ``model``, loaded from a store that holds the parts its split ``head``
        names, as this encoder's previous split: a next split that shares its arrays or
        their row blocks names those parts without encoding them again (the worker's first
        version after a start took 38 s to encode at 10,000 objects) and returns no bytes
        for them, as the store has them."""
        _, arrays = _contents(model)
        named: dict[str, tuple[np.ndarray, list[bytes]]] = {}
        previous: dict[bytes, tuple[str, bytes | None]] = {}
        for name, ref in part_refs(head).items():
            array, shas = arrays.get(name), ref if isinstance(ref, list) else [ref]
            if not isinstance(array, np.ndarray) or not unchangeable(array):
                continue
            if len(row_blocks(array)) != len(shas):
                continue  # stored in other blocks than this build's
            # a part's key is the SHA-256 of its .npy bytes, which is the stored SHA-256
            # when the part is stored uncompressed; a compressed one names the same part
            keys = [bytes.fromhex(sha) for sha in shas]
            previous.update({key: (sha, None) for key, sha in zip(keys, shas, strict=True)})
            named[name] = (array, keys)
        self._previous, self._named = previous, named

    def split(self, model: TactileRecognizer) -> tuple[bytes, dict[str, bytes]]:
        manifest, arrays = _contents(model)
        parts: dict[str, bytes] = {}
        refs: dict[str, str | list[str]] = {}
        encoded: dict[bytes, tuple[str, bytes]] = {}
        named: dict[str, tuple[np.ndarray, list[bytes]]] = {}
        views: dict[str, np.ndarray] = {}
        joined: dict[tuple[str, ...], np.ndarray] = {}
        for name in [n for n, a in arrays.items() if np.asanyarray(a).nbytes >= self.min_bytes]:
            array = np.asanyarray(arrays.pop(name))
            if self.freeze:
                freeze(array)
            before, known = self._named.get(name, (None, []))
            blocks = row_blocks(array)
            if before is array:
                # the very array of the previous version, which nothing can have changed: the
                # shared parts of a large model (2 GB at 10,000 objects) are neither copied
                # to .npy bytes nor hashed again for every enrolment
                keys = known
                encoded.update({k: self._previous[k] for k in keys})
            else:
                old = row_blocks(before) if before is not None else []
                keys = []
                for i, block in enumerate(blocks):
                    if i < len(old) and _same_bytes(block, old[i]):
                        keys.append(known[i])  # a block of the previous version: its part
                        encoded[known[i]] = self._previous[known[i]]
                        continue
                    data = _npy(block)
                    keys.append(hashlib.sha256(data).digest())
                    if keys[-1] not in encoded:
                        encoded[keys[-1]] = self._previous.get(keys[-1]) or _encode_npy(data)
            if unchangeable(array):
                named[name] = (array, keys)
            for key, block in zip(keys, blocks, strict=True):
                sha, blob = encoded[key]
                views[sha] = block
                if blob is not None:  # None: stored already (``prime``)
                    parts[sha] = blob
            shas = [encoded[k][0] for k in keys]
            refs[name] = shas[0] if len(shas) == 1 else shas
            if len(shas) > 1:
                joined[tuple(shas)] = array
        self._previous = encoded  # only the latest model's parts are kept
        self._named = named
        self.views, self.joined = views, joined
        manifest["parts"] = refs
        if any(isinstance(ref, list) for ref in refs.values()):
            manifest["format_version"] = max(manifest["format_version"], GROWN_FORMAT_VERSION)
        return _zip(manifest, arrays), parts


def _same_bytes(a: np.ndarray, b: np.ndarray) -> bool:
    """Whether two arrays are the same bytes of the same shape and type (memory compared, as
    a hash would tell, at a fraction of its cost)."""
    if a.shape != b.shape or a.dtype != b.dtype:
        return False
    if not (a.flags.c_contiguous and b.flags.c_contiguous):
        return False  # told apart by their hashes instead
    if a.__array_interface__["data"][0] == b.__array_interface__["data"][0]:
        return True  # the same memory (a promotion appended behind these rows)
    return bool(np.array_equal(a.reshape(-1).view(np.uint8), b.reshape(-1).view(np.uint8)))


def row_blocks(array: np.ndarray) -> list[np.ndarray]:
    """``array`` as consecutive row blocks of about ``BLOCK_BYTES`` (views; itself when it
    is no larger), as a split bundle stores it."""
    if array.ndim == 0 or array.nbytes <= BLOCK_BYTES:
        return [array]
    rows = max(1, BLOCK_BYTES * len(array) // array.nbytes)
    return [array[i : i + rows] for i in range(0, len(array), rows)]


def unchangeable(array: Any) -> bool:
    """Whether no reference can write into ``array``: read-only, and so is every array its
    memory comes from (a store's parts, an index's serialisation). Enrolment derives a model
    from its base sharing such arrays, never copying them (``PartCache``)."""
    while isinstance(array, np.ndarray):
        if array.flags.writeable:
            return False
        array = array.base
    return array is None or isinstance(array, bytes)


def freeze(array: np.ndarray) -> None:
    """``array`` read-only, and the arrays its memory comes from where that memory is
    their own or immutable bytes (``unchangeable`` is true then)."""
    chain, memory = [], array
    while isinstance(memory, np.ndarray):
        chain.append(memory)
        memory = memory.base
    for a in reversed(chain if memory is None or isinstance(memory, bytes) else chain[:1]):
        a.flags.writeable = False


def _encode_npy(data: bytes) -> tuple[str, bytes]:
    blob = zlib.compress(data, 1) if _compressible(data) else data
    return hashlib.sha256(blob).hexdigest(), blob


def part_refs(data: bytes) -> dict[str, str | list[str]]:
    """``{array name: part SHA-256, or its row blocks' list}`` of a split bundle's head;
    empty for a whole bundle."""
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            return dict(json.loads(zf.read(_MANIFEST)).get("parts") or {})
    except (zipfile.BadZipFile, KeyError, json.JSONDecodeError, OSError, EOFError) as exc:
        raise BundleError(f"not a readable model bundle: {exc}") from None


def part_shas(data: bytes) -> set[str]:
    """Every part SHA-256 a split bundle's head refers to; empty for a whole bundle."""
    return {
        sha for ref in part_refs(data).values() for sha in ([ref] if isinstance(ref, str) else ref)
    }


def decode_part(blob: bytes) -> np.ndarray:
    """The array of a part written by ``split``; BundleError if it is not one."""
    try:
        data = blob if blob[: len(_NPY_MAGIC)] == _NPY_MAGIC else zlib.decompress(blob)
        return np.lib.format.read_array(io.BytesIO(data), allow_pickle=False)
    except (zlib.error, ValueError, OSError, EOFError) as exc:
        raise BundleError(f"not a readable bundle part: {exc}") from None


def _contents(model: TactileRecognizer) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The manifest and every array of a fitted recognizer."""
    model._require_fitted()
    meta, arrays = model.get_state()
    reg = model.registry
    manifest: dict[str, Any] = {
        "format_version": FORMAT_VERSION,
        "method": model.method,
        "created_at": datetime.now(UTC).isoformat(),
        "input_shape": list(model.input_shape),
        "procedures": list(model.procedures),
        "attribute_names": list(reg.attribute_names),
        "classes": [{"name": n, "kind": "known"} for n in reg.known_names]
        + [{"name": n, "kind": "novel"} for n in reg.novel_names],
        "novelty_threshold": model.novelty_threshold,
        "novelty_tuning": model.novelty_tuning.to_dict() if model.novelty_tuning else None,
        "metrics": model.metrics,
        "method_state": meta,
        "novel_sample_classes": list(reg.novel_samples),
    }
    all_arrays = dict(arrays)
    if model.featurizer is not None:
        featurizer_meta, featurizer_arrays = model.featurizer.get_state()
        manifest["featurizer"] = featurizer_meta
        manifest["format_version"] = RAW_TRIALS_FORMAT_VERSION
        for name, value in featurizer_arrays.items():
            all_arrays[_FEATURIZER + name] = value
    if model.input_profile_ is not None:
        profile_meta, profile_arrays = model.input_profile_.get_state()
        manifest["input_profile"] = profile_meta
        for name, value in profile_arrays.items():
            all_arrays[_PROFILE + name] = value
    if any(name.endswith("forest/nodes") for name in all_arrays):
        manifest["format_version"] = RECORDS_FORMAT_VERSION
    all_arrays[_REG + "known_attributes"] = reg.known_attributes
    all_arrays[_REG + "novel_attributes"] = reg.novel_attributes
    for i, (_name, samples) in enumerate(reg.novel_samples.items()):
        all_arrays[f"{_REG}novel_samples/{i}"] = samples
    return manifest, all_arrays


def _zip(manifest: dict[str, Any], all_arrays: dict[str, np.ndarray]) -> bytes:
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as zf:
        zf.writestr(
            _entry(_MANIFEST),
            json.dumps(manifest, default=_json_default),
            compress_type=zipfile.ZIP_DEFLATED,
        )
        zf.writestr(_entry(_ARRAYS), _npz(all_arrays))  # its members are compressed where it pays
    return out.getvalue()


def _entry(name: str) -> zipfile.ZipInfo:
    """A zip member stamped with a fixed time, not the clock's: the same model gives the
    same bytes, so a download's strong ETag names its content (the manifest keeps the
    real creation time)."""
    info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
    info.external_attr = 0o600 << 16  # what ``writestr`` gives a member named by a string
    return info


def _npz(arrays: dict[str, np.ndarray]) -> bytes:
    """What ``np.savez`` writes (``np.load`` reads it), but each array deflated only when
    that pays. Trees and indices shrink 3-5x; stored training features (float32) shrink
    by 7 % at a cost of ~55 ms per 2.3 MB, and a bundle is written on every enrollment
    and read by every API process, so those are stored as they are."""
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as zf:
        for name, array in arrays.items():
            data = _npy(array)
            zf.writestr(
                _entry(name + ".npy"),
                data,
                compress_type=zipfile.ZIP_DEFLATED if _compressible(data) else zipfile.ZIP_STORED,
                compresslevel=1,
            )
    return out.getvalue()


def _npy(array: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.lib.format.write_array(buf, np.asanyarray(array), allow_pickle=False)
    return buf.getvalue()


def _compressible(data: bytes) -> bool:
    probe = data[:_PROBE_BYTES]
    return len(zlib.compress(probe, 1)) < _WORTH_IT * len(probe)


def from_bytes(
    data: bytes,
    part: Callable[[str], np.ndarray] | None = None,
    join: Callable[[list[str]], np.ndarray] | None = None,
) -> TactileRecognizer:
    """Rebuild a recognizer from bundle bytes; BundleError says what is wrong.

    A split bundle's head needs ``part``, which returns the array of a part given its
    SHA-256 (raising BundleError when it cannot). An array stored in row blocks is
    ``join(list of SHA-256)``: by default their arrays from ``part``, concatenated.
    """
    manifest, npz_bytes = _unzip(data)
    try:
        arrays = _unnpz(npz_bytes)
        refs = manifest.get("parts") or {}
        if refs and part is None:
            raise BundleError(
                f"this bundle keeps {len(refs)} arrays in parts of a model store; "
                "load it through the store"
            )
        arrays.update(_parts(refs, part, join))
        cls = method_class(manifest["method"])
        model = cls()
        model.input_shape = tuple(int(s) for s in manifest["input_shape"])
        model.procedures = tuple(str(p) for p in manifest.get("procedures") or ())
        names = manifest["classes"]
        model.registry = ClassRegistry(
            attribute_names=tuple(manifest["attribute_names"]),
            known_names=[c["name"] for c in names if c["kind"] == "known"],
            known_attributes=arrays.pop(_REG + "known_attributes"),
            novel_names=[c["name"] for c in names if c["kind"] == "novel"],
            novel_attributes=arrays.pop(_REG + "novel_attributes"),
            novel_samples={
                name: arrays.pop(f"{_REG}novel_samples/{i}")
                for i, name in enumerate(manifest["novel_sample_classes"])
            },
        )
        model.novelty_threshold = float(manifest["novelty_threshold"])
        tuning = manifest.get("novelty_tuning")
        model.novelty_tuning = NoveltyTuning.from_dict(tuning) if tuning else None
        model.metrics = manifest.get("metrics") or {}
        model.featurizer_ = _featurizer(manifest, arrays, model.input_shape)
        model.input_profile_ = _input_profile(manifest, arrays, model.input_shape)
        model.set_state(manifest["method_state"], arrays)
    except BundleError:
        raise
    except UnknownMethodError as exc:
        raise BundleError(f"bundle names a method this build does not have: {exc}") from None
    except (KeyError, ValueError, TypeError, RuntimeError, OSError, EOFError) as exc:
        raise BundleError(
            f"bundle is incomplete or inconsistent: {type(exc).__name__}: {exc}"
        ) from None
    return model


def _featurizer(
    manifest: dict[str, Any], arrays: dict[str, np.ndarray], input_shape: tuple[int, ...]
) -> Any:
    """The fitted featurizer a bundle stores (its arrays popped from ``arrays``), or None."""
    featurizer_arrays = {
        name[len(_FEATURIZER) :]: arrays.pop(name)
        for name in [n for n in arrays if n.startswith(_FEATURIZER)]
    }
    meta = manifest.get("featurizer")
    if meta is None:
        if featurizer_arrays:
            raise BundleError("bundle holds featurizer arrays but no featurizer entry")
        return None
    from app.framework.tactile_image import TactileImageFeaturizer

    try:
        featurizer = TactileImageFeaturizer.from_state(meta, featurizer_arrays)
    except (ValueError, TypeError, AttributeError) as exc:
        raise BundleError(f"bundle's featurizer is unreadable: {exc}") from None
    if tuple(featurizer.image_shape) != tuple(input_shape):
        raise BundleError(
            f"bundle's featurizer makes images of shape {list(featurizer.image_shape)} but the "
            f"model takes {list(input_shape)}"
        )
    return featurizer


def _input_profile(
    manifest: dict[str, Any], arrays: dict[str, np.ndarray], input_shape: tuple[int, ...]
) -> InputProfile | None:
    """The input profile a bundle stores (its arrays popped from ``arrays``), or None for a
    bundle written before profiles."""
    profile_arrays = {
        name[len(_PROFILE) :]: arrays.pop(name)
        for name in [n for n in arrays if n.startswith(_PROFILE)]
    }
    meta = manifest.get("input_profile")
    if meta is None:
        return None
    try:
        profile = InputProfile.from_state(meta, profile_arrays)
    except (ValueError, TypeError, KeyError) as exc:
        raise BundleError(f"bundle's input profile is unreadable: {exc}") from None
    if profile.input_shape != tuple(input_shape):
        raise BundleError(
            f"bundle's input profile is of samples of shape {list(profile.input_shape)} but "
            f"the model takes {list(input_shape)}"
        )
    return profile


def join(data: bytes, part: Callable[[str], np.ndarray]) -> bytes:
    """A split bundle's head and its parts as one self-contained bundle, the manifest (its
    creation time included) kept as it was: what a robot downloads to recognise offline.
    ``part`` returns the array of a part given its SHA-256."""
    manifest, npz_bytes = _unzip(data)
    try:
        arrays = _unnpz(npz_bytes)
    except (ValueError, OSError, EOFError) as exc:
        raise BundleError(
            f"bundle is incomplete or inconsistent: {type(exc).__name__}: {exc}"
        ) from None
    refs = manifest.pop("parts", None) or {}
    arrays.update(_parts(refs, part))
    return _zip(manifest, arrays)


def _parts(
    refs: dict[str, Any],
    part: Callable[[str], np.ndarray],
    join: Callable[[list[str]], np.ndarray] | None = None,
) -> dict[str, np.ndarray]:
    """The arrays a head's ``parts`` names: a part's SHA-256, or the list of its row blocks'."""
    if join is None:

        def join(shas: list[str]) -> np.ndarray:
            return np.concatenate([part(sha) for sha in shas])

    return {name: part(ref) if isinstance(ref, str) else join(ref) for name, ref in refs.items()}


def _unzip(data: bytes) -> tuple[dict[str, Any], bytes]:
    """The manifest of bundle bytes, checked for this build's format version, and the
    bytes of its ``arrays.npz``."""
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            manifest = json.loads(zf.read(_MANIFEST))
            npz_bytes = zf.read(_ARRAYS)
    except (zipfile.BadZipFile, KeyError, json.JSONDecodeError, OSError, EOFError) as exc:
        raise BundleError(f"not a readable model bundle: {exc}") from None
    version = manifest.get("format_version")
    if version not in READS:
        raise BundleError(
            f"bundle format version {version!r} is not supported "
            f"(this build reads {', '.join(map(str, READS))}); "
            "retrain the model with this version"
        )
    return manifest, npz_bytes


def _unnpz(npz_bytes: bytes) -> dict[str, np.ndarray]:
    with np.load(io.BytesIO(npz_bytes), allow_pickle=False) as npz:
        return {k: npz[k] for k in npz.files}


def save(model: TactileRecognizer, path: str | os.PathLike) -> str:
    """Write the bundle atomically; returns its SHA-256 (content address)."""
    data = to_bytes(model)
    write_atomic(Path(path), data)
    return hashlib.sha256(data).hexdigest()


def load(path: str | os.PathLike) -> TactileRecognizer:
    p = Path(path)
    if not p.is_file():
        raise BundleError(f"no model bundle at {p}")
    return from_bytes(p.read_bytes())


class BundleFile:
    """A bundle file that is read again whenever it is replaced (a sync renames a new file
    over it): ``load`` returns the model and whether it was read just now. When a changed
    file cannot be read, the error propagates once and the model read before stays."""

    def __init__(self, path: str | os.PathLike) -> None:
        self.path = Path(path)
        self.model: TactileRecognizer | None = None
        self.sha256: str | None = None  # of the bytes the model was read from
        self._stamp: tuple[int, int, int] | None = None

    def load(self) -> tuple[TactileRecognizer, bool]:
        stamp = _file_stamp(self.path)
        if self.model is not None and stamp == self._stamp:
            return self.model, False
        self._stamp = stamp  # a file that fails is not tried again until it changes
        if stamp is None:
            raise BundleError(f"no model bundle at {self.path}")
        data = self.path.read_bytes()
        self.model, self.sha256 = from_bytes(data), hashlib.sha256(data).hexdigest()
        return self.model, True


def _file_stamp(path: Path) -> tuple[int, int, int] | None:
    """What tells a replaced file from the one read before (None while there is none)."""
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_ino, st.st_mtime_ns, st.st_size


def write_atomic(path: Path, data: bytes) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, tuple):
        return list(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")
