"""Datasets: the one in-memory form, the PHAC-2 loader and the built-in tactile simulator."""

from app.data.dataset import DatasetError, TactileDataset

__all__ = ["DatasetError", "TactileDataset"]
