"""Extra-trees baseline: a strong non-neural classifier for known classes and novelty.

Known classes: ``ExtraTreesClassifier`` on robust-scaled flat inputs; novelty score
1 − max probability, threshold tuned by ``novelty_validation_split`` +
``tune_threshold`` (Sect. VI-B), see ``common``. Zero-shot: DAP on the same
features with the attribute classifiers being extra-trees too (one multi-output
forest), so the whole method is tree-based; one-shot: nearest class mean that
includes the one-shot sample (``common``). The ``dap`` method differs only in its
attribute classifiers (logistic regression).
"""

from __future__ import annotations

from app.baselines.dap import DAPRecognizer


class ExtraTreesRecognizer(DAPRecognizer):
    """DAP with a multi-output extra-trees forest as its attribute classifiers.

    Parameters
    ----------
    attribute_estimators : int, default 300
        Trees of the multi-output forest that predicts every attribute from a sample.
    clip : float, default 0.02
        Attribute probabilities, and the attribute prior, are clipped to
        [clip, 1 - clip], so that no single attribute classifier can veto a novel
        class alone. In (0, 0.5).
    n_estimators, max_features, min_samples_leaf, novelty_val_fraction,
    novelty_holdout_trials, seed, n_jobs
        The known-class forest and the novelty tuning, with ``ForestBaseline``'s
        meanings and defaults.
    featurizer_params
        The raw-trial featurizer's options, as ``ForestBaseline`` takes them.
    """

    method = "extratrees"

    def __init__(
        self,
        attribute_estimators: int = 300,
        clip: float = 0.02,
        n_estimators: int = 300,
        max_features: str | float = "sqrt",
        min_samples_leaf: int = 1,
        novelty_val_fraction: float = 0.1,
        novelty_holdout_trials: int = 1,
        seed: int = 0,
        n_jobs: int | None = -1,
        featurizer_params: dict | None = None,
    ) -> None:
        # DAP's other parameters keep DAP's defaults; C and the validation folds serve
        # only logistic attribute classifiers
        super().__init__(
            attribute_model="extratrees",
            attribute_estimators=attribute_estimators,
            clip=clip,
            n_estimators=n_estimators,
            max_features=max_features,
            min_samples_leaf=min_samples_leaf,
            novelty_val_fraction=novelty_val_fraction,
            novelty_holdout_trials=novelty_holdout_trials,
            seed=seed,
            n_jobs=n_jobs,
            featurizer_params=featurizer_params,
        )
