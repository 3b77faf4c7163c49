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
from app.api.descriptions import description_key, field_of, read_text, stored_readings
from app.api.problems import Problem, blame, not_found
from app.api.routes.samples import one_sample
from app.api.schemas import (
    ClassCreate,
    ClassCreated,
    ClassDescription,
    ClassList,
    ClassOut,
    JobOut,
    Withdrawal,
)
from app.api.withdrawals import queue_withdrawal
from app.config import Settings
from app.framework.recognizer import RAW_TRIALS
from app.framework.registry import method_class
from app.service.holder import LoadedModel
from app.service.keys import Principal
from app.service.metrics import Metrics
from app.store import repo
from app.store.enums import JobKind, Origin, SampleForm
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
    the class keeps the text and the values read from it). The class and its job are
    committed before the 202; poll the job until the class is in the active model.
    Registering a class whose registration failed again, with the same attributes,
    queues a new attempt. Registering a withdrawn class's name again gives that class
    back (same id) with the new attributes and none of its old samples. With an
    ``Idempotency-Key``, a retry gets the first answer."""
    idempotency.replay(session)
    vocab = repo.vocabulary(session)
    read = _read(body, vocab, interpreter)
    if body.samples is not None or body.trials is not None:
        return _register_from_samples(
            body, session, model, settings, metrics, response, idempotency, principal, vocab, read
        )
    field = field_of(body)
    key = description_key(body, vocab, read=read)
    cls = _failed_registration(session, body.name, key)
    if cls is None:
        _check_unique(session, body.name, key, field)
    # a concurrent registration of this name or vector (or a retry with this key) may win
    with idempotency.writing(
        session, recheck=lambda: _check_unique(session, body.name, key, field)
    ):
        if cls is None:
            withdrawn = repo.class_by_name(session, body.name, withdrawn=True)
            cls = (
                repo.revive_class(session, withdrawn, key)
                if withdrawn is not None
                else repo.add_class(session, body.name, key)
            )
        repo.set_description(session, cls, body.description, stored_readings(read))
        job = repo.add_job(session, JobKind.REGISTER_CLASS, cls.id, requested_by=principal.id)
        out = _class_accepted(session, cls, job, model)
        idempotency.accept(session, out, job.id, response)
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
    succeeds (the novel classes rebuilt, or the attribute classifiers refitted for a known
    class). A class of the training dataset keeps its values for the dataset's attributes;
    a mapping sets its values for attributes added since. A `description` replaces the
    class's text and sets the values read from it, as a mapping does. With an
    ``Idempotency-Key``, a retry gets the first answer."""
    idempotency.replay(session)
    cls = repo.get_class(session, class_id)
    if cls is None:
        raise not_found("class", "class_id", class_id)
    vocab = repo.vocabulary(session)
    field = field_of(body)
    if cls.origin == Origin.DATASET:
        _check_dataset_values(cls, body, vocab)
    read = _read(body, vocab, interpreter)
    key = description_key(body, vocab, base=cls.attribute_key, read=read)
    if cls.origin == Origin.ENROLLED:
        _check_unique_vector(session, key, field, other_than=cls.id)
    # a concurrent registration of this vector (or a retry with this key) may win
    with idempotency.writing(
        session, recheck=lambda: _check_unique_vector(session, key, field, cls.id)
    ):
        repo.redescribe_class(session, cls, key)
        if body.description is not None:
            repo.set_description(session, cls, body.description, stored_readings(read))
        job = repo.add_job(session, JobKind.UPDATE_CLASS, cls.id, requested_by=principal.id)
        out = _class_accepted(session, cls, job, model)
        idempotency.accept(session, out, job.id, response)
    metrics.enrollments.labels("redescription").inc()
    return out


def _register_from_samples(
    body: ClassCreate,
    session: Session,
    model: LoadedModel | None,
    settings: Settings,
    metrics: Metrics,
    response: Response,
    idempotency: Idempotency,
    principal: Principal,
    vocab: Vocabulary,
    read: dict | None,
) -> ClassCreated:
    """A class learnt from the samples or trials sent with it, described or not: the class,
    its samples (one ``add_sample`` job each) and its registration in one commit."""
    method = model.recognizer if model is not None else method_class(settings.method)
    field = "trials" if body.trials is not None else "samples"
    described = (
        body.attributes is not None
        or body.attribute_vector is not None
        or body.description is not None
    )
    key = description_key(body, vocab, read=read) if described else ""
    if model is not None and model.recognizer.has_attributes and not described:
        if not method.graded_attributes:
            raise Problem(
                409,
                "this model describes classes by attributes: register the class "
                "with 'attributes', then add its samples",
                field,
            )
    if not described and not method.learns_classes_from_samples:
        raise Problem(
            409,
            f"method '{method.method}' cannot recognise a class from its samples "
            "alone; method 'best' can",
            field,
        )
    kept = _samples_for(body, model) if model is not None else _samples_for_store(body, session)

    def check() -> None:
        _check_name(session, body.name)
        if key:
            _check_unique_vector(session, key, field_of(body))

    check()
    with idempotency.writing(session, recheck=check):
        withdrawn = repo.class_by_name(session, body.name, withdrawn=True)
        cls = (
            repo.revive_class(session, withdrawn, key)
            if withdrawn is not None
            else repo.add_class(session, body.name, key)
        )
        repo.set_description(session, cls, body.description, stored_readings(read))
        for item in kept:
            row = repo.add_sample(session, cls.id, item)
            repo.add_job(session, JobKind.ADD_SAMPLE, cls.id, row.id, requested_by=principal.id)
        job = repo.add_job(session, JobKind.REGISTER_CLASS, cls.id, requested_by=principal.id)
        out = _class_accepted(session, cls, job, model)
        idempotency.accept(session, out, job.id, response)
    metrics.enrollments.labels("class").inc()
    return out


