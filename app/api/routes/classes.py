from collections.abc import Callable

import numpy as np
from fastapi import APIRouter, Response
from sqlalchemy.orm import Session

from app.api import problems, trials
from app.api.deps import (
    EnrollAccess,
    Enroller,
    Idempotency,
    IdempotencyDep,
    InterpreterDep,
    JsonBody,
    MetricsDep,
    ModelDep,
    OptionalModelDep,
    PageDep,
    ReadAccess,
    RowId,
    SessionDep,
    SettingsDep,
)
from app.api.problems import Problem, blame, not_found
from app.api.routes.samples import one_sample
from app.api.sample_input import is_one_sample
from app.api.schemas import (
    ClassCreate,
    ClassCreated,
    ClassDescription,
    ClassList,
    ClassOut,
    JobOut,
    Withdrawal,
)
from app.api.withdrawals import withdrawal
from app.framework.recognizer import RAW_TRIALS, TactileRecognizer
from app.framework.registry import method_class
from app.service import enrolment
from app.service.holder import LoadedModel
from app.store import repo
from app.store.enums import SampleForm
from app.store.models import Job, ObjectClass
from app.store.vocabulary import Vocabulary

router = APIRouter(
    prefix="/v1/classes", tags=["classes"], responses=problems.responses(401, 403, 422, 429)
)


def class_out(
    cls: ObjectClass, vocabulary: Vocabulary, n_samples: int, model: LoadedModel | None
) -> ClassOut:
    served = model is not None and cls.name in model.recognizer.registry.all_names
    values = vocabulary.values(cls.attribute_key)
    return ClassOut(
        id=cls.id,
        name=cls.name,
        kind=cls.kind,
        attributes=[n for n, v in values.items() if v >= 0.5],
        attribute_values=values,
        n_samples=n_samples,
        description=cls.description,
        description_readings=cls.description_readings,
        created_at=cls.created_at,
        in_active_model=served,
    )


@router.get("", response_model=ClassList, dependencies=[ReadAccess])
def list_classes(session: SessionDep, model: OptionalModelDep, page: PageDep) -> ClassList:
    """Known and novel classes by id, a page at a time, and whether the model now
    serving covers each."""
    rows, next_after = page.cut(
        repo.list_classes(session, page.after, page.limit + 1), lambda c: c.id
    )
    vocab = repo.vocabulary(session)
    counts = repo.sample_counts(session, [c.id for c in rows])
    return ClassList(
        classes=[class_out(c, vocab, counts.get(c.id, 0), model) for c in rows],
        next_after=next_after,
    )


@router.get(
    "/{class_id}",
    response_model=ClassOut,
    dependencies=[ReadAccess],
    responses=problems.responses(404),
)
def get_class(class_id: RowId, session: SessionDep, model: OptionalModelDep) -> ClassOut:
    cls = repo.get_class(session, class_id)
    if cls is None:
        raise not_found("class", "class_id", class_id)
    n = repo.sample_counts(session, [class_id]).get(class_id, 0)
    return class_out(cls, repo.vocabulary(session), n, model)


@router.post(
    "",
    status_code=202,
    response_model=ClassCreated,
    dependencies=[EnrollAccess, JsonBody],
    responses=problems.responses(409, 415),
)
def register_class(
    body: ClassCreate,
    session: SessionDep,
    model: OptionalModelDep,
    settings: SettingsDep,
    metrics: MetricsDep,
    response: Response,
    idempotency: IdempotencyDep,
    principal: Enroller,
    interpreter: InterpreterDep,
) -> ClassCreated:
    """Register a novel class by its attributes (zero-shot), or in words (`description`:
    the class keeps the text and the values read from it). Names are unique without regard
    to case and surrounding spaces (a 409 names the class that has one). The class and its
    job are committed before the 202; poll the job until the class is in the active model.
    Registering a class whose registration failed again, with the same attributes,
    queues a new attempt. Registering a withdrawn class's name again gives that class
    back (same id) with the new attributes and none of its old samples. With an
    ``Idempotency-Key``, a retry gets the first answer."""
    idempotency.replay(session)
    shown = body.samples is not None or body.trials is not None
    if shown and model is not None:  # the wrong kind of touches: said before anything else
        _takes_kind(body, model.recognizer)
    # what learns the class from its samples: the served model, or the first one's method
    method = None
    if shown:
        method = model.recognizer if model is not None else method_class(settings.method)
    out = enrolment.register_class(
        session,
        body.name,
        body,
        interpreter,
        requested_by=principal.id,
        samples=(lambda: _samples_of(body, session, model)) if shown else None,
        samples_field="trials" if body.trials is not None else "samples",
        method=method,
        model_has_attributes=model is not None and model.recognizer.has_attributes,
        writing=idempotency.writing,
        finish=_accepted(session, model, idempotency, response),
    )
    metrics.enrollments.labels("class").inc()
    return out


