"""Known classes and novelty for the ``best`` method: an extra-trees forest plus a learned
novelty score that combines several cues.

Cues of a sample (all "higher = more novel"):

- ``1 - max p``: one minus the forest's largest class probability (the extra-trees
  baseline's whole score);
- the entropy of the forest's class distribution, and minus the gap between its
  two largest probabilities;
- ``log knn``: the log mean squared distance to the 3 nearest training samples in
  a feature-weighted space (each robust-scaled feature divided by its pooled
  within-class spread and multiplied by its Fisher ratio to the power 1/4), which
  sees how far a sample lies from every known object's trials rather than which
  object the forest would vote for.

A logistic regression combines the standardised cues. It is trained on
*pseudo-novel* objects carved from the known set: in each of ``meta_folds``
folds, ``novelty_validation_split`` removes some known objects entirely (they
play novel) and one trial of every other object (it plays known); a fold model
fitted on the rest scores both. Only known-class data is ever used, and the
recognizer tunes its threshold on yet another, outer validation split (Sect. VI-B).
"""

from __future__ import annotations

import numpy as np
from sklearn.ensemble import ExtraTreesClassifier
from sklearn.linear_model import LogisticRegression

from app.data.dataset import DatasetError, TactileDataset
from app.framework.novelty import novelty_validation_split
from app.framework.scaling import RobustInputScaler
from app.methods.forest import FlatForest

CUES = ("one_minus_maxp", "entropy", "neg_gap", "log_knn")
_KNN = 3


def flatten(samples: np.ndarray) -> np.ndarray:
    return np.asarray(samples, dtype=np.float32).reshape(len(samples), -1)


def fisher_weights(z: np.ndarray, y: np.ndarray, n_classes: int) -> np.ndarray:
    """Per-feature weights fisher^(1/4) / within-class spread (see the module docstring)."""
    means = np.stack([z[y == c].mean(axis=0) for c in range(n_classes)])
    dof = max(len(z) - n_classes, 1)
    within = np.sqrt(((z - means[y]) ** 2).sum(axis=0) / dof) + 1e-3
    fisher = (means.std(axis=0) / within) ** 2
    return (fisher**0.25 / within).astype(np.float32)


class ForestCues:
    """Scaler + forest + weighted reference samples: the known-class model and raw cues."""

    def __init__(self, scaler: RobustInputScaler, forest: FlatForest, weights: np.ndarray,
                 reference: np.ndarray) -> None:
        self.scaler = scaler
        self.forest = forest
        self.weights = np.asarray(weights, np.float32)
        self.reference = np.asarray(reference, np.float32)

    @classmethod
    def fit(cls, x: np.ndarray, y: np.ndarray, n_classes: int, n_estimators: int, max_features,
            seed: int, n_jobs: int | None) -> ForestCues:
        scaler = RobustInputScaler().fit(x)
        z = scaler.transform(x)
        et = ExtraTreesClassifier(n_estimators=n_estimators, max_features=max_features,
                                  random_state=seed, n_jobs=n_jobs).fit(z, y)
        w = fisher_weights(z, y, n_classes)
        return cls(scaler, FlatForest.from_sklearn(et), w, z * w)

    def scaled(self, x: np.ndarray) -> np.ndarray:
        return self.scaler.transform(x)

    def proba(self, z: np.ndarray) -> np.ndarray:
        return self.forest.predict_proba(z)

    def cues(self, z: np.ndarray, proba: np.ndarray) -> np.ndarray:
        """(N, len(CUES)) raw cues of scaled samples ``z`` with forest probabilities ``proba``."""
        top = np.sort(proba, axis=1)
        entropy = -(proba * np.log(np.clip(proba, 1e-12, None))).sum(axis=1)
        gap = top[:, -1] - (top[:, -2] if proba.shape[1] > 1 else 0.0)
        q = z * self.weights
        # squared distances by the expansion |q|^2 - 2 q.r + |r|^2, in float64 to avoid cancellation
        d2 = ((q.astype(np.float64) ** 2).sum(axis=1)[:, None]
              - 2.0 * q.astype(np.float64) @ self.reference.T.astype(np.float64)
              + (self.reference.astype(np.float64) ** 2).sum(axis=1)[None, :])
        k = min(_KNN, d2.shape[1])
        knn = np.partition(np.maximum(d2, 0.0), k - 1, axis=1)[:, :k].mean(axis=1)
        return np.stack([1.0 - top[:, -1], entropy, -gap, np.log(knn + 1e-6)], axis=1)

    def get_state(self) -> dict[str, np.ndarray]:
        out = {f"forest/{k}": v for k, v in self.forest.get_state().items()}
        out.update({f"scaler/{k}": v for k, v in self.scaler.get_state().items()})
        out["weights"], out["reference"] = self.weights, self.reference
        return out

    @classmethod
    def from_state(cls, arrays: dict[str, np.ndarray], n_classes: int, n_features: int) -> ForestCues:
        def part(prefix: str) -> dict[str, np.ndarray]:
            return {k[len(prefix):]: v for k, v in arrays.items() if k.startswith(prefix)}

        scaler = RobustInputScaler()
        scaler.set_state(part("scaler/"))
        forest = FlatForest.from_state(part("forest/"), n_classes, n_features)
        weights, reference = arrays["weights"], arrays["reference"]
        if weights.shape != (n_features,) or reference.ndim != 2 or reference.shape[1] != n_features:
            raise ValueError("novelty reference samples do not match the inputs")
        return cls(scaler, forest, weights, reference)


