"""Enrolment: the rules for registering, describing and withdrawing classes and samples,
and for growing and retiring the attribute vocabulary, and the jobs that bring each change
into the served model.

Routes (``app/api/routes/classes.py``, ``samples.py``, ``attributes.py``) and tests call
these functions with what a request asked for, already parsed. Each rule broken raises an
``EnrolmentError`` naming the field at fault; ``app.api.problems`` answers each kind with
its status (``NotFound`` 404, ``Conflict`` 409, ``Invalid`` 422, ``ReaderUnavailable``
503).

Every write runs inside ``writing(session, recheck)`` and ends with ``finish(...)``, which
commits. A route passes its ``Idempotency``'s ``writing`` (a concurrent retry with the same
key replays its answer) and a ``finish`` that stores the answer in the same transaction;
the defaults (``guarded``, a plain commit) serve callers without idempotency keys. A unique
constraint broken by a concurrent write is named by ``recheck`` as the conflict it is.

Class descriptions are keys over the store's vocabulary (``app.store.vocabulary``):
registration and redescription accept an attribute the moment it is added, before any
model has learnt it.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator, Mapping
from contextlib import AbstractContextManager, contextmanager
from typing import Any, NamedTuple, Protocol, TypeVar

import numpy as np
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session

from app.framework.recognizer import suggest_attribute
from app.store import repo
from app.store.enums import ClassKind, JobKind, Origin
from app.store.models import Attribute, Job, ObjectClass, Sample
from app.store.vocabulary import MAX_ATTRIBUTES, Vocabulary, describes
from app.words.embedding import EmbeddingModelError
from app.words.estimate import UnmentionedEstimator, estimated_readings
from app.words.interpret import NothingRecognised, Reading, TextError, TextInterpreter

T = TypeVar("T")


# ------------------------------------------------------------------------- errors
class EnrolmentError(Exception):
    """A rule of enrolment the request broke; ``field`` names the part at fault."""

    def __init__(self, message: str, field: str | None = None) -> None:
        super().__init__(message)
        self.field = field


class NotFound(EnrolmentError):
    """No live class (or sample) of that id."""

    def __init__(self, what: str, field: str, value: Any) -> None:
        super().__init__(f"no {what} with {field} {value}", field)


class Conflict(EnrolmentError):
    """The request is well formed but the store's state refuses it."""


class NameTaken(Conflict):
    """A live class has the name."""


class SameDescription(Conflict):
    """A live class has the same attribute vector: no model could tell them apart."""


class KnownClass(Conflict):
    """Samples sent for a known class, which is learnt from its training samples."""


class DatasetClass(Conflict):
    """What only enrolled classes and samples allow, asked of the training dataset's."""


class CannotLearn(Conflict):
    """The method cannot learn a class from what the registration gives it."""


class AttributeTaken(Conflict):
    """An attribute of the name exists, or existed: names are never reused."""


class VocabularyFull(Conflict):
    """The vocabulary holds its most attributes."""


class RetiredAttribute(Conflict):
    """The attribute is retired already."""


class DescribedByNothing(Conflict):
    """A change that would leave a class nothing to be recognised by."""


class EmptyVocabulary(Conflict):
    """A class described by attributes while the vocabulary holds none."""


class Invalid(EnrolmentError):
    """Well-formed content the store's state makes meaningless."""


class UnknownClassName(Invalid):
    """A name no live class has."""


class InvalidDescription(Invalid):
    """A description that names unknown attributes, has the wrong length, contradicts the
    text beside it, gives no value above 0, or whose text names nothing known."""


class ReaderUnavailable(EnrolmentError):
    """The sentence-embedding model that reads descriptions in words is not installed."""


# -------------------------------------------------------------------- transactions
class Description(Protocol):
    """How a class is described (``ClassDescription``'s fields): attribute names (a list)
    or values (a mapping), a vector, and/or a text."""

    attributes: list[str] | dict[str, float | None] | None
    attribute_vector: list[float | None] | None
    description: str | None


Writing = Callable[[Session, Callable[[], None] | None], AbstractContextManager[None]]


