"""Defaults that light modules need without importing the methods: ``app.config`` reads the
default method from here, so loading the settings does not load numpy, the data loaders
or the recognizer interface. Only the standard library may be imported here."""

from __future__ import annotations

# the service uses the method that measured better on the mixed known/novel
# figure (gzsl_h, docs/RESULTS.md); the paper pipeline stays selectable as "paper".
DEFAULT_METHOD = "best"
