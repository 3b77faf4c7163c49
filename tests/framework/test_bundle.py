"""The model bundle: round trip, atomic write, and clear errors."""

import io
import json
import zipfile

import numpy as np
import pytest

from app.framework import bundle
from app.framework.errors import BundleError


def test_round_trip_gives_identical_predictions(with_novel, sim_split, tmp_path):
    model = with_novel.add_one_shot(sim_split["novel"].class_names[0], sim_split["novel"].samples[:1])
    path = tmp_path / "model.bundle"
    digest = bundle.save(model, path)
    assert len(digest) == 64
    loaded = bundle.load(path)
    x = np.concatenate([sim_split["test"].samples[:8], sim_split["novel"].samples[:8]])
    np.testing.assert_allclose(loaded.known_proba(x), model.known_proba(x), atol=1e-6)
    np.testing.assert_allclose(loaded.novel_proba(x), model.novel_proba(x), atol=1e-6)
    np.testing.assert_allclose(loaded.novelty_score(x), model.novelty_score(x), rtol=1e-6)
    assert loaded.novelty_threshold == model.novelty_threshold
    assert loaded.registry.novel_names == model.registry.novel_names
    assert set(loaded.registry.novel_samples) == {sim_split["novel"].class_names[0]}
    assert loaded.metrics["n_known_classes"] == 30
    # a loaded model keeps learning
    again = loaded.add_one_shot(sim_split["novel"].class_names[1], sim_split["novel"].samples[10:11])
    assert len(again.registry.novel_samples) == 2


def test_manifest_describes_the_model(fitted):
    with zipfile.ZipFile(io.BytesIO(bundle.to_bytes(fitted))) as zf:
        manifest = json.loads(zf.read("manifest.json"))
    assert manifest["format_version"] == bundle.FORMAT_VERSION
    assert manifest["method"] == "paper"
    assert manifest["input_shape"] == [32, 30]
    assert len(manifest["attribute_names"]) == 19
    assert {c["kind"] for c in manifest["classes"]} == {"known"}
    assert manifest["method_state"]["params"]["encoder_epochs"] == 25


def _rewrite_manifest(data: bytes, **changes) -> bytes:
    src = zipfile.ZipFile(io.BytesIO(data))
    manifest = json.loads(src.read("manifest.json"))
    manifest.update(changes)
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w") as zf:
        zf.writestr("manifest.json", json.dumps(manifest))
        zf.writestr("arrays.npz", src.read("arrays.npz"))
    return out.getvalue()


def test_incompatible_format_version_fails_clearly(fitted):
    data = _rewrite_manifest(bundle.to_bytes(fitted), format_version=99)
    with pytest.raises(BundleError, match="format version 99 is not supported"):
        bundle.from_bytes(data)


def test_unknown_method_fails_clearly(fitted):
    data = _rewrite_manifest(bundle.to_bytes(fitted), method="nonexistent")
    with pytest.raises(BundleError, match="method"):
        bundle.from_bytes(data)


@pytest.mark.parametrize("cut", [0, 100, 5000])
def test_truncated_or_garbage_bundle_fails_clearly(fitted, tmp_path, cut):
    data = bundle.to_bytes(fitted)
    path = tmp_path / "bad.bundle"
    path.write_bytes(data[:cut] if cut else b"not a bundle")
    with pytest.raises(BundleError):
        bundle.load(path)


def test_missing_bundle_names_the_path(tmp_path):
    with pytest.raises(BundleError, match="no model bundle at"):
        bundle.load(tmp_path / "absent.bundle")


def test_save_is_atomic_and_leaves_no_temporary_files(fitted, tmp_path, monkeypatch):
    path = tmp_path / "m.bundle"
    bundle.save(fitted, path)
    before = path.read_bytes()

    def explode(*args, **kwargs):
        raise OSError("disk full")

    monkeypatch.setattr(bundle.os, "replace", explode)
    with pytest.raises(OSError, match="disk full"):
        bundle.save(fitted, path)
    assert path.read_bytes() == before  # the old bundle is intact
    assert [p.name for p in tmp_path.iterdir()] == ["m.bundle"]
