"""Built-in tactile simulator: layout, determinism, attribute vectors, traces, difficulty,
and the separation option."""

import hashlib
import time

import numpy as np
import pytest
from sklearn.ensemble import ExtraTreesClassifier
from sklearn.linear_model import LogisticRegression
from sklearn.preprocessing import StandardScaler
from threadpoolctl import threadpool_limits

from app.data.simulator import (
    CHANNEL_NAMES,
    PAPER_ATTRIBUTES,
    channel,
    sample_attributes,
    signature_scale,
    simulate_dataset,
)

# Sect. V-A of the paper, in its order.
PAPER_LIST = (
    "absorbent bumpy compressible cool fuzzy hard hairy metallic porous rough scratchy "
    "slippery smooth soft solid springy squishy textured thick"
).split()


@pytest.fixture(scope="module")
def sim():
    return simulate_dataset(seed=0)


def held_out_split(ds):
    """8 trials of each object for training, the other 2 for testing."""
    k = np.arange(len(ds)) % 10  # trials are generated object by object
    return k < 8, k >= 8


def test_layout(sim):
    assert PAPER_ATTRIBUTES == tuple(PAPER_LIST)
    assert sim.samples.shape == (600, 32, 30) and sim.samples.dtype == np.float32
    assert np.isfinite(sim.samples).all()
    assert sim.name == "simulated" and sim.attribute_names == PAPER_ATTRIBUTES
    assert sim.class_names[0] == "sim-object-00" and sim.class_names[-1] == "sim-object-59"
    assert sim.object_ids == tuple(range(60))
    np.testing.assert_array_equal(np.bincount(sim.labels), np.full(60, 10))
    assert len(np.unique(sim.trials)) == 600
    assert len(CHANNEL_NAMES) == 32 and channel("move_down", "e3") == 31
    assert CHANNEL_NAMES[channel("hold", "tdc")] == "hold/tdc"


def test_sizes_and_names():
    ds = simulate_dataset(n_objects=120, trials_per_object=3, seed=4)
    assert ds.samples.shape == (360, 32, 30)
    assert ds.class_names[7] == "sim-object-007"
    assert len(np.unique(ds.trials)) == 360


def test_fast():
    start = time.perf_counter()
    simulate_dataset(seed=11)
    assert time.perf_counter() - start < 1.0


def test_deterministic_per_seed(sim):
    again = simulate_dataset(seed=0)
    np.testing.assert_array_equal(sim.samples, again.samples)
    np.testing.assert_array_equal(sim.class_attributes, again.class_attributes)
    other = simulate_dataset(seed=1)
    assert not np.allclose(sim.samples, other.samples)
    assert not np.array_equal(sim.class_attributes, other.class_attributes)


@pytest.mark.parametrize("n_objects", [20, 21, 60, 150])
def test_attribute_vectors(n_objects):
    conflicts = [("hard", "soft"), ("solid", "squishy"), ("metallic", "fuzzy"),
                 ("smooth", "rough"), ("slippery", "scratchy"), ("cool", "hairy")]  # fmt: skip
    for seed in range(10):
        a = sample_attributes(np.random.default_rng(seed), n_objects).astype(bool)
        assert len(np.unique(a, axis=0)) == n_objects, "vectors must be pairwise distinct"
        assert a.sum(axis=0).min() >= 3, "every attribute must be used by >= 3 objects"
        assert 2 <= a.sum(axis=1).min() and a.sum(axis=1).max() <= 7
        for x, y in conflicts:
            both = a[:, PAPER_ATTRIBUTES.index(x)] & a[:, PAPER_ATTRIBUTES.index(y)]
            assert not both.any(), f"{x} and {y} together"


def test_attributes_correlate_plausibly():
    a = np.concatenate([sample_attributes(np.random.default_rng(s), 60) for s in range(5)])
    col = {n: a[:, i] for i, n in enumerate(PAPER_ATTRIBUTES)}
    # Metal is cool; compressible things are usually squishy.
    assert col["cool"][col["metallic"] == 1].mean() > 0.7
    assert col["squishy"][col["compressible"] == 1].mean() > 0.6


def test_attribute_subset():
    ds = simulate_dataset(n_objects=30, attribute_names=("thick", "hard", "rough"), seed=2)
    assert ds.attribute_names == ("thick", "hard", "rough")
    assert ds.class_attributes.shape == (30, 3)
    assert ds.class_attributes.sum(axis=0).min() >= 3
    with pytest.raises(ValueError, match="attribute_names"):
        simulate_dataset(attribute_names=("hard", "glossy"))
    with pytest.raises(ValueError, match="attribute_names"):
        simulate_dataset(attribute_names=("hard", "hard"))


def test_bad_arguments():
    with pytest.raises(ValueError):
        simulate_dataset(n_objects=0)
    with pytest.raises(ValueError):
        simulate_dataset(noise=-1.0)


