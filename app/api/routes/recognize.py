import io

import numpy as np
from fastapi import APIRouter, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError
from pydantic import ValidationError

from app.api import problems
from app.api.deps import BatcherDep, MetricsDep, ModelDep, ReadAccess, SettingsDep
from app.api.problems import Problem, blame
from app.api.schemas import RecognitionOut, RecognizeRequest, RecognizeResponse, ScoreOut

router = APIRouter(
    prefix="/v1", tags=["recognize"], dependencies=[ReadAccess],
    responses=problems.responses(401, 403, 429),
)

NPY = "application/x-npy"
# Bodies above this are parsed in the thread pool, so one big JSON batch cannot stall
# the event loop; batches up to COALESCE samples share forward passes (see batcher).
PARSE_INLINE_BYTES = 64 * 1024
COALESCE = 64

# The body is read by hand to accept JSON or .npy; this documents both.
REQUEST_BODY = {
    "requestBody": {
        "required": True,
        "content": {
            "application/json": {"schema": RecognizeRequest.model_json_schema()},
            NPY: {
                "schema": {
                    "type": "string", "format": "binary",
                    "description": "A float array (N, *input_shape) saved with numpy.save.",
                },
            },
        },
    }
}


@router.post(
    "/recognize", response_model=RecognizeResponse, openapi_extra=REQUEST_BODY,
    responses=problems.responses(413, 422, 503),
)
async def recognize(
    request: Request, model: ModelDep, settings: SettingsDep, metrics: MetricsDep,
    batcher: BatcherDep,
) -> RecognizeResponse:
    """Recognise a batch of samples as known or novel objects.

    Send `{"samples": [...]}` as JSON, or the same batch as a binary `.npy` body
    with `Content-Type: application/x-npy`.
    """
    body = await request.body()
    content_type = request.headers.get("content-type", "").split(";")[0].strip().lower()
    if content_type == NPY:
        samples = _from_npy(body)
    elif len(body) > PARSE_INLINE_BYTES:
        samples = await run_in_threadpool(_from_json, body)
    else:
        samples = _from_json(body)
    rec = model.recognizer
    one = isinstance(samples, np.ndarray) and samples.ndim <= len(rec.input_shape)
    n = 1 if one else len(samples)
    if n > settings.batch_limit:
        raise Problem(
            422, f"{n} samples is more than the batch limit of {settings.batch_limit}", "samples"
        )
    # inference runs off the event loop; `model` stays this request's snapshot
    with blame("samples"):
        if n <= COALESCE:
            x = rec.validate_samples(samples)  # each request's own errors, before sharing a pass
            results = await batcher.recognize(model, x, settings.top_k)
        else:
            results = await run_in_threadpool(rec.recognize, samples, settings.top_k)
    ids = model.class_ids
    for r in results:
        metrics.recognitions.labels(r.kind).inc()
    return RecognizeResponse(
        model_version=model.version,
        results=[
            RecognitionOut(
                class_id=ids.get(r.class_name), class_name=r.class_name, kind=r.kind,
                is_novel=r.is_novel, novelty_score=r.novelty_score,
                top_k=[ScoreOut(class_id=ids.get(s.class_name), class_name=s.class_name,
                                probability=s.probability) for s in r.top_k],
            )
            for r in results
        ],
    )


def _from_json(body: bytes) -> list:
    # pydantic's own JSON parser: 4-5x faster than json.loads + validation, and like
    # json.loads it reads NaN/Infinity literals, which the framework then rejects by name
    try:
        return RecognizeRequest.model_validate_json(body).samples
    except ValidationError as exc:
        raise RequestValidationError(
            [{**e, "loc": ("body", *e["loc"])} for e in exc.errors(include_url=False)]
        ) from None


def _from_npy(body: bytes) -> np.ndarray:
    try:
        x = np.load(io.BytesIO(body), allow_pickle=False)
    except (ValueError, EOFError, OSError) as exc:
        raise Problem(422, f"not a readable .npy array: {exc}", "body") from None
    if not isinstance(x, np.ndarray) or x.dtype.kind not in "fiu":
        raise Problem(422, "the .npy array must hold real numbers", "body")
    return x
