import numpy as np
from fastapi import APIRouter, Request
from fastapi.concurrency import run_in_threadpool

from app.api import problems
from app.api.deps import RecognizingDep
from app.api.problems import blame
from app.api.routes.recognize import OPENAPI_EXTRA, read_samples
from app.api.schemas import AttributeScore, DescribeResponse, Description

router = APIRouter(prefix="/v1", tags=["describe"], responses=problems.responses(401, 403, 429))


@router.post(
    "/describe", response_model=DescribeResponse, openapi_extra=OPENAPI_EXTRA,
    responses=problems.responses(409, 413, 422, 503),
)
async def describe(request: Request, recognizing: RecognizingDep) -> DescribeResponse:
    """What each touch feels like: the probability of every attribute, from the served
    model's attribute classifiers. For an object the robot found novel that nobody has
    registered: a person checks the `suggested` attributes and registers the object with
    them. Takes the samples as `POST /v1/recognize` does. Only methods that predict
    attributes from a sample answer (`best` does; otherwise 409). On objects the model was
    never trained on these predictions are far from certain: docs/RESULTS.md measures them."""
    model, service = recognizing
    rec = model.recognizer
    samples, _ = await read_samples(request, rec.input_shape, service.batch_limit)
    with blame("samples"):
        x = rec.validate_samples(samples)
    proba = await run_in_threadpool(rec.attribute_proba, x)  # a method without them: 409, "model"
    names = rec.registry.attribute_names
    return DescribeResponse(model_version=model.version, results=[_description(p, names) for p in proba])


def _description(proba: np.ndarray, names: list[str]) -> Description:
    likely = (proba > 0.5) | (np.arange(len(proba)) == proba.argmax())
    return Description(
        attributes=[AttributeScore(name=names[i], probability=float(proba[i])) for i in np.argsort(-proba)],
        suggested=[n for n, keep in zip(names, likely, strict=True) if keep],
    )
