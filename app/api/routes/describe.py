from typing import Annotated

import numpy as np
from fastapi import APIRouter, Query, Request
from fastapi.concurrency import run_in_threadpool

from app.api import problems
from app.api.deps import RecognizingDep
from app.api.problems import Problem, blame
from app.api.routes.recognize import OPENAPI_EXTRA, read_body, takes_kind
from app.api.schemas import AttributeScore, DescribeResponse, Description

router = APIRouter(prefix="/v1", tags=["describe"], responses=problems.responses(401, 403, 429))


@router.post(
    "/describe",
    response_model=DescribeResponse,
    openapi_extra=OPENAPI_EXTRA,
    responses=problems.responses(409, 413, 415, 422, 503),
)
async def describe(
    request: Request,
    recognizing: RecognizingDep,
    same_object: Annotated[
        bool,
        Query(
            description="The samples are touches of one object: describe "
            "it from all of them together too (`object`)."
        ),
    ] = False,
) -> DescribeResponse:
    """What each touch feels like: the probability of every attribute, from the served
    model's attribute classifiers. For an object the robot found novel that nobody has
    registered: a person checks the `suggested` attributes and registers the object with
    them; with `same_object`, several touches of the object give one description too. Takes
    the samples (or raw trials: one description per trial) as `POST /v1/recognize` does.
    Only methods that predict attributes from a sample answer (`best` and `prototypes`, either
    of which the default `auto` serves, do; otherwise 409).
    On objects the model was never trained on these predictions are far from certain:
    docs/RESULTS.md measures them."""
    model, service = recognizing
    rec = model.recognizer
    body = await read_body(
        request, rec.input_shape, service.batch_limit, rec.procedures, rec.input_kind
    )
    takes_kind(rec, body)
    if not rec.has_attributes:
        raise Problem(
            409,
            "the served model has no attributes (its dataset had none): there is nothing to "
            "describe a touch by",
            "model",
        )
    # a method without attribute classifiers: 409, naming the model
    if body.trials is not None:
        with blame("trials"):
            proba = await run_in_threadpool(rec.attribute_proba_trials, body.trials)
    else:
        with blame("samples"):
            proba = await run_in_threadpool(rec.attribute_proba, body.samples)
    names = rec.registry.attribute_names
    return DescribeResponse(
        model_version=model.version,
        results=[_description(p, names) for p in proba],
        object=_description(proba.mean(axis=0), names) if same_object else None,
    )


def suggestion(proba: np.ndarray) -> np.ndarray:
    """Which attributes to suggest from (..., M) probabilities: those more probable than
    not, and at least the most probable one (a class needs one). bench/describe_quality.py
    measures this rule."""
    likely = proba > 0.5
    np.put_along_axis(likely, proba.argmax(axis=-1)[..., None], True, axis=-1)
    return likely


def _description(proba: np.ndarray, names: list[str]) -> Description:
    return Description(
        attributes=[
            AttributeScore(name=names[i], probability=float(proba[i])) for i in np.argsort(-proba)
        ],
        suggested=[n for n, keep in zip(names, suggestion(proba), strict=True) if keep],
    )
