"""Baselines measured beside the paper's pipeline (docs/RESULTS.md), each a ``TactileRecognizer``.

- ``extratrees``  extra-trees for known classes and max-probability novelty; DAP with
  extra-trees attribute classifiers for zero-shot; nearest class mean for one-shot
- ``dap``         Direct Attribute Prediction (Lampert et al.) with logistic attribute
  classifiers; known classes, novelty and one-shot as ``extratrees``
- ``eszsl``       ESZSL closed form (Romera-Paredes and Torr, 2015); known classes,
  novelty and one-shot as ``extratrees``

They are evaluation-only: tree ensembles are not stored in model bundles.
"""
