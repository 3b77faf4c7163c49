"""Defaults that light modules need without importing the methods: ``app.config`` reads the
default method from here, so loading the settings does not load numpy, the data loaders
or the recognizer interface. Only the standard library may be imported here."""

from __future__ import annotations

# the service fits whichever of best and prototypes measures better on a probe of its own
# training data (app/methods/choice.py): best's figures on PHAC-2, shrinkage LDA's on
# thousands of simulated objects (docs/RESULTS.md, docs/BENCHMARKS.md); each method, and
# the paper pipeline ("paper"), stays selectable by name.
#: the method that chooses among the others (app/methods/choice.py), by name
AUTO = "auto"
DEFAULT_METHOD = AUTO

# the operating point every served answer is routed by unless one is asked for: the novelty
# threshold that kept this share of held-out known touches known at fit, for every method
# that holds a calibration curve (the service's TACTILE_KNOWN_KEPT, the client's model file,
# the ROS 2 bridge); prototypes fits its own threshold at the same share
DEFAULT_KNOWN_KEPT = 0.90
