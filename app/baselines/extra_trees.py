"""Extra-trees baseline (issue 5): a strong non-neural classifier for known classes and novelty.

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
    method = "extratrees"

    def __init__(self, attribute_estimators: int = 300, clip: float = 0.02, **base) -> None:
        super().__init__(
            attribute_model="extratrees",
            attribute_estimators=attribute_estimators,
            clip=clip,
            **base,
        )