class Enrolled(NamedTuple):
    """What the default ``finish`` gives back: the class (or the attribute) changed, and the
    job that brings the change into the model."""

    cls: ObjectClass | Attribute
    job: Job


@contextmanager
def guarded(session: Session, recheck: Callable[[], None] | None = None) -> Iterator[None]:
    """A write whose unique constraint broken by a concurrent write is named by ``recheck``
    (it raises the conflict), or raised as it is."""
    try:
        yield
    except IntegrityError:
        session.rollback()
        if recheck is not None:
            recheck()
        raise


def _live_class(session: Session, class_id: int) -> ObjectClass:
    """The live class ``class_id``; ``NotFound`` naming ``class_id`` otherwise."""
    cls = repo.get_class(session, class_id)
    if cls is None:
        raise NotFound("class", "class_id", class_id)
    return cls


def _committing(session: Session) -> Callable[[ObjectClass | Attribute, Job], Enrolled]:
    def finish(cls: ObjectClass | Attribute, job: Job) -> Enrolled:
        session.commit()
        return Enrolled(cls, job)

    return finish


# -------------------------------------------------------------------- descriptions
def field_of(described: Description) -> str:
    """The field a description's errors name: the values given, else the text."""
    if described.attributes is not None:
        return "attributes"
    return "attribute_vector" if described.attribute_vector is not None else "description"


def is_described(described: Description) -> bool:
    return (
        described.attributes is not None
        or described.attribute_vector is not None
        or described.description is not None
    )


def read_text(
    text: str, vocab: Vocabulary, interpreter: TextInterpreter, field: str
) -> dict[str, Reading]:
    """The readings of ``text`` over the active vocabulary: ``InvalidDescription`` naming
    the problem (empty, too long, nothing the vocabulary knows, with the closest
    attributes), ``ReaderUnavailable`` when the sentence-embedding model is not installed."""
    if not vocab.active:
        raise EmptyVocabulary(
            "the vocabulary is empty: add attributes (POST /v1/attributes) first", field
        )
    try:
        return interpreter.interpret(text, vocab.active)
    except NothingRecognised as exc:
        raise InvalidDescription(
            f"{exc} (GET /v1/attributes lists them all); an attribute the vocabulary lacks "
            "can be added with POST /v1/attributes",
            field,
        ) from None
    except TextError as exc:
        raise InvalidDescription(str(exc), field) from None
    except EmbeddingModelError as exc:
        raise ReaderUnavailable(str(exc), field) from None


def stored_readings(readings: dict[str, Reading] | None) -> list[dict] | None:
    """Readings as a class keeps them (``classes.description_readings``)."""
    if readings is None:
        return None
    return [
        {"attribute": r.attribute, "value": float(r.value), "words": r.words, "source": r.source}
        for r in readings.values()
    ]


def description_key(
    described: Description,
    vocab: Vocabulary,
    base: str = "",
    read: dict[str, Reading] | None = None,
) -> str:
    """The key ``described`` describes. A list of names: these 1, every other active
    attribute 0. A mapping: the named values set on ``base`` (others keep theirs, or are
    not known for a new class). A vector: one value (or null) per active attribute.
    ``read``: the values read from ``described.description`` (``read_text``), set on
    ``base`` as a mapping is, under the values given beside them, which must not contradict
    them. ``InvalidDescription`` naming the problem for a name not in use, a vector of the
    wrong length, a contradiction, or no value above 0."""
    active = vocab.active
    if not active:
        raise EmptyVocabulary(
            "the vocabulary is empty: add attributes (POST /v1/attributes) before describing "
            "a class, or register it with its samples",
            field_of(described),
        )
    attributes, vector = described.attributes, described.attribute_vector
    if attributes is None and vector is None:
        key = vocab.key({a: r.value for a, r in (read or {}).items()}, base=base)
    elif isinstance(attributes, list):
        check_names(attributes, vocab, "attributes")
        named = set(attributes)
        given = {n: 1.0 if n in named else 0.0 for n in active}
        _agree(read, given, "attributes")
        key = vocab.key(given)
    elif attributes is not None:
        check_names(attributes, vocab, "attributes")
        _agree(read, attributes, "attributes")
        values = {a: r.value for a, r in (read or {}).items()}
        key = vocab.key({**values, **attributes}, base=base)
    else:
        if len(vector) != len(active):
            raise InvalidDescription(
                f"expected {len(active)} values, one per attribute in GET /v1/attributes "
                f"order, got {len(vector)}",
                "attribute_vector",
            )
        _agree(read, dict(zip(active, vector, strict=True)), "attribute_vector")
        key = vocab.key_of_vector(vector)
    if not describes(vocab, key):
        field = field_of(described)
        raise InvalidDescription(
            f"{field} gives no attribute a value above 0: a class needs at least one"
            + (" (name one of GET /v1/attributes)" if field == "attributes" else ""),
            field,
        )
    return key


