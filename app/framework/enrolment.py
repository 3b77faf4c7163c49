"""Enrolment: how a fitted recognizer grows without a full refit.

``Enrolment`` gives ``TactileRecognizer`` its enrolment methods: zero-shot classes described
by attributes (``add_novel_classes``), novel classes learnt from samples alone
(``add_novel_classes_from_samples``), one-shot samples (``add_one_shot``), known classes
learnt incrementally (``with_known_samples``), dropping the novel part
(``without_novel_classes``), and the checks of attribute vectors and names they take. Each
returns a *new* recognizer; the original is untouched. A method's own parts come in through
the hooks ``_refit_novel``, ``_grow_known`` and ``_reset_novel``, and its capabilities through
``TactileRecognizer``'s class flags (``novel_part_separable``, ``learns_classes_from_samples``,
``graded_attributes``, ``learns_known_incrementally``).
"""

from __future__ import annotations

import copy
import difflib
from collections.abc import Callable, Mapping, Sequence
from typing import Any, Self

import numpy as np

from app.framework.errors import (
    AttributeVectorError,
    DuplicateClassError,
    FrameworkError,
    UnknownClassError,
    UnsupportedOperationError,
    ZeroShotUnavailableError,
)


class Enrolment:
    """The enrolment methods of ``TactileRecognizer`` (see the module docstring); they use
    its registry, flags, ``validate_samples`` and ``_refit_novel``."""

    def add_novel_classes(
        self,
        names: Sequence[str],
        attribute_vectors: np.ndarray | Sequence[Sequence[float]],
        *,
        allow_known_vectors: bool = False,
        **options: Any,
    ) -> Self:
        """Zero-shot enrolment: a new recognizer that also recognises these classes.

        A novel class whose attribute vector equals an existing class's is refused:
        FC_Z could never tell them apart from attributes. ``allow_known_vectors``
        relaxes that for *known* classes only, as the paper's evaluation splits do
        (routing by novelty detection still separates them); novel classes must
        always differ from each other.

        A model fitted without attributes (M = 0) has nothing to recognise a described
        class by: ZeroShotUnavailableError (enrol such a class with
        ``add_novel_classes_from_samples``).
        """
        self._require_fitted()
        if not self.has_attributes:
            raise ZeroShotUnavailableError(
                "this model was fitted on classes without attributes: a class without "
                "attributes cannot be recognised zero-shot; add samples "
                "(add_novel_classes_from_samples)"
            )
        names = [str(n) for n in names]
        vectors = self.validate_attribute_vectors(attribute_vectors)
        if len(names) != len(vectors):
            raise AttributeVectorError(f"{len(names)} names but {len(vectors)} attribute vectors")
        reg = self.registry
        existing = set(reg.all_names)
        all_vectors = (
            reg.novel_attributes
            if allow_known_vectors
            else np.concatenate([reg.known_attributes, reg.novel_attributes])
        )
        existing_names = reg.novel_names if allow_known_vectors else reg.all_names
        for i, name in enumerate(names):
            if not name.strip():
                raise DuplicateClassError("a class name must not be empty")
            if name in existing or names.count(name) > 1:
                raise DuplicateClassError(f"class '{name}' already exists")
            same = np.flatnonzero(same_vectors(all_vectors, vectors[i]))
            if len(same):
                other = existing_names[same[0]]
                raise DuplicateClassError(
                    f"class '{name}' has the same attribute vector as existing class '{other}'"
                )
            same_new = [names[j] for j in range(i) if same_vectors(vectors[j][None], vectors[i])[0]]
            if same_new:
                raise DuplicateClassError(
                    f"classes '{same_new[0]}' and '{name}' have the same attribute vector"
                )
        new = copy.deepcopy(self)
        new.registry.novel_names = reg.novel_names + names
        new.registry.novel_attributes = np.concatenate([reg.novel_attributes, vectors]).astype(
            np.float32
        )
        new._refit_novel(**options)
        return new

    def add_novel_classes_from_samples(
        self, samples: Mapping[str, np.ndarray], **options: Any
    ) -> Self:
        """Novel classes without a description, learnt from their real samples alone: a new
        recognizer that also recognises them. ``samples``: class name -> its samples (at
        least one; for a raw-trial model, e.g. ``trial_samples([trial])[0]``). Later samples
        come with ``add_one_shot`` as for any novel class.

        Only methods that can recognise a class from its samples alone (``best``) take
        them: on a model without attributes (M = 0), or one with ``graded_attributes``, where
        such a class's vector is not known for every attribute. Elsewhere a novel class is
        described by attributes (``add_novel_classes``) and UnsupportedOperationError says so.
        """
        self._require_fitted()
        if self.has_attributes and not self.graded_attributes:
            raise UnsupportedOperationError(
                "this model describes classes by attributes: enrol a class with its attributes "
                "(add_novel_classes), then add its samples (add_one_shot)"
            )
        if not self.learns_classes_from_samples:
            raise UnsupportedOperationError(
                f"method '{self.method}' cannot recognise a class from its samples alone "
                "(without attributes); method 'best' can"
            )
        if not isinstance(samples, Mapping) or not samples:
            raise FrameworkError("give at least one class: a mapping of class name -> samples")
        reg = self.registry
        checked: dict[str, np.ndarray] = {}
        for name, x in samples.items():
            name = str(name)
            if not name.strip():
                raise DuplicateClassError("a class name must not be empty")
            if name in reg.all_names or name in checked:
                raise DuplicateClassError(f"class '{name}' already exists")
            checked[name] = self.validate_samples(x)
        new = copy.deepcopy(self)
        new.registry.novel_names = reg.novel_names + list(checked)
        unknown = np.full((len(checked), len(reg.attribute_names)), np.nan, np.float32)
        new.registry.novel_attributes = np.concatenate([reg.novel_attributes, unknown])
        new.registry.novel_samples.update(checked)
        new._refit_novel(**options)
        return new

    def add_one_shot(self, class_name: str, samples: np.ndarray, **options: Any) -> Self:
        """One-shot learning: real samples of a novel class refine FC_Z (Sect. IV-F).
        For a raw-trial model the samples are tactile images, ``trial_samples([trial])[0]``
        for one trial (both fingers)."""
        self._require_fitted()
        kind = self.registry.kind_of(class_name)
        if kind != "novel":
            raise UnknownClassError(
                f"class '{class_name}' is a known class; one-shot samples are for novel classes"
            )
        x = self.validate_samples(samples)
        new = copy.deepcopy(self)
        prev = new.registry.novel_samples.get(class_name)
        new.registry.novel_samples[class_name] = x if prev is None else np.concatenate([prev, x])
        new._refit_novel(**options)
        return new

    def with_known_samples(
        self,
        samples: Mapping[str, np.ndarray],
        attribute_vectors: Mapping[str, Any] | None = None,
    ) -> Self:
        """Known classes learnt without a refit: a new recognizer in which every class named
        in ``samples`` (name -> its samples, as for ``add_one_shot``) is known and has learnt
        those samples. A known class gains them; a novel class is promoted (with the
        attribute vector it was enrolled with); a new name becomes a known class, described
        by ``attribute_vectors[name]`` (not known, NaN, where the method takes graded
        attributes and none is given). The other novel classes stay. Only for methods with
        ``learns_known_incrementally``; the result differs from a model fitted on everything
        by what the method's ``_grow_known`` documents."""
        self._require_fitted()
        if not self.learns_known_incrementally:
            raise UnsupportedOperationError(
                f"method '{self.method}' cannot learn known classes without a refit; fit it "
                "again instead"
            )
        if not isinstance(samples, Mapping) or not samples:
            raise FrameworkError("give at least one class: a mapping of class name -> samples")
        vectors = dict(attribute_vectors or {})
        reg = self.registry
        new = copy.deepcopy(self)
        nreg = new.registry
        known = list(reg.known_names)
        added: list[np.ndarray] = []
        grown: list[tuple[int, np.ndarray]] = []  # (known class index, its samples)
        for name, x in samples.items():
            name = str(name)
            if not name.strip():
                raise DuplicateClassError("a class name must not be empty")
            if name in vectors and name in reg.known_names:
                raise FrameworkError(f"class '{name}' is known already: it keeps its attributes")
            if name in reg.novel_names:
                i = nreg.novel_names.index(name)
                vector = nreg.novel_attributes[i]
                nreg.novel_names = nreg.novel_names[:i] + nreg.novel_names[i + 1 :]
                nreg.novel_attributes = np.delete(nreg.novel_attributes, i, axis=0)
                nreg.novel_samples.pop(name, None)
            elif name not in reg.known_names:
                if name in vectors:
                    vector = self.validate_attribute_vectors([vectors[name]])[0]
                elif self.graded_attributes or not self.has_attributes:
                    vector = np.full(len(reg.attribute_names), np.nan, np.float32)
                else:
                    raise AttributeVectorError(f"new known class '{name}' needs its attributes")
            if name not in known:
                known.append(name)
                added.append(np.asarray(vector, np.float32)[None])
            grown.append((known.index(name), self.validate_samples(x)))
        nreg.known_names = known
        if added:
            nreg.known_attributes = np.concatenate([reg.known_attributes, *added]).astype(
                np.float32
            )
        new._grow_known(
            np.concatenate([x for _, x in grown]),
            np.concatenate([np.full(len(x), c, np.int64) for c, x in grown]),
        )
        new._refit_novel()
        return new

    def _grow_known(self, samples: np.ndarray, labels: np.ndarray) -> None:
        """Learn ``samples`` of known classes ``labels`` (indices into the registry's known
        classes, which already lists any new ones); ``learns_known_incrementally`` methods
        override it."""
        raise UnsupportedOperationError(f"method '{self.method}' cannot grow its known part")

    def without_novel_classes(self) -> Self:
        """A new recognizer with the known part only: no novel class, no one-shot sample.
        Only for methods with ``novel_part_separable``; others must be fitted again."""
        self._require_fitted()
        if not self.novel_part_separable:
            raise UnsupportedOperationError(
                f"method '{self.method}' adapts shared parts to enrolments; fit it again instead"
            )
        new = copy.deepcopy(self)
        reg = new.registry
        reg.novel_names, reg.novel_samples = [], {}
        reg.novel_attributes = np.zeros((0, len(reg.attribute_names)), np.float32)
        new._reset_novel()
        return new

    def _reset_novel(self) -> None:
        """Forget FC_Z; methods with ``novel_part_separable`` override it."""
        raise UnsupportedOperationError(f"method '{self.method}' cannot drop its novel classes")

    def validate_attribute_vectors(self, vectors: Any) -> np.ndarray:
        m = len(self.registry.attribute_names)
        try:
            v = np.asarray(vectors, dtype=np.float32)
        except (TypeError, ValueError) as exc:
            raise AttributeVectorError(f"attribute vectors are not numeric: {exc}") from None
        if v.ndim == 1:
            v = v[None]
        if v.ndim != 2 or v.shape[1] != m:
            raise AttributeVectorError(
                f"expected attribute vectors of length {m}, got shape {v.shape}"
            )
        if self.graded_attributes:
            known = ~np.isnan(v)
            if not ((v[known] >= 0) & (v[known] <= 1)).all():
                raise AttributeVectorError(
                    "attribute values must lie in [0, 1] (NaN: not known), got "
                    f"{float(v[known][(v[known] < 0) | (v[known] > 1)][0])}"
                )
        elif not np.isin(v, (0.0, 1.0)).all():
            raise AttributeVectorError(
                f"attribute vectors must contain only 0 and 1 (method '{self.method}' learns "
                "0/1 attributes; method 'best' takes graded and not-known values)"
            )
        if (np.nan_to_num(v).sum(axis=1) == 0).any():
            raise AttributeVectorError(
                "an attribute vector must have at least one attribute set (a value above 0)"
            )
        return v

    def attribute_vector(self, attribute_names: Sequence[str]) -> np.ndarray:
        """0/1 vector from attribute names; unknown names raise AttributeVectorError."""
        vocab = self.registry.attribute_names
        unknown = [a for a in attribute_names if a not in vocab]
        if unknown:
            raise AttributeVectorError(
                f"unknown attribute(s): {'; '.join(map(suggest_attribute(vocab), unknown))}; "
                f"the attributes are: {', '.join(vocab)}"
            )
        return np.array([1.0 if a in set(attribute_names) else 0.0 for a in vocab], np.float32)


def same_vectors(vectors: np.ndarray, vector: np.ndarray) -> np.ndarray:
    """(L,) bool: which rows of ``vectors`` equal ``vector``, a value not known (NaN) equal
    only to another value not known."""
    vectors, vector = np.asarray(vectors), np.asarray(vector)
    return ((vectors == vector) | (np.isnan(vectors) & np.isnan(vector))).all(axis=1)


def suggest_attribute(vocabulary: Sequence[str]) -> Callable[[Any], str]:
    """An unknown attribute name with the vocabulary's closest ones, for a typo."""

    def named(name: Any) -> str:
        close = difflib.get_close_matches(str(name), vocabulary, n=2, cutoff=0.6)
        return f"{name!r} (did you mean {' or '.join(map(repr, close))}?)" if close else repr(name)

    return named