class CueCombiner:
    """Standardise the cues, then a logistic regression's decision function (higher = more novel)."""

    def __init__(self, mean: np.ndarray, scale: np.ndarray, coef: np.ndarray, intercept: float) -> None:
        self.mean = np.asarray(mean, np.float64)
        self.scale = np.asarray(scale, np.float64)
        self.coef = np.asarray(coef, np.float64)
        self.intercept = float(intercept)
        if not (self.mean.shape == self.scale.shape == self.coef.shape == (len(CUES),)):
            raise ValueError(f"the cue combiner needs {len(CUES)} weights")

    @classmethod
    def fit(cls, cues: np.ndarray, is_novel: np.ndarray, C: float) -> CueCombiner:
        mean, scale = cues.mean(axis=0), cues.std(axis=0)
        scale = np.where(scale > 1e-9, scale, 1.0)
        lr = LogisticRegression(C=C, class_weight="balanced", max_iter=1000)
        lr.fit((cues - mean) / scale, is_novel.astype(np.int64))
        return cls(mean, scale, lr.coef_[0], lr.intercept_[0])

    @classmethod
    def only_maxp(cls) -> CueCombiner:
        """1 - max p alone (used when the known set is too small for pseudo-novel folds)."""
        coef = np.zeros(len(CUES))
        coef[0] = 1.0
        return cls(np.zeros(len(CUES)), np.ones(len(CUES)), coef, 0.0)

    def score(self, cues: np.ndarray) -> np.ndarray:
        return ((cues - self.mean) / self.scale) @ self.coef + self.intercept

    def get_state(self) -> dict[str, np.ndarray]:
        return {"mean": self.mean, "scale": self.scale, "coef": self.coef,
                "intercept": np.asarray([self.intercept])}

    @classmethod
    def from_state(cls, arrays: dict[str, np.ndarray]) -> CueCombiner:
        return cls(arrays["mean"], arrays["scale"], arrays["coef"], float(arrays["intercept"][0]))


def _relabelled(dataset: TactileDataset, idx: np.ndarray) -> TactileDataset:
    sub = dataset.subset(idx)
    return sub.select_classes(np.unique(sub.labels))


class KnownModel:
    """ForestCues + CueCombiner: ``known_proba`` and the novelty score of the best method."""

    def __init__(self, cues: ForestCues, combiner: CueCombiner) -> None:
        self.cues_model = cues
        self.combiner = combiner

    @classmethod
    def fit(cls, dataset: TactileDataset, n_estimators: int, max_features, seed: int,
            n_jobs: int | None, meta_folds: int, meta_val_fraction: float, meta_C: float) -> KnownModel:
        x, y, k = flatten(dataset.samples), dataset.labels, dataset.n_classes
        cues, labels = [], []
        for f in range(meta_folds):
            try:
                fit_idx, known_idx, val_idx = novelty_validation_split(
                    dataset, meta_val_fraction, 1, seed=seed + 1009 * (f + 1))
            except DatasetError:
                break
            if len(known_idx) == 0 or len(val_idx) == 0:
                break
            sub = _relabelled(dataset, fit_idx)
            fold = ForestCues.fit(flatten(sub.samples), sub.labels, sub.n_classes, n_estimators,
                                  max_features, seed + f + 1, n_jobs)
            for idx, novel in ((known_idx, 0), (val_idx, 1)):
                z = fold.scaled(x[idx])
                cues.append(fold.cues(z, fold.proba(z)))
                labels.append(np.full(len(idx), novel))
        if cues:
            combiner = CueCombiner.fit(np.concatenate(cues), np.concatenate(labels), meta_C)
        else:
            combiner = CueCombiner.only_maxp()
        model = ForestCues.fit(x, y, k, n_estimators, max_features, seed, n_jobs)
        return cls(model, combiner)

    def scores(self, x_flat: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(scaled inputs, known-class probabilities, novelty scores)."""
        z = self.cues_model.scaled(x_flat)
        p = self.cues_model.proba(z)
        return z, p, self.combiner.score(self.cues_model.cues(z, p))

    def get_state(self) -> dict[str, np.ndarray]:
        out = self.cues_model.get_state()
        out.update({f"combiner/{k}": v for k, v in self.combiner.get_state().items()})
        return out

    @classmethod
    def from_state(cls, arrays: dict[str, np.ndarray], n_classes: int, n_features: int) -> KnownModel:
        comb = {k[len("combiner/"):]: v for k, v in arrays.items() if k.startswith("combiner/")}
        rest = {k: v for k, v in arrays.items() if not k.startswith("combiner/")}
        return cls(ForestCues.from_state(rest, n_classes, n_features), CueCombiner.from_state(comb))
