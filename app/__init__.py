"""Tactile recognition of known and novel objects (Abderrahmane et al.), as a service."""

__version__ = "0.1.0"
