"""The model bundle: round trip, atomic write, and clear errors."""

import io
import json
import zipfile

import numpy as np
import pytest

from app.framework import bundle
from app.framework.errors import BundleError


def test_round_trip_gives_identical_predictions(with_novel, sim_split, tmp_path):
    model = with_novel.add_one_shot(
        sim_split["novel"].class_names[0], sim_split["novel"].samples[:1]
    )
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
    again = loaded.add_one_shot(
        sim_split["novel"].class_names[1], sim_split["novel"].samples[10:11]
    )
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


def test_arrays_are_deflated_only_where_it_pays():
    """Repetitive arrays (trees, indices) are compressed; noise-like float32 features are
    stored as they are; np.load reads both back exactly."""
    rng = np.random.default_rng(0)
    arrays = {
        "known/forest/left": np.repeat(np.arange(500, dtype=np.int32), 100),
        "known/reference": rng.normal(size=(300, 400)).astype(np.float32),
        "tiny": np.array([1.5]),
    }
    data = bundle._npz(arrays)
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        kinds = {i.filename: i.compress_type for i in zf.infolist()}
    assert kinds["known/forest/left.npy"] == zipfile.ZIP_DEFLATED
    assert kinds["known/reference.npy"] == zipfile.ZIP_STORED
    with np.load(io.BytesIO(data), allow_pickle=False) as npz:
        assert sorted(npz.files) == sorted(arrays)
        for name, array in arrays.items():
            assert npz[name].dtype == array.dtype and np.array_equal(npz[name], array)