def _agree(read: dict[str, Reading] | None, given: dict, field: str) -> None:
    """A value given beside a description must not contradict what was read from it (an
    estimate, which the text does not say, gives way to a value given)."""
    for name, value in given.items():
        reading = (read or {}).get(name)
        if reading is None or reading.source == "estimated" or value is None:
            continue
        if abs(float(value) - reading.value) >= 0.5:
            raise InvalidDescription(
                f"the description says '{reading.words}' ({name} {reading.value:g}) but "
                f"{field} gives {name} {float(value):g}: correct one of them",
                field,
            )


def check_names(names: Iterable[str], vocab: Vocabulary, field: str) -> None:
    """``InvalidDescription`` for names that are not attributes in use, with the closest
    ones for a typo."""
    active = vocab.active
    unknown = [n for n in names if n not in active]
    if not unknown:
        return

    def named(name: str) -> str:
        return f"'{name}' (retired)" if name in vocab.retired else suggest_attribute(active)(name)

    raise InvalidDescription(
        f"unknown attribute(s): {'; '.join(map(named, unknown))}; the attributes are: "
        f"{', '.join(active)}; a new one can be added with POST /v1/attributes",
        field,
    )


def _read(
    described: Description, vocab: Vocabulary, interpreter: TextInterpreter, session: Session
) -> dict[str, Reading] | None:
    """The readings of the description's text (None without one), with the attributes it
    does not mention estimated from the live classes' vectors (source ``estimated``)."""
    if described.description is None:
        return None
    read = read_text(described.description, vocab, interpreter, "description")
    return {**read, **estimates(session, vocab, read)}


def estimates(session: Session, vocab: Vocabulary, read: dict[str, Reading]) -> dict:
    """Readings (source ``estimated``) of the active attributes ``read`` is silent on, from
    which attributes go together in the live classes' vectors (``app.words.estimate``);
    none while no live class has a vector."""
    keys = [s.attribute_key for s in repo.class_states(session) if s.attribute_key]
    if not keys:
        return {}
    known = np.stack([vocab.vector(k) for k in keys])
    return estimated_readings(read, UnmentionedEstimator().fit(known, vocab.active))


