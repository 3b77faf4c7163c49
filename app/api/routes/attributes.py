"""The attribute vocabulary: listed, grown (``POST``) and retired (``DELETE``) on a running
service; every class description is a key over it (``app.store.vocabulary``)."""

from collections.abc import Callable

from fastapi import APIRouter, Response
from sqlalchemy.orm import Session

from app.api import problems
from app.api.deps import (
    AdminAccess,
    Enroller,
    Idempotency,
    IdempotencyDep,
    InterpreterDep,
    JsonBody,
    MetricsDep,
    ReadAccess,
    SessionDep,
)
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
from app.service import enrolment
from app.store import repo
from app.store.models import Attribute, Job
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
    read = enrolment.read_text(body.text, vocab, interpreter, "text")
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
    words and given no value here gets the value read from its text, if it speaks of it.
    It is in `GET /v1/attributes` and accepted by registration and `PATCH` at once; the
    served model learns it when the job succeeds. Classes given no value are not known for
    it: left out of its training, never counted as 0. With an `Idempotency-Key`, a retry
    gets the first answer."""
    idempotency.replay(session)
    out = enrolment.add_attribute(
        session,
        body.name,
        body.values,
        interpreter,
        requested_by=principal.id,
        writing=idempotency.writing,
        finish=_accepted(session, idempotency, response),
    )
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
    out = enrolment.retire_attribute(
        session,
        name,
        requested_by=principal.id,
        writing=idempotency.writing,
        finish=_accepted(session, idempotency, response),
    )
    metrics.enrollments.labels("attribute").inc()
    return out


def _accepted(
    session: Session, idempotency: Idempotency, response: Response
) -> Callable[[Attribute, Job], AttributeChanged]:
    """The 202's body for an attribute and its job, committed with them (kept for
    retries)."""

    def finish(attribute: Attribute, job: Job) -> AttributeChanged:
        out = AttributeChanged(
            attribute=AttributeOut.model_validate(attribute), job=JobOut.model_validate(job)
        )
        idempotency.accept(session, out, job.id, response)
        return out

    return finish


def readings_out(readings: dict[str, Reading]) -> list[ReadingOut]:
    return [
        ReadingOut(attribute=r.attribute, value=r.value, words=r.words, source=r.source)
        for r in readings.values()
    ]