def _auc(pos, neg):
    return (pos[:, None] > neg[None, :]).mean() + 0.5 * (pos[:, None] == neg[None, :]).mean()


def _sig(ds, proc, reading):
    return ds.samples[:, channel(proc, reading)]


# (measure, attributes of the "high" group, of the "low" group; None: all other objects)
TRACES = {
    "hard: fast squeeze pressure rise": (
        lambda d: np.diff(_sig(d, "squeeze", "pdc"), axis=1)[:, 5:15].max(axis=1),
        ["hard"], ["soft", "squishy", "compressible"]),
    "compliant: large electrode deformation": (
        lambda d: _sig(d, "squeeze", "e0")[:, -8:].mean(axis=1),
        ["compressible", "squishy", "soft"], ["hard"]),
    "textured: slide vibration energy": (
        lambda d: (np.diff(_sig(d, "slide", "pac")[:, 8:], axis=1) ** 2).mean(axis=1),
        ["rough", "textured", "scratchy"], ["slippery", "smooth"]),
    "cool/metallic: temperature drop in hold": (
        lambda d: -_sig(d, "hold", "tdc").mean(axis=1), ["cool", "metallic"], None),
    "slippery: low slide shear": (
        lambda d: -_sig(d, "slide", "e1")[:, 10:].mean(axis=1), ["slippery"], None),
    "thick: aperture offset": (
        lambda d: d.samples[:, [channel(p, "e2") for p in ("squeeze", "hold", "slide")]]
        .mean(axis=(1, 2)),
        ["thick"], None),
    "absorbent/porous: pressure relaxation": (
        lambda d: _sig(d, "hold", "pdc")[:, :5].mean(axis=1)
        - _sig(d, "hold", "pdc")[:, -5:].mean(axis=1),
        ["absorbent", "porous"], None),
    "fuzzy/hairy: broadband vibration in hold": (
        lambda d: (_sig(d, "hold", "pac") ** 2).mean(axis=1), ["fuzzy", "hairy"], None),
    "springy: squeeze rebound": (
        lambda d: np.ptp(_sig(d, "squeeze", "e3"), axis=1), ["springy"], None),
}  # fmt: skip


@pytest.mark.parametrize("trace", list(TRACES))
def test_attribute_traces_are_measurable(sim, trace):
    measure, high, low = TRACES[trace]
    has = lambda names: np.any(  # noqa: E731
        [sim.class_attributes[sim.labels, PAPER_ATTRIBUTES.index(n)] == 1 for n in names], axis=0
    )
    pos = has(high)
    neg = ~pos if low is None else has(low) & ~pos
    values = measure(sim)
    assert pos.sum() >= 30 and neg.sum() >= 30
    assert _auc(values[pos], values[neg]) > 0.7


def test_same_attribute_objects_still_differ():
    # With 3 attributes only two compatible vectors exist, so many objects share one.
    ds = simulate_dataset(n_objects=24, attribute_names=("hard", "soft", "rough"), seed=3)
    _, group = np.unique(ds.class_attributes, axis=0, return_inverse=True)
    twins = ds.select_classes(np.flatnonzero(group.ravel() == 0))
    assert twins.n_classes >= 8
    train, test = held_out_split(twins)
    x = twins.samples.reshape(len(twins), -1)
    scaler = StandardScaler().fit(x[train])
    with threadpool_limits(1):
        clf = LogisticRegression(max_iter=1000).fit(scaler.transform(x[train]), twins.labels[train])
        acc = clf.score(scaler.transform(x[test]), twins.labels[test])
    assert acc > 3.0 / twins.n_classes


def test_trials_of_one_object_vary(sim):
    trials = sim.samples[sim.labels == 0]
    assert np.abs(trials - trials.mean(axis=0)).mean() > 0.05


def test_known_objects_learnable_but_not_perfectly(sim):
    train, test = held_out_split(sim)
    x = sim.samples.reshape(len(sim), -1)
    with threadpool_limits(1):
        trees = ExtraTreesClassifier(n_estimators=100, random_state=0).fit(
            x[train], sim.labels[train]
        )
        scaler = StandardScaler().fit(x[train])
        linear = LogisticRegression(max_iter=1000).fit(
            scaler.transform(x[train]), sim.labels[train]
        )
    acc_trees = trees.score(x[test], sim.labels[test])
    acc_linear = linear.score(scaler.transform(x[test]), sim.labels[test])
    assert 0.75 <= acc_trees <= 0.97, acc_trees
    assert 0.75 <= acc_linear <= 0.97, acc_linear


def _summary(samples):
    d = np.diff(samples, axis=2)
    rise = samples[:, :, -5:].mean(axis=2) - samples[:, :, :5].mean(axis=2)
    return np.concatenate(
        [samples.mean(axis=2), samples.std(axis=2), (d**2).mean(axis=2), rise], axis=1
    )