# -------------------------------------------------------------------------- classes
def register_class(
    session: Session,
    name: str,
    described: Description,
    interpreter: TextInterpreter,
    *,
    requested_by: str | None,
    samples: Callable[[], list] | None = None,
    samples_field: str = "samples",
    method: Any = None,
    model_has_attributes: bool = False,
    writing: Writing = guarded,
    finish: Callable[[ObjectClass, Job], T] | None = None,
) -> T | Enrolled:
    """Register the class ``name``, described by attributes and/or in words (the class
    keeps the text and the values read from it), and queue its ``register_class`` job.

    ``samples``: the class is learnt from samples sent with it too, or from them alone
    where ``described`` describes nothing. It gives the samples or raw trials as the store
    keeps them (its own errors raised as they are), and is called once ``method`` (the
    served recognizer, or the configured method's class before a first model) is known to
    learn a class that way; each sample is stored with an ``add_sample`` job.
    ``model_has_attributes``: the served model describes classes by attributes.

    The name of a withdrawn class gives that class back (same id) with the new
    description and none of its old samples. A class whose registration failed,
    registered again without samples with the same description, gets a new attempt.
    Otherwise a live class of the same name (``NameTaken``) or attribute vector
    (``SameDescription``) refuses it."""
    vocab = repo.vocabulary(session)
    read = _read(described, vocab, interpreter, session)
    field = field_of(described)
    cls = None
    kept: list = []
    if samples is None:
        key = description_key(described, vocab, read=read)
        cls = _failed_registration(session, name, key)
    else:
        key = description_key(described, vocab, read=read) if is_described(described) else ""
        _check_learnable(method, model_has_attributes, is_described(described), samples_field)
        kept = samples()
    if cls is None:
        _check_free(session, name, key, field)
    # a concurrent registration of this name or vector (or a retry with this key) may win
    with writing(session, lambda: _check_free(session, name, key, field)):
        if cls is None:
            cls = _revive_or_add(session, name, key)
        repo.set_description(session, cls, described.description, stored_readings(read))
        for item in kept:
            row = repo.add_sample(session, cls.id, item)
            repo.add_job(session, JobKind.ADD_SAMPLE, cls.id, row.id, requested_by=requested_by)
        job = repo.add_job(session, JobKind.REGISTER_CLASS, cls.id, requested_by=requested_by)
        return (finish or _committing(session))(cls, job)


def redescribe_class(
    session: Session,
    class_id: int,
    described: Description,
    interpreter: TextInterpreter,
    *,
    requested_by: str | None,
    writing: Writing = guarded,
    finish: Callable[[ObjectClass, Job], T] | None = None,
) -> T | Enrolled:
    """Describe the live class ``class_id`` anew, keeping its samples, and queue its
    ``update_class`` job. A list of names or a vector replaces the description; a mapping
    sets the values named and keeps the rest; a text replaces the class's text and sets the
    values read from it, as a mapping does. A class of the training dataset keeps its values
    for the dataset's attributes (``DatasetClass``); a mapping sets its values for
    attributes added since. An enrolled class may not take another's vector
    (``SameDescription``)."""
    cls = _live_class(session, class_id)
    vocab = repo.vocabulary(session)
    field = field_of(described)
    if cls.origin == Origin.DATASET:
        _check_dataset_values(cls, described, vocab)
    read = _read(described, vocab, interpreter, session)
    key = description_key(described, vocab, base=cls.attribute_key, read=read)
    if cls.origin == Origin.ENROLLED:
        _check_vector(session, key, field, other_than=cls.id)
    # a concurrent registration of this vector (or a retry with this key) may win
    with writing(session, lambda: _check_vector(session, key, field, cls.id)):
        repo.redescribe_class(session, cls, key)
        if described.description is not None:
            repo.set_description(session, cls, described.description, stored_readings(read))
        job = repo.add_job(session, JobKind.UPDATE_CLASS, cls.id, requested_by=requested_by)
        return (finish or _committing(session))(cls, job)


def novel_class(session: Session, class_id: int) -> ObjectClass:
    """The live class ``class_id``, one samples can be added to: a novel class (a known
    class is learnt from its training samples; ``KnownClass``)."""
    cls = _live_class(session, class_id)
    if cls.kind != ClassKind.NOVEL:
        raise KnownClass(
            f"class '{cls.name}' is a known class; samples can be added to novel classes only",
            "class_id",
        )
    return cls


#: a sample the served model gives to another class with at least this probability is
#: still accepted, with a warning that it may be of the wrong object
DOUBT_PROBABILITY = 0.9


