"""What ``best`` and ``prototypes`` share around their known parts: the check of the classes
a fit is given, and the zero-shot part (DAP's attribute classifiers, the prior and the
semantic autoencoder, ``app.methods.attributes``) read from the method's own
hyper-parameters (``attribute_C``, ``attribute_samples``, ``sae_lambda``, ``dap_clip``,
``sae_temperature``, ``seed``, ``n_jobs``)."""

from __future__ import annotations

import numpy as np

from app.data.dataset import DatasetError, TactileDataset
from app.methods.attributes import fit_zero_shot, zero_shot_proba


def check_known_classes(dataset: TactileDataset, method: str) -> None:
    """DatasetError unless the dataset has at least 2 classes, each with samples."""
    if dataset.n_classes < 2:
        raise DatasetError(f"the {method} method needs at least 2 known classes")
    present = np.unique(dataset.labels)
    if len(present) != dataset.n_classes:
        missing = sorted(set(range(dataset.n_classes)) - set(present.tolist()))
        raise DatasetError(f"every known class needs samples; none for classes {missing[:5]}")


class DescribedClasses:
    """The zero-shot part of a method (the module docstring); sets ``attributes_``,
    ``prior_`` and ``sae_``."""

    def _fit_attributes(self, z: np.ndarray, y: np.ndarray) -> None:
        """The parts that learn attributes, from the scaled training inputs ``z`` and their
        class indices ``y``. The known classes' vectors are (K, M) values in [0, 1] or NaN
        (not known), or (K, 0) without any attribute: then the attribute model predicts
        nothing and zero-shot enrolment is refused."""
        self.attributes_, self.prior_, self.sae_ = fit_zero_shot(
            z,
            y,
            self.registry.known_attributes,
            self.attribute_C,
            self.attribute_samples,
            self.sae_lambda,
            self.seed,
            self.n_jobs,
        )

    def _zero_shot(self, z: np.ndarray) -> np.ndarray:
        """(N, L) zero-shot posterior over the registry's novel classes."""
        return zero_shot_proba(
            z,
            self.attributes_,
            self.prior_,
            self.sae_,
            self.registry.novel_attributes,
            self.dap_clip,
            self.sae_temperature,
        )
