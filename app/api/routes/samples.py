import io
from typing import Annotated, Any

import numpy as np
from fastapi import APIRouter, Header, Response

from app.api import problems, trials
from app.api.deps import (
    NPY,
    EnrollAccess,
    Enroller,
    IdempotencyDep,
    JsonBody,
    MetricsDep,
    ModelDep,
    PageDep,
    ReadAccess,
    RowId,
    SessionDep,
    SettingsDep,
)
from app.api.problems import Problem, blame, not_found
from app.api.sample_input import sample_array
from app.api.schemas import (
    JobOut,
    SampleCreate,
    SampleCreated,
    SampleDetail,
    SampleList,
    SampleOut,
    Withdrawal,
)
from app.api.withdrawals import withdrawal
from app.data.biotac import RawTrial
from app.framework.recognizer import RAW_TRIALS
from app.service import enrolment
from app.service.holder import LoadedModel
from app.store import repo
from app.store.models import Job, Sample

router = APIRouter(
    prefix="/v1/classes", tags=["samples"], responses=problems.responses(401, 403, 422, 429)
)


@router.get(
    "/{class_id}/samples",
    response_model=SampleList,
    dependencies=[ReadAccess],
    responses=problems.responses(404),
)
def list_samples(class_id: RowId, session: SessionDep, page: PageDep) -> SampleList:
    """The class's samples by id, a page at a time, without their data: the training
    trials of a dataset class, or the samples robots enrolled (and who), e.g. to find one
    to withdraw."""
    if repo.get_class(session, class_id) is None:
        raise not_found("class", "class_id", class_id)
    rows, next_after = page.cut(
        repo.list_samples(session, class_id, page.after, page.limit + 1), lambda r: r.id
    )
    return SampleList(samples=[SampleOut(**r._mapping) for r in rows], next_after=next_after)


@router.get(
    "/{class_id}/samples/{sample_id}",
    response_model=SampleDetail,
    dependencies=[ReadAccess],
    responses={
        200: {
            "content": {NPY: {"schema": {"type": "string", "format": "binary"}}},
            "description": f"The sample as JSON, or as `.npy` with `Accept: {NPY}`",
        },
        **problems.responses(404),
    },
)
def get_sample(
    class_id: RowId,
    sample_id: RowId,
    session: SessionDep,
    accept: Annotated[str, Header(description=f"`{NPY}` for a `.npy` body")] = "application/json",
) -> SampleDetail | Response:
    """One live sample with its data, e.g. to look at an enrolment before withdrawing it,
    or to send it to `POST /v1/recognize` again. With `Accept: application/x-npy` the body
    is the sample saved with `numpy.save`, as `POST /v1/recognize` accepts it."""
    if repo.get_class(session, class_id) is None:
        raise not_found("class", "class_id", class_id)
    row = repo.sample_record(session, class_id, sample_id)
    if row is None:
        raise not_found("sample", "sample_id", sample_id)
    x = repo.decode(row)
    fields = {k: v for k, v in row._mapping.items() if k not in ("data", "form")}
    if isinstance(x, RawTrial):  # as it was enrolled, as POST /v1/recognize takes trials
        return SampleDetail(**fields, sample=x.to_dict())
    if NPY in accept.lower():
        body = io.BytesIO()
        np.save(body, x, allow_pickle=False)
        return Response(body.getvalue(), media_type=NPY)
    return SampleDetail(**fields, sample=x.tolist())