def doubts(cls: ObjectClass, recognized_as: Mapping[str, Any], served: Iterable[str]) -> list[str]:
    """The warnings a sample added to ``cls`` earns from what the served model made of it
    (``recognized_as``, a ``POST /v1/recognize`` result; ``served``: the model's class
    names): given to another class with probability ``DOUBT_PROBABILITY`` or more, where
    the model knows ``cls``, or, where it does not yet, to a known class it is no novelty to
    (a novel object's first samples go to some other class: that alone is no doubt)."""
    best = recognized_as["top_k"][0] if recognized_as.get("top_k") else None
    if best is None or best["class_name"] == cls.name or best["probability"] < DOUBT_PROBABILITY:
        return []
    if cls.name not in served and recognized_as["is_novel"]:
        return []
    return [
        f"the served model recognises this sample as '{best['class_name']}' (class "
        f"{best.get('class_id')}) with probability {best['probability']:.8g}, not as "
        f"'{cls.name}': it is kept; if it was taken of another object, withdraw it "
        "(DELETE /v1/classes/{class_id}/samples/{sample_id})"
    ]


def add_sample(
    session: Session,
    cls: ObjectClass,
    sample: Any,
    *,
    requested_by: str | None,
    warnings: list[str] | None = None,
    writing: Writing = guarded,
    finish: Callable[[Sample, Job], T] | None = None,
) -> T | tuple[Sample, Job]:
    """Store ``sample`` (an array, or a raw trial kept as sent) for the novel class ``cls``
    (``novel_class``) and queue the ``add_sample`` job that brings it into the model; the
    job keeps ``warnings`` (``doubts``)."""
    with writing(session, None):  # a concurrent retry with this key may win
        row = repo.add_sample(session, cls.id, sample)
        job = repo.add_job(
            session,
            JobKind.ADD_SAMPLE,
            cls.id,
            row.id,
            requested_by=requested_by,
            warnings=warnings,
        )
        if finish is None:
            session.commit()
            return row, job
        return finish(row, job)


def withdraw_class(
    session: Session,
    class_id: int,
    *,
    requested_by: str | None,
    writing: Writing = guarded,
    finish: Callable[[ObjectClass, Job], T] | None = None,
) -> T | Enrolled:
    """Withdraw the enrolled class ``class_id`` with its samples from the store's live data,
    and queue the ``withdraw_class`` job that takes it out of the served model. Classes of
    the training dataset stay (``DatasetClass``); the name can be registered again."""
    cls = _live_class(session, class_id)
    if cls.origin != Origin.ENROLLED:
        raise DatasetClass(
            f"class '{cls.name}' comes from the training dataset; only enrolled classes "
            "can be withdrawn",
            "class_id",
        )
    repo.withdraw_class(session, cls)
    with writing(session, None):  # a concurrent retry with this key may win
        job = repo.add_job(session, JobKind.WITHDRAW_CLASS, cls.id, requested_by=requested_by)
        return (finish or _committing(session))(cls, job)


def withdraw_sample(
    session: Session,
    class_id: int,
    sample_id: int,
    *,
    requested_by: str | None,
    writing: Writing = guarded,
    finish: Callable[[ObjectClass, Job], T] | None = None,
) -> T | Enrolled:
    """Withdraw the enrolled sample ``sample_id`` of class ``class_id`` from the store's live
    data, and queue the ``withdraw_sample`` job that takes it out of the served model.
    Samples of the training dataset stay (``DatasetClass``)."""
    cls = _live_class(session, class_id)
    row = repo.get_sample(session, class_id, sample_id)
    if row is None:
        raise NotFound("sample", "sample_id", sample_id)
    if row.origin != Origin.ENROLLED:
        raise DatasetClass(
            f"sample {sample_id} comes from the training dataset; only enrolled samples "
            "can be withdrawn",
            "sample_id",
        )
    repo.withdraw_sample(session, row)
    with writing(session, None):  # a concurrent retry with this key may win
        job = repo.add_job(
            session, JobKind.WITHDRAW_SAMPLE, class_id, sample_id, requested_by=requested_by
        )
        return (finish or _committing(session))(cls, job)