def _samples_for(body: ClassCreate, model: LoadedModel) -> list:
    """The registration's samples or raw trials, as the served model takes them."""
    rec = model.recognizer
    if body.trials is not None:
        kept = [
            trials.one(t.model_dump(exclude_none=True), "trials", i)
            for i, t in enumerate(body.trials)
        ]
        with blame("trials"):
            rec.trial_samples(kept)  # a model of samples: 409; phases not found: 422
        return kept
    if rec.input_kind == RAW_TRIALS:
        raise Problem(
            409,
            "this model was fitted on raw BioTac trials: send 'trials', raw "
            "trials, which the store keeps as sent",
            "samples",
        )
    kept = []
    for i, data in enumerate(body.samples):
        x = one_sample(data, rec.input_shape, f"samples[{i}]")
        with blame(f"samples[{i}]"):
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
            trials.one(t.model_dump(exclude_none=True), "trials", i)
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


def _check_name(session: Session, name: str) -> None:
    if repo.class_by_name(session, name) is not None:
        raise Problem(409, f"a class named '{name}' already exists", "name")


def _class_accepted(
    session: Session, cls: ObjectClass, job: Job, model: LoadedModel | None
) -> ClassCreated:
    n = repo.sample_counts(session, [cls.id]).get(cls.id, 0)
    return ClassCreated(
        class_=class_out(cls, repo.vocabulary(session), n, model),
        job=JobOut.model_validate(job),
    )


def _enrolled_class(session: Session, class_id: int, done: str) -> ObjectClass:
    """The live class ``class_id``, one an operator enrolled: what can be ``done`` to it."""
    cls = repo.get_class(session, class_id)
    if cls is None:
        raise not_found("class", "class_id", class_id)
    if cls.origin != Origin.ENROLLED:
        raise Problem(
            409,
            f"class '{cls.name}' comes from the training dataset; only enrolled classes "
            f"can be {done}",
            "class_id",
        )
    return cls


def _read(body: ClassDescription, vocab: Vocabulary, interpreter) -> dict | None:
    """The readings of the body's description (None without one)."""
    if body.description is None:
        return None
    return read_text(body.description, vocab, interpreter, "description")


def _check_dataset_values(cls: ObjectClass, body: ClassDescription, vocab: Vocabulary) -> None:
    """A dataset class's values for the dataset's own attributes stay fixed: only a mapping
    of attributes added since may set its values."""
    if not isinstance(body.attributes, dict):
        raise Problem(
            409,
            f"class '{cls.name}' comes from the training dataset: its values for the dataset's "
            "attributes stay fixed; set its values for attributes added since with a mapping "
            "of names to values",
            field_of(body),
        )
    fixed = sorted(n for n in body.attributes if n in vocab.fixed)
    if fixed:
        raise Problem(
            409,
            f"class '{cls.name}' comes from the training dataset: its values for the dataset's "
            f"attributes stay fixed ({', '.join(fixed)})",
            f"attributes.{fixed[0]}",
        )


def _failed_registration(session: Session, name: str, key: str) -> ObjectClass | None:
    cls = repo.class_by_name(session, name)
    if cls is None or cls.origin != Origin.ENROLLED or cls.attribute_key != key:
        return None
    return cls if repo.registration_failed(session, cls.id) else None


def _check_unique(session: Session, name: str, key: str, field: str) -> None:
    if repo.class_by_name(session, name) is not None:
        raise Problem(409, f"a class named '{name}' already exists", "name")
    _check_unique_vector(session, key, field)


def _check_unique_vector(
    session: Session, key: str, field: str, other_than: int | None = None
) -> None:
    other = repo.class_by_key(session, key, other_than)
    if other is not None:
        raise Problem(
            409,
            f"class '{other.name}' has the same attribute vector; the model could never tell "
            "them apart",
            field,
        )


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
    at once and the served model when the job succeeds (the novel classes rebuilt, or a
    full retrain where it was in the known part); until then recognition may answer it.
    Classes of the training dataset cannot be withdrawn. Its name can then be registered
    again."""
    idempotency.replay(session)
    cls = _enrolled_class(session, class_id, "withdrawn")
    repo.withdraw_class(session, cls)
    return queue_withdrawal(session, idempotency, metrics, response, principal, cls.id, None)
