"""Recognition methods beyond the paper's pipeline, measured in docs/RESULTS.md.

- ``best``  the ``best`` method: extra-trees known-class forest whose max-probability
  is the novelty score, DAP with logistic attribute classifiers for zero-shot, and
  one-shot by cosine similarity of known-class posterior signatures
- ``forest``  tree ensembles stored as plain arrays (no pickle) with numpy inference
- ``attributes``  per-attribute logistic classifiers as arrays, and DAP scoring
"""