# ------------------------------------------------------------------------ vocabulary
def add_attribute(
    session: Session,
    name: str,
    values: Mapping[str, float | None],
    interpreter: TextInterpreter,
    *,
    requested_by: str | None,
    writing: Writing = guarded,
    finish: Callable[[Attribute, Job], T] | None = None,
) -> T | Enrolled:
    """Add the attribute ``name`` after the existing ones (existing keys keep their
    meaning), with its ``values`` for the live classes they name, and queue the
    ``add_attribute`` job. A class described in words and given no value gets the value read
    from its text, if it speaks of it; other classes are not known for it. Refused for a
    name used before (``AttributeTaken``), a full vocabulary (``VocabularyFull``), a name
    no live class has (``UnknownClassName``), or values that would leave two enrolled
    classes with the same description (``SameDescription``)."""
    _check_new(session, name)
    vocab = repo.vocabulary(session)
    if len(vocab.names) >= MAX_ATTRIBUTES:
        raise VocabularyFull(f"the vocabulary holds its most attributes ({MAX_ATTRIBUTES})", "name")
    classes = {c.name: c for c in repo.list_classes(session)}
    unknown = [n for n in values if n not in classes]
    if unknown:
        raise UnknownClassName(
            f"no live class named {', '.join(map(repr, unknown[:5]))}", f"values.{unknown[0]}"
        )
    grown = Vocabulary(vocab.names + (name,), vocab.retired, vocab.fixed)
    keys = {
        classes[n].id: grown.key({name: v}, base=classes[n].attribute_key)
        for n, v in values.items()
    }
    worded = {}  # class id -> (class, its reading of the new word)
    for cls in classes.values():
        if cls.description and cls.name not in values:
            reading = interpreter.value_of(cls.description, name)
            if reading is not None:
                worded[cls.id] = (cls, reading)
                keys[cls.id] = grown.key({name: reading.value}, base=cls.attribute_key)
    _check_distinct(session, grown, keys, f"values.{name}")
    with writing(session, lambda: _check_new(session, name)):
        attribute = repo.add_attribute(session, name)
        repo.describe(session, keys)
        for cls, r in worded.values():
            readings = [*(cls.description_readings or []), *stored_readings({r.attribute: r})]
            repo.set_description(session, cls, cls.description, readings)
        job = _attribute_job(session, JobKind.ADD_ATTRIBUTE, attribute, requested_by)
        return (finish or _committing(session))(attribute, job)


def retire_attribute(
    session: Session,
    name: str,
    *,
    requested_by: str | None,
    writing: Writing = guarded,
    finish: Callable[[Attribute, Job], T] | None = None,
) -> T | Enrolled:
    """Retire the attribute ``name``: every class's value for it is dropped, and the
    ``retire_attribute`` job takes it out of later models. Refused for an attribute retired
    already (``RetiredAttribute``), and while it would leave a novel class without samples
    described by nothing (``DescribedByNothing``) or two enrolled classes with the same
    description (``SameDescription``)."""
    attribute = repo.attribute_by_name(session, name)
    if attribute is None:
        raise NotFound("attribute", "name", repr(name))
    if attribute.retired_at is not None:
        raise RetiredAttribute(f"attribute '{name}' is already retired", "name")
    vocab = repo.vocabulary(session)
    after = Vocabulary(vocab.names, vocab.retired | {name}, vocab.fixed)
    counts = repo.sample_counts(session)
    for cls in repo.list_classes(session):
        if (
            cls.kind == ClassKind.NOVEL
            and not counts.get(cls.id)
            and describes(vocab, cls.attribute_key)
            and not describes(after, cls.attribute_key)
        ):
            raise DescribedByNothing(
                f"retiring '{name}' would leave class '{cls.name}' described by nothing (and it "
                "has no samples to be recognised by)",
                "name",
            )
    _check_distinct(session, after, {}, "name", because=f"retiring '{name}'")
    with writing(session, None):
        repo.retire_attribute(session, attribute, vocab)
        job = _attribute_job(session, JobKind.RETIRE_ATTRIBUTE, attribute, requested_by)
        return (finish or _committing(session))(attribute, job)


def _attribute_job(
    session: Session, kind: JobKind, attribute: Attribute, requested_by: str | None
) -> Job:
    return repo.add_job(session, kind, None, requested_by=requested_by, attribute_id=attribute.id)


