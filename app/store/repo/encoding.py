"""How the store writes values down: attribute vectors as digit strings, samples as
float32 bytes with their shape, metrics as strict JSON. No queries."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np


def vector_key(vector: Iterable[float]) -> str:
    """A 0/1 attribute vector as a string of digits: comparable and indexable."""
    return "".join("1" if v >= 0.5 else "0" for v in vector)


def key_vector(key: str) -> np.ndarray:
    return np.array([c == "1" for c in key], dtype=np.float32)


def attribute_labels(key: str, vocabulary: Sequence[str]) -> list[str]:
    return [name for name, bit in zip(vocabulary, key, strict=False) if bit == "1"]


def encode_sample(sample: np.ndarray) -> tuple[bytes, list[int]]:
    x = np.ascontiguousarray(sample, dtype=np.float32)
    return x.tobytes(), list(x.shape)


def decode_sample(data: bytes, shape: Sequence[int]) -> np.ndarray:
    return np.frombuffer(data, dtype=np.float32).reshape(tuple(shape))
