"""Sensors of many values a touch: ``prototypes`` reduces them to principal components chosen
by its probe, the autoencoder solves them in the samples' span, and the simulator makes them
(``channels``, ``steps``)."""

import numpy as np
import pytest

from app.data.simulator import simulate_dataset
from app.framework.bundle import from_bytes, to_bytes
from app.framework.errors import FrameworkError
from app.framework.scaling import BlockPCA
from app.methods.attributes import semantic_autoencoder
from app.methods.prototypes import PrototypeRecognizer

OBJECTS, TRIALS = 20, 5


@pytest.fixture(scope="module")
def wide():
    """(model, held-out samples, labels): 20 objects x 4 training trials, 64 x 24 = 1,536
    values a touch, one whole trial of each object held out."""
    ds = simulate_dataset(OBJECTS, TRIALS, seed=4, channels=64, steps=24)
    held = (ds.trials % TRIALS) == 2
    model = PrototypeRecognizer(seed=0, reduce_dims=(16, 32, 64)).fit(
        ds.subset(np.flatnonzero(~held))
    )
    return model, ds.samples[held], ds.labels[held]


def test_wide_inputs_are_reduced_to_the_components_the_probe_chose(wide):
    model, x, y = wide
    tried = model.metrics["reduction_ll"]
    chosen = model.metrics["reduced_dims"]
    # one per procedure block, each of the candidates (capped) with classes whole and split
    assert chosen in (16, 32, 64), model.metrics
    assert len(tried) == 6 and f"{chosen}/{model.metrics['modes']}" in tried
    assert max(tried.values()) == tried[f"{chosen}/{model.metrics['modes']}"]
    assert model.reduction_.n_features_in == 64 * 24
    assert model.reduction_.n_features_out == chosen
    assert model.embedding_.projection_.shape[0] == chosen
    acc = float(np.mean(model.known_proba(x).argmax(axis=1) == y))
    assert acc >= 0.6, acc  # chance: 0.05


def test_a_reduced_model_reads_back_with_the_same_answers(wide):
    model, x, _ = wide
    back = from_bytes(to_bytes(model))
    assert back.reduction_ is not None
    np.testing.assert_array_equal(back.known_proba(x), model.known_proba(x))
    np.testing.assert_array_equal(back.novelty_score(x), model.novelty_score(x))


def test_a_reduced_model_answers_from_some_procedures(wide):
    model, x, y = wide
    some = x.copy()
    some[:, 16:] = np.nan  # only the first procedure's 16 taxels
    p = model.known_proba(some)
    assert np.allclose(p.sum(axis=1), 1.0)
    assert float(np.mean(p.argmax(axis=1) == y)) > 0.2  # chance: 0.05


def test_block_components_keep_each_procedure_apart():
    rng = np.random.default_rng(0)
    z = rng.normal(size=(50, 40)).astype(np.float32)
    pca = BlockPCA(8, n_blocks=4, seed=0).fit(z)
    assert pca.components_.shape == (4, 2, 10)
    moved = z.copy()
    moved[:, 10:20] += 5.0  # the second block alone
    diff = pca.transform(moved) - pca.transform(z)
    assert np.abs(diff[:, [0, 1, 4, 5, 6, 7]]).max() == 0.0
    assert np.abs(diff[:, 2:4]).max() > 0.0
    leading = pca.transform(z)[:, [0, 2, 4, 6]]
    np.testing.assert_allclose(pca.truncated(4).transform(z), leading, rtol=1e-5, atol=1e-5)
    with pytest.raises(ValueError, match="equal blocks"):
        BlockPCA(8, n_blocks=3).fit(z)


def test_the_autoencoder_of_wide_inputs_is_the_sylvester_solution():
    from scipy.linalg import solve_sylvester

    rng = np.random.default_rng(1)
    z = rng.normal(size=(60, 1100)) @ rng.normal(size=(1100, 1100)) * 0.03
    targets = (rng.random((60, 7)) < 0.4).astype(np.float64)
    w = semantic_autoencoder(z, targets, 50.0)
    x, a = z.T, targets.T
    aa = a @ a.T
    aa += 1e-6 * max(float(np.trace(aa)) / len(aa), 1.0) * np.eye(len(aa))
    reference = solve_sylvester(aa, 50.0 * (x @ x.T), 51.0 * (a @ x.T))
    assert np.abs(w - reference).max() <= 1e-7 * np.abs(reference).max()


def test_the_simulators_sensor_shape_changes_nothing_at_its_defaults_and_is_checked():
    plain = simulate_dataset(6, 3, seed=5)
    same = simulate_dataset(6, 3, seed=5, channels=32, steps=30)
    np.testing.assert_array_equal(plain.samples, same.samples)
    wide = simulate_dataset(6, 3, seed=5, channels=48, steps=40)
    assert wide.samples.shape == (18, 48, 40)
    # neighbouring taxels see the same readings: far more alike than taxels far apart
    taxels = wide.samples[:, :12].transpose(1, 0, 2).reshape(12, -1)
    near = np.corrcoef(taxels[5], taxels[6])[0, 1]
    assert near > 0.5, near
    with pytest.raises(ValueError, match="channels must be a positive multiple of 4"):
        simulate_dataset(6, 3, channels=30)
    with pytest.raises(ValueError, match="steps must be an integer >= 2"):
        simulate_dataset(6, 3, steps=1)


@pytest.mark.parametrize(
    "params, name",
    [({"reduce_dims": ()}, "reduce_dims"), ({"reduce_dims": (0, 8)}, "reduce_dims")]
    + [({"reduce_dims": "64"}, "reduce_dims"), ({"reduce_above": -1}, "reduce_above")],
)
def test_bad_reduction_parameters_are_refused_with_their_names(params, name):
    ds = simulate_dataset(4, 3, seed=0)
    with pytest.raises(FrameworkError, match=name):
        PrototypeRecognizer(**params).fit(ds)
