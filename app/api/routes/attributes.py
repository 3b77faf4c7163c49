"""The attribute vocabulary: listed, grown (``POST``) and retired (``DELETE``) on a running
service; every class description is a key over it (``app.store.vocabulary``)."""

from fastapi import APIRouter, Response
from sqlalchemy.orm import Session

from app.api import problems
from app.api.deps import (
    AdminAccess,
    Enroller,
    IdempotencyDep,
    InterpreterDep,
    JsonBody,
    MetricsDep,
    ReadAccess,
    SessionDep,
)
from app.api.problems import Problem
from app.api.schemas import (
    AttributeChanged,
    AttributeCreate,
    AttributeList,
    AttributeOut,
    JobOut,
    ReadingOut,
    TextIn,
    TextRead,
)
from app.service.enrolment import read_text, stored_readings
from app.service.keys import Principal
from app.store import repo
from app.store.enums import ClassKind, JobKind, Origin
from app.store.models import Attribute
from app.store.vocabulary import MAX_ATTRIBUTES, Vocabulary, describes
from app.words.interpret import Reading

router = APIRouter(
    prefix="/v1/attributes",
    tags=["attributes"],
    responses=problems.responses(401, 403, 429),
)


@router.get("", response_model=AttributeList, dependencies=[ReadAccess])
def list_attributes(session: SessionDep) -> AttributeList:
    """The attribute vocabulary, in the order attribute vectors use, and every attribute
    with where it came from (retired ones too)."""
    rows = repo.list_attributes(session)
    return AttributeList(
        attributes=[a.name for a in rows if a.retired_at is None],
        vocabulary=[AttributeOut.model_validate(a) for a in rows],
    )


@router.post(
    "/interpret",
    response_model=TextRead,
    dependencies=[ReadAccess, JsonBody],
    responses=problems.responses(409, 415, 422, 503),
)
def interpret_text(body: TextIn, session: SessionDep, interpreter: InterpreterDep) -> TextRead:
    """Read attribute values from a description in words, as registering a class with a
    `description` would, without storing anything: graded ("slightly rough" 0.6, "very hard"
    1), negated ("not hard" 0), through synonyms, paraphrases and materials ("spongy",
    "slick", "soaks up water", "steel"), each with the words that gave it. Attributes the
    text says nothing of are absent, never 0. A 422 names the closest attributes when the
    text names none; the first text a process reads loads the sentence-embedding model
    (about 4 s)."""
    vocab = repo.vocabulary(session)
    read = read_text(body.text, vocab, interpreter, "text")
    return TextRead(
        values={a: r.value for a, r in read.items()},
        readings=readings_out(read),
        not_mentioned=[a for a in vocab.active if a not in read],
    )


@router.post(
    "",
    status_code=202,
    response_model=AttributeChanged,
    dependencies=[AdminAccess, JsonBody],
    responses=problems.responses(409, 415, 422),
)
def add_attribute(
    body: AttributeCreate,
    session: SessionDep,
    metrics: MetricsDep,
    response: Response,
    idempotency: IdempotencyDep,
    principal: Enroller,
    interpreter: InterpreterDep,
) -> AttributeChanged:
    """Add an attribute to the vocabulary, after the existing ones (existing vectors keep
    their meaning), with its value for the classes it is known for; a class described in
    words and given no value here gets the value read from its text, if it speaks of it. It is in
    `GET /v1/attributes` and accepted by registration and `PATCH` at once; the served model
    learns it when the job succeeds. Classes given no value are
    not known for it: left out of its training, never counted as 0. With an
    `Idempotency-Key`, a retry gets the first answer."""
    idempotency.replay(session)
    _check_new(session, body.name)
    vocab = repo.vocabulary(session)
    if len(vocab.names) >= MAX_ATTRIBUTES:
        raise Problem(409, f"the vocabulary holds its most attributes ({MAX_ATTRIBUTES})", "name")
    classes = {c.name: c for c in repo.list_classes(session)}
    unknown = [n for n in body.values if n not in classes]
    if unknown:
        raise Problem(
            422, f"no live class named {', '.join(map(repr, unknown[:5]))}", f"values.{unknown[0]}"
        )
    grown = Vocabulary(vocab.names + (body.name,), vocab.retired, vocab.fixed)
    keys = {
        classes[n].id: grown.key({body.name: v}, base=classes[n].attribute_key)
        for n, v in body.values.items()
    }
    worded = {}  # class id -> (class, its reading of the new word)
    for cls in classes.values():
        if cls.description and cls.name not in body.values:
            reading = interpreter.value_of(cls.description, body.name)
            if reading is not None:
                worded[cls.id] = (cls, reading)
                keys[cls.id] = grown.key({body.name: reading.value}, base=cls.attribute_key)
    _check_distinct(session, grown, keys, f"values.{body.name}")
    with idempotency.writing(session, recheck=lambda: _check_new(session, body.name)):
        attribute = repo.add_attribute(session, body.name)
        repo.describe(session, keys)
        for cls, r in worded.values():
            readings = [*(cls.description_readings or []), *stored_readings({r.attribute: r})]
            repo.set_description(session, cls, cls.description, readings)
        out = _queue(session, JobKind.ADD_ATTRIBUTE, attribute, principal)
        idempotency.accept(session, out, out.job.id, response)
    metrics.enrollments.labels("attribute").inc()
    return out


