"""Class descriptions from request bodies to store keys, against the store's vocabulary
(``app.store.vocabulary``): registration and ``PATCH`` accept an attribute the moment it is
added, before any model has learnt it."""

from __future__ import annotations

from collections.abc import Iterable

from app.api.problems import Problem
from app.api.schemas import ClassDescription, ReadingOut
from app.framework.recognizer import suggest_attribute
from app.store.vocabulary import Vocabulary, describes
from app.words.embedding import EmbeddingModelError
from app.words.interpret import NothingRecognised, Reading, TextError, TextInterpreter


def field_of(body: ClassDescription) -> str:
    if body.attributes is not None:
        return "attributes"
    return "attribute_vector" if body.attribute_vector is not None else "description"


def read_text(
    text: str, vocab: Vocabulary, interpreter: TextInterpreter, field: str
) -> dict[str, Reading]:
    """The readings of ``text`` over the active vocabulary; 422 naming the problem (empty,
    too long, nothing the vocabulary knows, with the closest attributes), 503 when the
    sentence-embedding model is not installed."""
    if not vocab.active:
        raise Problem(
            409, "the vocabulary is empty: add attributes (POST /v1/attributes) first", field
        )
    try:
        return interpreter.interpret(text, vocab.active)
    except NothingRecognised as exc:
        raise Problem(422, f"{exc} (GET /v1/attributes lists them all)", field) from None
    except TextError as exc:
        raise Problem(422, str(exc), field) from None
    except EmbeddingModelError as exc:
        raise Problem(503, str(exc), field) from None


def readings_out(readings: dict[str, Reading]) -> list[ReadingOut]:
    return [
        ReadingOut(attribute=r.attribute, value=r.value, words=r.words, source=r.source)
        for r in readings.values()
    ]


def stored_readings(readings: dict[str, Reading] | None) -> list[dict] | None:
    """Readings as a class keeps them (``classes.description_readings``)."""
    return None if readings is None else [r.model_dump() for r in readings_out(readings)]


def description_key(
    body: ClassDescription,
    vocab: Vocabulary,
    base: str = "",
    read: dict[str, Reading] | None = None,
) -> str:
    """The key ``body`` describes. A list of names: these 1, every other active attribute
    0. A mapping: the named values set on ``base`` (others keep theirs, or are not known for
    a new class). A vector: one value (or null) per active attribute. ``read``: the values
    read from ``body.description`` (``read_text``), set on ``base`` as a mapping is, under
    the values given beside them, which must not contradict them. 422 naming the problem
    for a name not in use, a vector of the wrong length, a contradiction, or no value
    above 0."""
    active = vocab.active
    if not active:
        raise Problem(
            409,
            "the vocabulary is empty: add attributes (POST /v1/attributes) before describing "
            "a class, or register it with its samples",
            field_of(body),
        )
    if body.attributes is None and body.attribute_vector is None:
        key = vocab.key({a: r.value for a, r in (read or {}).items()}, base=base)
    elif isinstance(body.attributes, list):
        check_names(body.attributes, vocab, "attributes")
        named = set(body.attributes)
        given = {n: 1.0 if n in named else 0.0 for n in active}
        _agree(read, given, "attributes")
        key = vocab.key(given)
    elif body.attributes is not None:
        check_names(body.attributes, vocab, "attributes")
        _agree(read, body.attributes, "attributes")
        values = {a: r.value for a, r in (read or {}).items()}
        key = vocab.key({**values, **body.attributes}, base=base)
    else:
        vector = body.attribute_vector
        if len(vector) != len(active):
            raise Problem(
                422,
                f"expected {len(active)} values, one per attribute in GET /v1/attributes "
                f"order, got {len(vector)}",
                "attribute_vector",
            )
        _agree(read, dict(zip(active, vector, strict=True)), "attribute_vector")
        key = vocab.key_of_vector(vector)
    if not describes(vocab, key):
        raise Problem(
            422,
            "a description needs at least one attribute with a value above 0",
            field_of(body),
        )
    return key


def _agree(read: dict[str, Reading] | None, given: dict, field: str) -> None:
    """422 where a value given beside a description contradicts what was read from it."""
    for name, value in given.items():
        reading = (read or {}).get(name)
        if reading is not None and value is not None and abs(float(value) - reading.value) >= 0.5:
            raise Problem(
                422,
                f"the description says '{reading.words}' ({name} {reading.value:g}) but "
                f"{field} gives {name} {float(value):g}: correct one of them",
                field,
            )


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