def test_zero_shot_baseline_above_chance_below_perfect(sim):
    """DAP-style: per-attribute logistic regression on 54 objects, 6 novel objects scored."""
    x, a = _summary(sim.samples), sim.class_attributes
    rng = np.random.default_rng(0)
    accs = []
    with threadpool_limits(1):
        for _ in range(3):
            novel = rng.choice(sim.n_classes, 6, replace=False)
            while len(np.unique(a[novel], axis=0)) < 6:
                novel = rng.choice(sim.n_classes, 6, replace=False)
            seen = ~np.isin(sim.labels, novel)
            scaler = StandardScaler().fit(x[seen])
            xs, xn = scaler.transform(x[seen]), scaler.transform(x[~seen])
            log_p = np.zeros((len(xn), 6))
            for m in range(a.shape[1]):
                clf = LogisticRegression(C=0.1, max_iter=1000).fit(xs, a[sim.labels[seen], m])
                p = np.clip(clf.predict_proba(xn)[:, 1], 1e-3, 1 - 1e-3)
                log_p += np.where(a[novel, m] == 1, np.log(p)[:, None], np.log1p(-p)[:, None])
            accs.append((novel[log_p.argmax(axis=1)] == sim.labels[~seen]).mean())
    assert 0.35 <= np.mean(accs) <= 0.9, accs


# ---------------------------------------------------------------- separation

# simulate_dataset() and simulate_dataset(120, 3, seed=4) as they were before the
# ``separation`` option existed (2026-11-27): the default must keep every value.
BEFORE = {
    (60, 10, 0): (112703.0083409439, [0.31159395, 0.06141759, 0.01877488]),
    (120, 3, 4): (70838.2237381391, [0.05795791, 0.15193410, -0.03377444]),
}
ATTRIBUTES_SHA256 = {
    (60, 10, 0): "438c6bafa6cf268c0ae3a543b242eaa3bad627bf884a759a0205bf47f98cda91",
    (120, 3, 4): "e540c26cb4d472885b8d3cc1866396877d1332ce0619f6fc5c57605942ee0cf4",
}


@pytest.mark.parametrize("size", list(BEFORE))
def test_default_is_unchanged_by_the_separation_option(size):
    n, trials, seed = size
    ds = simulate_dataset(n, trials, seed=seed)
    total, first = BEFORE[size]
    np.testing.assert_allclose(ds.samples[0, 0, :3], first, rtol=1e-6)
    np.testing.assert_allclose(ds.samples.sum(dtype=np.float64), total, rtol=1e-9)
    digest = hashlib.sha256(ds.class_attributes.tobytes() + ds.labels.tobytes()).hexdigest()
    assert digest == ATTRIBUTES_SHA256[size]
    explicit = simulate_dataset(n, trials, seed=seed, separation=None)
    np.testing.assert_array_equal(explicit.samples, ds.samples)


def test_separation_adds_only_a_per_object_signature():
    plain = simulate_dataset(300, 4, seed=5)
    apart = simulate_dataset(300, 4, seed=5, separation="phac2")
    np.testing.assert_array_equal(apart.class_attributes, plain.class_attributes)
    np.testing.assert_array_equal(apart.labels, plain.labels)
    added = (apart.samples - plain.samples).reshape(300, 4, 32, 30)
    np.testing.assert_allclose(added, added[:, :1].repeat(4, axis=1), atol=1e-5)  # per object
    assert 0.005 < added.std() < 0.05
    again = simulate_dataset(300, 4, seed=5, separation="phac2")
    np.testing.assert_array_equal(again.samples, apart.samples)
    # up to 60 objects the default is already at PHAC-2's level: nothing is added
    small = simulate_dataset(40, 3, seed=1, separation="phac2")
    np.testing.assert_array_equal(small.samples, simulate_dataset(40, 3, seed=1).samples)
    assert signature_scale("phac2", 30_000) > signature_scale("phac2", 3_000) > 0


def test_separation_holds_the_nearest_object_at_phac2s_distance():
    """bench/separation.py's statistic (median over objects of the nearest other object's
    distance in trial spreads along that line) is 5.50 on PHAC-2's 60 real objects."""
    from bench.separation import statistic

    plain = simulate_dataset(800, 10, seed=0)
    apart = simulate_dataset(800, 10, seed=0, separation="phac2")
    crowded = statistic(plain.samples, plain.labels, nn1=False)["sep_median"]
    held = statistic(apart.samples, apart.labels, nn1=False)["sep_median"]
    assert crowded < 5.2 and 5.2 < held < 5.8, (crowded, held)


@pytest.mark.parametrize("bad", ["far", "PHAC2", "", 1.0, 5])
def test_bad_separation_is_refused_by_name(bad):
    with pytest.raises(ValueError, match="separation"):
        simulate_dataset(10, 2, separation=bad)