@router.delete(
    "/{name:path}",  # a name may hold a slash ("wet/dry")
    status_code=202,
    response_model=AttributeChanged,
    dependencies=[AdminAccess],
    responses=problems.responses(404, 409, 422),
)
def retire_attribute(
    name: str,
    session: SessionDep,
    metrics: MetricsDep,
    response: Response,
    idempotency: IdempotencyDep,
    principal: Enroller,
) -> AttributeChanged:
    """Retire an attribute: later models leave it out, and every class's value for it is
    dropped; model versions made before keep it (a rollback answers with it). Refused while
    two live classes would be left with the same description, or a novel class without
    samples with none. The name is never used again."""
    idempotency.replay(session)
    attribute = repo.attribute_by_name(session, name)
    if attribute is None:
        raise problems.not_found("attribute", "name", repr(name))
    if attribute.retired_at is not None:
        raise Problem(409, f"attribute '{name}' is already retired", "name")
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
            raise Problem(
                409,
                f"retiring '{name}' would leave class '{cls.name}' described by nothing (and it "
                "has no samples to be recognised by)",
                "name",
            )
    _check_distinct(session, after, {}, "name", because=f"retiring '{name}'")
    with idempotency.writing(session):
        repo.retire_attribute(session, attribute, vocab)
        out = _queue(session, JobKind.RETIRE_ATTRIBUTE, attribute, principal)
        idempotency.accept(session, out, out.job.id, response)
    metrics.enrollments.labels("attribute").inc()
    return out


def _queue(
    session: Session, kind: JobKind, attribute: Attribute, principal: Principal
) -> AttributeChanged:
    """The job that brings the vocabulary's change into the model, and the 202's body."""
    job = repo.add_job(session, kind, None, requested_by=principal.id, attribute_id=attribute.id)
    return AttributeChanged(
        attribute=AttributeOut.model_validate(attribute), job=JobOut.model_validate(job)
    )


def _check_new(session: Session, name: str) -> None:
    existing = repo.attribute_by_name(session, name)
    if existing is not None:
        state = " (retired: names are never reused)" if existing.retired_at else ""
        raise Problem(409, f"an attribute named '{name}' exists{state}", "name")


def _check_distinct(
    session: Session,
    vocab: Vocabulary,
    keys: dict[int, str],
    field: str,
    because: str = "these values",
) -> None:
    """409 when, with ``keys`` (class id -> new key) and ``vocab``, two live enrolled classes
    would have the same description: a model could never tell them apart."""
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
            raise Problem(
                409,
                f"{because} would give classes '{seen[description]}' and '{cls.name}' the same "
                "description; the model could never tell them apart",
                field,
            )
        seen[description] = cls.name


def readings_out(readings: dict[str, Reading]) -> list[ReadingOut]:
    return [
        ReadingOut(attribute=r.attribute, value=r.value, words=r.words, source=r.source)
        for r in readings.values()
    ]