@router.patch(
    "/{class_id}",
    status_code=202,
    response_model=ClassCreated,
    dependencies=[EnrollAccess, JsonBody],
    responses=problems.responses(404, 409, 415),
)
def redescribe_class(
    class_id: RowId,
    body: ClassDescription,
    session: SessionDep,
    model: ModelDep,
    metrics: MetricsDep,
    response: Response,
    idempotency: IdempotencyDep,
    principal: Enroller,
    interpreter: InterpreterDep,
) -> ClassCreated:
    """Correct the attributes an enrolled class was described by (say, *hard* where the
    object is *soft*), keeping the samples robots enrolled for it: a list of names or a
    vector replaces the description, a mapping of names to values sets those and keeps the
    rest. Committed before the 202; the served model describes the class anew when the job
    succeeds. A class of the training dataset keeps its values for the dataset's
    attributes; a mapping sets its values for attributes added since. A `description`
    replaces the class's text and sets the values read from it, as a mapping does. With an
    ``Idempotency-Key``, a retry gets the first answer."""
    idempotency.replay(session)
    out = enrolment.redescribe_class(
        session,
        class_id,
        body,
        interpreter,
        requested_by=principal.id,
        writing=idempotency.writing,
        finish=_accepted(session, model, idempotency, response),
    )
    metrics.enrollments.labels("redescription").inc()
    return out


def _accepted(
    session: Session, model: LoadedModel | None, idempotency: Idempotency, response: Response
) -> Callable[[ObjectClass, Job], ClassCreated]:
    """The 202's body for a class and its job, committed with them (kept for retries)."""

    def finish(cls: ObjectClass, job: Job) -> ClassCreated:
        n = repo.sample_counts(session, [cls.id]).get(cls.id, 0)
        out = ClassCreated(
            class_=class_out(cls, repo.vocabulary(session), n, model),
            job=JobOut.model_validate(job),
        )
        idempotency.accept(session, out, job.id, response)
        return out

    return finish


def _takes_kind(body: ClassCreate, rec: TactileRecognizer) -> None:
    """A 409 for touches of the kind the served model does not take, before they are read."""
    if body.trials is not None and rec.input_kind != RAW_TRIALS:
        raise trials.refused(rec.input_shape, "trials")
    if body.samples is not None and rec.input_kind == RAW_TRIALS:
        raise Problem(
            409,
            "this model was fitted on raw BioTac trials: send 'trials', raw "
            "trials, which the store keeps as sent",
            "samples",
        )


def _samples_of(body: ClassCreate, session: Session, model: LoadedModel | None) -> list:
    """The registration's samples or raw trials, as the store keeps them."""
    return _samples_for(body, model) if model is not None else _samples_for_store(body, session)


def _samples_for(body: ClassCreate, model: LoadedModel) -> list:
    """The registration's samples or raw trials, as the served model takes them."""
    rec = model.recognizer
    if body.trials is not None:
        kept = [
            trials.one(t.model_dump(exclude_none=True), "trials", i, whole=True)
            for i, t in enumerate(body.trials)
        ]
        with blame("trials"):
            rec.trial_samples(kept)  # a model of samples: 409; phases not found: 422
        return kept
    if is_one_sample(body.samples, rec.input_shape, rec.procedures):
        raise Problem(
            422,
            f"samples: expected a list of samples, got one sample of shape {list(rec.input_shape)} "
            "alone: wrap one sample in a list",
            "samples",
        )
    kept = []
    for i, data in enumerate(body.samples):
        x = one_sample(data, rec.input_shape, f"samples[{i}]")
        with blame(f"samples[{i}]", one=True):
            kept.append(rec.validate_samples(x)[0])
    return kept


def _samples_for_store(body: ClassCreate, session: Session) -> list:
    """The registration's samples or raw trials before a service started empty has a model:
    of the form and shape the store already holds, or, for the first class, any one form
    and shape (a flat vector or a C x T image) for all of them."""
    stored = repo.stored_sample_form(session)
    if body.trials is not None:
        if stored is not None and stored[0] != SampleForm.RAW_TRIAL:
            raise Problem(
                409,
                f"the store holds samples of shape {stored[1]}, not raw trials: send 'samples'",
                "trials",
            )
        return [
            trials.one(t.model_dump(exclude_none=True), "trials", i, whole=True)
            for i, t in enumerate(body.trials)
        ]
    if stored is not None and stored[0] == SampleForm.RAW_TRIAL:
        raise Problem(409, "the store holds raw trials: send 'trials'", "samples")
    shape = tuple(stored[1]) if stored is not None else None
    kept = []
    for i, data in enumerate(body.samples):
        field = f"samples[{i}]"
        if shape is None:
            try:
                shape = np.asarray(data, dtype=np.float32).shape
            except ValueError:
                raise Problem(422, "its rows have different lengths", field) from None
        x = one_sample(data, shape, field)[0]
        if x.ndim not in (1, 2) or x.size == 0:
            raise Problem(422, "expected a flat vector or a C x T image of numbers", field)
        if not np.isfinite(x).all():
            raise Problem(422, "the sample contains NaN or infinity", field)
        kept.append(x)
    return kept


@router.delete(
    "/{class_id}",
    status_code=202,
    response_model=Withdrawal,
    dependencies=[EnrollAccess],
    responses=problems.responses(404, 409),
)
def withdraw_class(
    class_id: RowId,
    session: SessionDep,
    metrics: MetricsDep,
    response: Response,
    idempotency: IdempotencyDep,
    principal: Enroller,
) -> Withdrawal:
    """Withdraw a wrongly enrolled class with its samples. It leaves the store's live data
    at once and the served model when the job succeeds; until then recognition may answer
    it. Classes of the training dataset cannot be withdrawn. Its name can then be
    registered again."""
    idempotency.replay(session)
    out = enrolment.withdraw_class(
        session,
        class_id,
        requested_by=principal.id,
        writing=idempotency.writing,
        finish=lambda cls, job: withdrawal(session, idempotency, response, cls.id, None, job),
    )
    metrics.withdrawals.labels("class").inc()
    return out