@router.post(
    "/{class_id}/samples",
    status_code=202,
    response_model=SampleCreated,
    dependencies=[EnrollAccess, JsonBody],
    responses=problems.responses(404, 409, 415),
)
def add_sample(
    class_id: RowId,
    body: SampleCreate,
    session: SessionDep,
    model: ModelDep,
    metrics: MetricsDep,
    response: Response,
    idempotency: IdempotencyDep,
    principal: Enroller,
    settings: SettingsDep,
) -> SampleCreated:
    """Add one real sample of a novel class (one-shot learning). Stored and queued
    before the 202; the job says when a model including it is live. The answer says what
    the served model made of the sample before learning from it (`recognized_as`), and
    `warnings` where it gave the sample to another class with probability 0.9 or more:
    the sample is kept, and may be withdrawn. With an ``Idempotency-Key``, a retry gets
    the first answer and adds nothing."""
    idempotency.replay(session)
    cls = enrolment.novel_class(session, class_id)
    kept, recognized_as = _read_and_recognize(body, model, settings.known_kept)

    warnings = enrolment.doubts(cls, recognized_as, model.recognizer.registry.all_names)

    def accepted(row: Sample, job: Job) -> SampleCreated:
        out = SampleCreated(
            sample_id=row.id,
            job=JobOut.model_validate(job),
            recognized_as=recognized_as,
            model_version=model.version,
            warnings=job.warnings or [],
        )
        idempotency.accept(session, out, job.id, response)
        return out

    out = enrolment.add_sample(
        session,
        cls,
        kept,
        requested_by=principal.id,
        warnings=warnings,
        writing=idempotency.writing,
        finish=accepted,
    )
    metrics.enrollments.labels("sample").inc()
    return out


def _read_and_recognize(
    body: SampleCreate, model: LoadedModel, known_kept: float | None
) -> tuple[Any, dict]:
    """The body's sample or raw trial as the store keeps it, and what ``model`` makes of it
    before learning from it (one answer for all of it: both fingers of a trial)."""
    rec = model.recognizer
    if body.trial is not None:
        if rec.input_kind != RAW_TRIALS:  # said before the trial is read
            raise trials.refused(rec.input_shape, "trial")
        kept = trials.one(body.trial.model_dump(exclude_none=True), whole=True)
        with blame("trial"):  # 409 when the model takes samples
            x, _ = rec.trial_samples([kept])
    elif rec.input_kind == RAW_TRIALS:  # a later featurizer could not make anything of it
        raise Problem(
            409,
            "this model was fitted on raw BioTac trials: send the sample as "
            "'trial', a raw trial, which the store keeps as sent",
            "sample",
        )
    else:
        x = one_sample(body.sample, rec.input_shape)
        with blame("sample", one=True):
            x = rec.validate_samples(x)  # NaN and infinity become a named 422
        kept = x[0]
    # at the service's operating point, as POST /v1/recognize answers it
    answer = rec.recognize_batch(
        x, groups=np.zeros(len(x), np.int64), known_kept=rec.operating_point(None, known_kept)
    )
    return kept, answer.records(model.class_ids)[0]


def one_sample(data: list, input_shape: tuple[int, ...], field: str = "sample") -> np.ndarray:
    """``data`` as one complete sample of ``input_shape`` (a batch of one), or a 422 at
    ``field`` that names the shape expected."""
    return sample_array(data, input_shape, field)[None]


@router.delete(
    "/{class_id}/samples/{sample_id}",
    status_code=202,
    response_model=Withdrawal,
    dependencies=[EnrollAccess],
    responses=problems.responses(404, 409),
)
def withdraw_sample(
    class_id: RowId,
    sample_id: RowId,
    session: SessionDep,
    metrics: MetricsDep,
    response: Response,
    idempotency: IdempotencyDep,
    principal: Enroller,
) -> Withdrawal:
    """Withdraw a wrongly enrolled sample (say, one taken of the wrong object). It leaves
    the store's live data at once and the served model when the job succeeds. Samples of
    the training dataset cannot be withdrawn."""
    idempotency.replay(session)
    out = enrolment.withdraw_sample(
        session,
        class_id,
        sample_id,
        requested_by=principal.id,
        writing=idempotency.writing,
        finish=lambda _, job: withdrawal(session, idempotency, response, class_id, sample_id, job),
    )
    metrics.withdrawals.labels("sample").inc()
    return out
