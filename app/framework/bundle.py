"""The model bundle: one versioned file holding everything a recognizer needs.

Layout: a zip archive with ``manifest.json`` (format version, method, input
shape, attribute vocabulary, classes with their kind, novelty threshold and its
tuning, training config, metrics) and ``arrays.npz`` (weights and other
arrays). No pickle: loading a bundle never executes code from the file.
Written to a temporary file in the target folder, then renamed into place.
"""

from __future__ import annotations

import hashlib
import io
import json
import os
import tempfile
import zipfile
import zlib
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from app.framework.errors import BundleError
from app.framework.recognizer import ClassRegistry, NoveltyTuning, TactileRecognizer
from app.framework.registry import UnknownMethodError, method_class

FORMAT_VERSION = 1
_MANIFEST = "manifest.json"
_ARRAYS = "arrays.npz"
_REG = "registry/"  # prefix of the registry's arrays inside arrays.npz
# an array is deflated when its first 64 kB shrink below 80 % at level 1
_PROBE_BYTES = 64 * 1024
_WORTH_IT = 0.8


def to_bytes(model: TactileRecognizer) -> bytes:
    """Serialise a fitted recognizer to bundle bytes."""
    model._require_fitted()
    meta, arrays = model.get_state()
    reg = model.registry
    manifest: dict[str, Any] = {
        "format_version": FORMAT_VERSION,
        "method": model.method,
        "created_at": datetime.now(UTC).isoformat(),
        "input_shape": list(model.input_shape),
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
    all_arrays[_REG + "known_attributes"] = reg.known_attributes
    all_arrays[_REG + "novel_attributes"] = reg.novel_attributes
    for i, (_name, samples) in enumerate(reg.novel_samples.items()):
        all_arrays[f"{_REG}novel_samples/{i}"] = samples
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as zf:
        zf.writestr(_MANIFEST, json.dumps(manifest, default=_json_default),
                    compress_type=zipfile.ZIP_DEFLATED)
        zf.writestr(_ARRAYS, _npz(all_arrays))  # its members are compressed where it pays
    return out.getvalue()


def _npz(arrays: dict[str, np.ndarray]) -> bytes:
    """What ``np.savez`` writes (``np.load`` reads it), but each array deflated only when
    that pays. Trees and indices shrink 3-5x; stored training features (float32) shrink
    by 7 % at a cost of ~55 ms per 2.3 MB, and a bundle is written on every enrollment
    and read by every API process, so those are stored as they are."""
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as zf:
        for name, array in arrays.items():
            buf = io.BytesIO()
            np.lib.format.write_array(buf, np.asanyarray(array), allow_pickle=False)
            data = buf.getvalue()
            probe = data[:_PROBE_BYTES]
            compressible = len(zlib.compress(probe, 1)) < _WORTH_IT * len(probe)
            zf.writestr(name + ".npy", data, compress_type=zipfile.ZIP_DEFLATED if compressible
                        else zipfile.ZIP_STORED, compresslevel=1)
    return out.getvalue()


def from_bytes(data: bytes) -> TactileRecognizer:
    """Rebuild a recognizer from bundle bytes; BundleError says what is wrong."""
    try:
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            manifest = json.loads(zf.read(_MANIFEST))
            npz_bytes = zf.read(_ARRAYS)
    except (zipfile.BadZipFile, KeyError, json.JSONDecodeError, OSError, EOFError) as exc:
        raise BundleError(f"not a readable model bundle: {exc}") from None
    version = manifest.get("format_version")
    if version != FORMAT_VERSION:
        raise BundleError(
            f"bundle format version {version!r} is not supported (this build reads {FORMAT_VERSION}); "
            "retrain the model with this version"
        )
    try:
        with np.load(io.BytesIO(npz_bytes), allow_pickle=False) as npz:
            arrays = {k: npz[k] for k in npz.files}
        cls = method_class(manifest["method"])
        model = cls()
        model.input_shape = tuple(int(s) for s in manifest["input_shape"])
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
        model.set_state(manifest["method_state"], arrays)
    except BundleError:
        raise
    except UnknownMethodError as exc:
        raise BundleError(f"bundle names a method this build does not have: {exc}") from None
    except (KeyError, ValueError, TypeError, RuntimeError, OSError, EOFError) as exc:
        raise BundleError(f"bundle is incomplete or inconsistent: {type(exc).__name__}: {exc}") from None
    return model


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