def test_bundles_written_as_one_deflated_npz_still_load(fitted):
    """The layout before per-array compression: np.savez inside a deflated zip."""
    meta_zip = zipfile.ZipFile(io.BytesIO(bundle.to_bytes(fitted)))
    manifest = meta_zip.read("manifest.json")
    with np.load(io.BytesIO(meta_zip.read("arrays.npz"))) as npz:
        arrays = {k: npz[k] for k in npz.files}
    npz_bytes = io.BytesIO()
    np.savez(npz_bytes, **arrays)
    old = io.BytesIO()
    with zipfile.ZipFile(old, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("manifest.json", manifest)
        zf.writestr("arrays.npz", npz_bytes.getvalue())
    x = np.zeros((3, *fitted.input_shape), np.float32)
    again = bundle.from_bytes(old.getvalue())
    assert np.array_equal(again.known_proba(x), fitted.known_proba(x))


def test_a_split_bundle_round_trips_through_its_parts(fitted):
    head, parts = bundle.split(fitted, min_bytes=1024)
    assert parts and len(head) < len(bundle.to_bytes(fitted))
    loaded = bundle.from_bytes(head, part=lambda sha: bundle.decode_part(parts[sha]))
    x = np.zeros((3, *fitted.input_shape), np.float32)
    np.testing.assert_allclose(loaded.known_proba(x), fitted.known_proba(x), atol=1e-6)


def test_a_joined_split_bundle_is_self_contained_and_keeps_its_manifest(with_novel, sim_split):
    model = with_novel.add_one_shot(
        sim_split["novel"].class_names[0], sim_split["novel"].samples[:1]
    )
    head, parts = bundle.split(model, min_bytes=1024)
    joined = bundle.join(head, part=lambda sha: bundle.decode_part(parts[sha]))
    loaded = bundle.from_bytes(joined)  # no part loader: everything is in the file
    x = np.concatenate([sim_split["test"].samples[:8], sim_split["novel"].samples[:8]])
    ours, theirs = loaded.recognize_batch(x).records(), model.recognize_batch(x).records()
    assert [r["class_name"] for r in ours] == [r["class_name"] for r in theirs]
    np.testing.assert_allclose(
        [r["novelty_score"] for r in ours], [r["novelty_score"] for r in theirs], rtol=1e-6
    )
    assert set(loaded.registry.novel_samples) == {sim_split["novel"].class_names[0]}

    def manifest(data):
        with zipfile.ZipFile(io.BytesIO(data)) as zf:
            return json.loads(zf.read("manifest.json"))

    assert "parts" in manifest(head) and "parts" not in manifest(joined)
    assert manifest(joined) == {k: v for k, v in manifest(head).items() if k != "parts"}


def test_joining_gives_the_same_bytes_whatever_the_clock_says(fitted, monkeypatch):
    """A download's strong ETag is its head's SHA-256, so joining that head again, a
    second or a day later, must give the very same bytes."""
    import time

    head, parts = bundle.split(fitted, min_bytes=1024)
    joined = [bundle.join(head, part=lambda sha: bundle.decode_part(parts[sha]))]
    later = time.time() + 86_400 + 3
    monkeypatch.setattr(time, "time", lambda: later)
    joined.append(bundle.join(head, part=lambda sha: bundle.decode_part(parts[sha])))
    assert joined[0] == joined[1]


def test_joining_a_damaged_head_is_a_clear_error():
    with pytest.raises(BundleError, match="not a readable model bundle"):
        bundle.join(b"garbage", part=bundle.decode_part)


def test_a_split_head_alone_is_a_clear_error(fitted):
    head, _ = bundle.split(fitted, min_bytes=1024)
    with pytest.raises(BundleError, match="parts of a model store"):
        bundle.from_bytes(head)


def test_a_part_that_is_no_array_is_a_clear_error():
    with pytest.raises(BundleError, match="not a readable bundle part"):
        bundle.decode_part(b"garbage")


def test_the_part_encoder_does_not_encode_unchanged_arrays_again(with_novel, sim_split):
    encoder = bundle.PartEncoder(min_bytes=1024)
    _, before = encoder.split(with_novel)
    grown = with_novel.add_one_shot(
        sim_split["novel"].class_names[0], sim_split["novel"].samples[:1]
    )
    _, after = encoder.split(grown)
    shared = before.keys() & after.keys()
    assert shared  # the encoder, the known-class classifier, ... are unchanged
    assert all(after[sha] is before[sha] for sha in shared)  # the same bytes, not encoded again
    assert after.keys() == bundle.split(grown, min_bytes=1024)[1].keys()  # as a fresh split


def test_a_freezing_encoder_reads_the_arrays_a_version_shares_once(sim_split, monkeypatch):
    from app.methods.best import BestRecognizer

    novel = sim_split["novel"]
    model = BestRecognizer(n_estimators=10).fit(sim_split["train"])
    model = model.add_novel_classes(novel.class_names[:1], novel.class_attributes[:1])
    encoder = bundle.PartEncoder(min_bytes=1024, freeze=True)
    _, before = encoder.split(model)
    _, arrays = model.get_state()
    assert not any(a.flags.writeable for a in arrays.values() if a.nbytes >= 1024)
    grown = model.add_one_shot(novel.class_names[0], novel.samples[:1])
    read = []
    npy = bundle._npy
    monkeypatch.setattr(bundle, "_npy", lambda a: read.append(a.nbytes) or npy(a))
    _, after = encoder.split(grown)
    # the arrays it shares are its base's very objects, frozen: only what changed is read
    assert sum(read) < sum(a.nbytes for a in arrays.values()) / 2
    assert after.keys() == bundle.split(grown, min_bytes=1024)[1].keys()  # as a fresh split
    assert all(after[sha] is before[sha] for sha in before.keys() & after.keys())


def test_only_arrays_nobody_can_write_count_as_unchanged():
    a = np.arange(4096, dtype=np.float64)
    assert not bundle.unchangeable(a)  # writable: always read
    view = a[:2048]
    a.flags.writeable = False
    view.flags.writeable = False
    assert bundle.unchangeable(view) and bundle.unchangeable(a)
    b = np.arange(4096.0)
    ro_view = b[:2048]
    ro_view.flags.writeable = False
    assert not bundle.unchangeable(ro_view)  # its base can still be written