def _check_new(session: Session, name: str) -> None:
    existing = repo.attribute_by_name(session, name)
    if existing is not None:
        state = " (retired: names are never reused)" if existing.retired_at else ""
        raise AttributeTaken(f"an attribute named '{name}' exists{state}", "name")


def _check_distinct(
    session: Session,
    vocab: Vocabulary,
    keys: Mapping[int, str],
    field: str,
    because: str = "these values",
) -> None:
    """``SameDescription`` when, with ``keys`` (class id -> new key) and ``vocab``, two live
    enrolled classes would have the same description: a model could never tell them
    apart."""
    seen: dict[tuple, str] = {}
    for cls in repo.list_classes(session):
        if cls.origin != Origin.ENROLLED:
            continue
        key = keys.get(cls.id, cls.attribute_key)
        values = vocab.values(key)
        if not describes(vocab, key):
            continue
        description = tuple(sorted(values.items()))
        if description in seen:
            raise SameDescription(
                f"{because} would give classes '{seen[description]}' and '{cls.name}' the same "
                "description; the model could never tell them apart",
                field,
            )
        seen[description] = cls.name


# ----------------------------------------------------------------------------- rules
def _revive_or_add(session: Session, name: str, key: str) -> ObjectClass:
    """The withdrawn class ``name`` given back (same id) with ``key``, else a new class."""
    withdrawn = repo.class_by_name(session, name, withdrawn=True)
    if withdrawn is not None:
        return repo.revive_class(session, withdrawn, key)
    return repo.add_class(session, name, key)


def _failed_registration(session: Session, name: str, key: str) -> ObjectClass | None:
    """The enrolled class ``name`` of description ``key`` whose registration failed: a
    registration of the same class again is a new attempt."""
    cls = repo.class_by_name(session, name)
    if cls is None or cls.origin != Origin.ENROLLED or cls.attribute_key != key:
        return None
    return cls if repo.registration_failed(session, cls.id) else None


def _check_free(session: Session, name: str, key: str, field: str) -> None:
    """No live class has the name, nor (for a described class) the vector ``key``."""
    existing = repo.class_by_name(session, name)
    if existing is not None:
        alike = "" if existing.name == name else "; names are compared without regard to case"
        raise NameTaken(
            f"a class named '{existing.name}' already exists (class {existing.id}{alike}): "
            "add samples to it, or choose another name",
            "name",
        )
    if key:
        _check_vector(session, key, field)


def _check_vector(session: Session, key: str, field: str, other_than: int | None = None) -> None:
    other = repo.class_by_key(session, key, other_than)
    if other is not None:
        raise SameDescription(
            f"class '{other.name}' has the same attribute vector; the model could never tell "
            "them apart",
            field,
        )


def _check_learnable(method: Any, model_has_attributes: bool, described: bool, field: str) -> None:
    """A class learnt from samples: undescribed only where the method learns a class from
    its samples alone (and, for a model of attributes, grades them itself)."""
    if model_has_attributes and not described and not method.graded_attributes:
        raise CannotLearn(
            "this model describes classes by attributes: register the class "
            "with 'attributes', then add its samples",
            field,
        )
    if not described and not method.learns_classes_from_samples:
        raise CannotLearn(
            f"method '{method.method}' cannot recognise a class from its samples "
            "alone; method 'best' can",
            field,
        )


def _check_dataset_values(cls: ObjectClass, described: Description, vocab: Vocabulary) -> None:
    """A dataset class's values for the dataset's own attributes stay fixed: only a mapping
    of attributes added since may set its values."""
    if not isinstance(described.attributes, dict):
        raise DatasetClass(
            f"class '{cls.name}' comes from the training dataset: its values for the dataset's "
            "attributes stay fixed; set its values for attributes added since with a mapping "
            "of names to values",
            field_of(described),
        )
    fixed = sorted(n for n in described.attributes if n in vocab.fixed)
    if fixed:
        raise DatasetClass(
            f"class '{cls.name}' comes from the training dataset: its values for the dataset's "
            f"attributes stay fixed ({', '.join(fixed)})",
            f"attributes.{fixed[0]}",
        )
