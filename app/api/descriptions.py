"""Class descriptions from request bodies to store keys, against the store's vocabulary
(``app.store.vocabulary``): registration and ``PATCH`` accept an attribute the moment it is
added, before any model has learnt it."""

from __future__ import annotations

from collections.abc import Iterable

from app.api.problems import Problem
from app.api.schemas import ClassDescription
from app.framework.recognizer import suggest_attribute
from app.store.vocabulary import Vocabulary, describes


def field_of(body: ClassDescription) -> str:
    return "attributes" if body.attributes is not None else "attribute_vector"


def description_key(body: ClassDescription, vocab: Vocabulary, base: str = "") -> str:
    """The key ``body`` describes. A list of names: these 1, every other active attribute
    0. A mapping: the named values set on ``base`` (others keep theirs, or are not known for
    a new class). A vector: one value (or null) per active attribute. 422 naming the problem
    for a name not in use, a vector of the wrong length, or no value above 0."""
    active = vocab.active
    if not active:
        raise Problem(
            409,
            "the vocabulary is empty: add attributes (POST /v1/attributes) before describing "
            "a class, or register it with its samples",
            field_of(body),
        )
    if isinstance(body.attributes, list):
        check_names(body.attributes, vocab, "attributes")
        named = set(body.attributes)
        key = vocab.key({n: 1.0 if n in named else 0.0 for n in active})
    elif body.attributes is not None:
        check_names(body.attributes, vocab, "attributes")
        key = vocab.key(body.attributes, base=base)
    else:
        vector = body.attribute_vector
        if len(vector) != len(active):
            raise Problem(
                422,
                f"expected {len(active)} values, one per attribute in GET /v1/attributes "
                f"order, got {len(vector)}",
                "attribute_vector",
            )
        key = vocab.key_of_vector(vector)
    if not describes(vocab, key):
        raise Problem(
            422,
            "a description needs at least one attribute with a value above 0",
            field_of(body),
        )
    return key


def check_names(names: Iterable[str], vocab: Vocabulary, field: str) -> None:
    """422 for names that are not attributes in use, with the closest ones for a typo."""
    active = vocab.active
    unknown = [n for n in names if n not in active]
    if not unknown:
        return

    def named(name: str) -> str:
        return f"'{name}' (retired)" if name in vocab.retired else suggest_attribute(active)(name)

    raise Problem(
        422,
        f"unknown attribute(s): {'; '.join(map(named, unknown))}; the attributes are: "
        f"{', '.join(active)}",
        field,
    )
