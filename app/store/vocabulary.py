"""The attribute vocabulary as the store keeps it, and class descriptions as keys. No
queries (``repo.vocabulary`` reads one).

Every attribute has a fixed position; a class's description is its ``attribute_key``: one
token per position, comma-separated, the value to 4 decimals (``1``, ``0``, ``0.5``) or
nothing where it is not known, with trailing unknown positions left out. So a key keeps its
meaning when attributes are added after it (they are not known for it), and retiring an
attribute blanks its position in every key (``Vocabulary.without``). Models see only the
*active* attributes (not retired), in position order, as vectors with NaN for a value not
known.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np

#: most attributes one store holds: keys fit ``classes.attribute_key`` (migration 0007)
MAX_ATTRIBUTES = 256


def token(value: float | None) -> str:
    if value is None or math.isnan(value):
        return ""
    return f"{float(value):.4f}".rstrip("0").rstrip(".")


def vector_key(values: Iterable[float | None]) -> str:
    """The key of values by position (None or NaN: not known)."""
    return ",".join(token(v) for v in values).rstrip(",")


def key_values(key: str, length: int) -> list[float | None]:
    """The values of a key, by position, padded with None (not known) to ``length``."""
    out: list[float | None] = [float(t) if t else None for t in key.split(",")] if key else []
    return out + [None] * (length - len(out))


@dataclass(frozen=True)
class Vocabulary:
    """Every attribute by position; which are retired, and which the bootstrap dataset
    brought (their values for the dataset's classes stay fixed)."""

    names: tuple[str, ...] = ()
    retired: frozenset[str] = field(default_factory=frozenset)
    fixed: frozenset[str] = field(default_factory=frozenset)

    @property
    def active(self) -> tuple[str, ...]:
        """The attributes models learn, in position order (``GET /v1/attributes``)."""
        return tuple(n for n in self.names if n not in self.retired)

    def values(self, key: str) -> dict[str, float]:
        """The known values of the active attributes, by name. A key may be longer than
        this vocabulary: an attribute added after it was read (a worker plans on the
        vocabulary it read first; a class registered in between may carry the newer
        attribute's value). Those positions are not this vocabulary's to read; the job
        that added the attribute relearns the attribute parts with them."""
        by_position = key_values(key, len(self.names))[: len(self.names)]
        return {
            n: v
            for n, v in zip(self.names, by_position, strict=True)
            if v is not None and n not in self.retired
        }

    def vector(self, key: str) -> np.ndarray:
        """float32 over the active attributes, NaN where not known."""
        known = self.values(key)
        return np.array([known.get(n, np.nan) for n in self.active], np.float32)

    def key(self, values: Mapping[str, float | None], base: str = "") -> str:
        """``base`` with the named attributes set to ``values`` (None: not known)."""
        by_position = key_values(base, len(self.names))
        position = {n: i for i, n in enumerate(self.names)}
        for name, value in values.items():
            by_position[position[name]] = value
        return vector_key(by_position)

    def key_of_vector(self, vector: Sequence[float | None]) -> str:
        """The key of a vector over the active attributes (None or NaN: not known)."""
        return self.key(dict(zip(self.active, vector, strict=True)))

    def without(self, key: str, name: str) -> str:
        """The key with ``name``'s value blanked (the attribute retired)."""
        return self.key({name: None}, base=key)


def describes(vocab: Vocabulary, key: str) -> bool:
    """Whether the key says something a model can recognise a class by: an active
    attribute's value above 0."""
    return any(v > 0 for v in vocab.values(key).values())
