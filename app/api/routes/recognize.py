import contextlib
import io
import json
from typing import Any, NamedTuple

import numpy as np
import orjson
from fastapi import APIRouter, Request, Response
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError
from pydantic import TypeAdapter, ValidationError

from app.api import problems, trials
from app.api.deps import JSON, NPY, api_key_header, get_recognizing, header, media_type
from app.api.deps import service as service_state
from app.api.problems import Problem, blame
from app.api.sample_input import is_one_sample, sample_array
from app.api.schemas import RecognizeRequest, RecognizeResponse
from app.data.biotac import RawTrial
from app.framework.recognizer import (
    OUTLIER_POLICIES,
    RAW_TRIALS,
    TARGET_CONFIDENCE,
    TactileRecognizer,
)
from app.service.holder import LoadedModel, ModelWaitTimeout
from app.service.recognition import RecognitionService
from app.service.table_answers import Label, LabelError, check_labels, split_labels

router = APIRouter(prefix="/v1", tags=["recognize"], responses=problems.responses(401, 403, 429))

# Bodies above this are parsed in the thread pool, so one big JSON batch cannot stall
# the event loop.
PARSE_INLINE_BYTES = 64 * 1024

# The body is read by hand to accept JSON, .npy or HDF5; this documents them, and the API key
# that get_recognizing checks (the other routes' Security dependency documents it for them).
OPENAPI_EXTRA = {
    "security": [{api_key_header.scheme_name: []}],
    "requestBody": {
        "required": True,
        "content": {
            JSON: {
                "schema": {
                    "oneOf": [
                        {"$ref": "#/components/schemas/RecognizeRequest"},
                        {"$ref": "#/components/schemas/RecognizeTrialsRequest"},
                    ]
                }
            },
            NPY: {
                "schema": {
                    "type": "string",
                    "format": "binary",
                    "description": "A float array (N, *input_shape) saved with numpy.save.",
                },
            },
            trials.HDF5: {
                "schema": {
                    "type": "string",
                    "format": "binary",
                    "description": "Raw BioTac trials, for a model fitted on raw trials: an "
                    "HDF5 file with one group per trial holding finger_0, finger_1, … groups "
                    "of the channels pdc, tdc, tac (T), pac (T, 22) and electrodes (T, 19), "
                    "as the BioTac recordings are laid out (docs/DATASETS.md); answered in "
                    "the file's group order.",
                },
            },
        },
    },
}

SAME_OBJECT = (
    "The samples (or trials) are touches of one object: answer once for all of them, their "
    "evidence fused (the mean of their class probabilities and novelty scores)."
)
MIN_MODEL_VERSION = (
    "Answer with this model version or a newer one: pass the `model_version` of the "
    "enrolment job you waited for, and the answer includes that class or sample whichever "
    "API process answers (one that still serves an older version loads the active one "
    "first, instead of at its next poll). A 409 when the active version is older (it was "
    "rolled back); a 503 when this process cannot load it, or has not loaded it within "
    "`TACTILE_MODEL_WAIT_SECONDS` (30 s by default; its `Retry-After` says when to ask again)."
)
OUTLIERS = (
    "What the answer to an input outlier is (`input_outlier` true: a sensor reading zeros, "
    "saturated, wrongly scaled or with a dead channel). `abstain` names no object: `kind` "
    "`input_outlier`, `class_id` and `class_name` null, `is_novel` null, `top_k` empty. "
    "`answer` gives the model's guess as for any input (`kind` `known` or `novel`), still "
    "flagged `input_outlier`. Default: the service's `TACTILE_OUTLIERS` (`abstain` unless set)."
)
KNOWN_KEPT = (
    "The novelty operating point of this answer: a sample is novel above the threshold that "
    "kept this share of held-out known touches known when the model was fitted (read off the "
    "model's calibration curve, up to 200 points). Higher keeps more known touches known and "
    "detects fewer novel ones. Default: the service's `TACTILE_KNOWN_KEPT` (0.90 unless set), "
    "for every method; a model without a calibration curve answers at its own threshold. "
    "Each answer states the threshold it used (`novelty_threshold`, `known_kept`, "
    "`operating_point`)."
)
OBJECTS = (
    "A table of objects (docs/TABLES.md): the physical object each sample (or raw trial) was "
    "touched on, one label per sample in their order, comma-separated (`objects=cup,box,cup`; "
    "spaces around a label are dropped), for a `.npy` or HDF5 body or a JSON one (which may "
    "give them as its `objects` list instead). Distinct labels are distinct objects, named "
    "jointly: no class, known or novel, is given to two of them; novel, not any registered "
    "class, may repeat. The answer has one result per object, in order of first appearance, "
    "with `object`, `alone`, `margin` and `touches`. Not with `same_object`. The header "
    "`X-Tactile-Objects` takes the same list (for lists longer than a URL takes); given "
    "both, they must agree."
)
OBJECTS_HEADER = b"x-tactile-objects"
# recognize reads its query by hand too: FastAPI's parameter machinery cost ~25 µs a request
# (bench/side_by_side.py measures the route against the framework's floor)
RECOGNIZE_EXTRA = {
    **OPENAPI_EXTRA,
    "parameters": [
        {
            "name": "same_object",
            "in": "query",
            "required": False,
            "schema": {"type": "boolean", "default": False},
            "description": SAME_OBJECT,
        },
        {
            "name": "target_confidence",
            "in": "query",
            "required": False,
            "schema": {
                "type": "number",
                "exclusiveMinimum": 0,
                "maximum": 1,
                "default": TARGET_CONFIDENCE,
            },
            "description": "An answer whose probability reaches this, after two procedures "
            "at least, needs no further procedure (`next_procedure` null); otherwise "
            "`next_procedure` names the one to do next. The default was chosen on PHAC-2's "
            "development splits (docs/RESULTS.md).",
        },
        {
            "name": "known_kept",
            "in": "query",
            "required": False,
            "schema": {"type": "number", "exclusiveMinimum": 0, "exclusiveMaximum": 1},
            "description": KNOWN_KEPT,
        },
        {
            "name": "outliers",
            "in": "query",
            "required": False,
            "schema": {"type": "string", "enum": list(OUTLIER_POLICIES)},
            "description": OUTLIERS,
        },
        {
            "name": "min_model_version",
            "in": "query",
            "required": False,
            "schema": {"type": "integer", "minimum": 1},
            "description": MIN_MODEL_VERSION,
        },
        {
            "name": "objects",
            "in": "query",
            "required": False,
            "schema": {"type": "string"},
            "example": "cup,box,cup",
            "description": OBJECTS,
        },
        {
            "name": "X-Tactile-Objects",
            "in": "header",
            "required": False,
            "schema": {"type": "string"},
            "example": "cup,box,cup",
            "description": "The `objects` labels of a table, as the query parameter takes them.",
        },
    ],
}
_BOOL = TypeAdapter(bool)
_CONFIDENCE = TypeAdapter(float)
_VERSION = TypeAdapter(int)


class Body(NamedTuple):
    """A recognition request's input: ``n`` samples, or ``n`` raw trials; ``objects``: the
    JSON body's labels as sent (None when it has none), checked by ``_table_labels``."""

    samples: np.ndarray | None
    trials: list[RawTrial] | None
    n: int
    objects: Any = None


@router.post(
    "/recognize",
    response_model=RecognizeResponse,
    openapi_extra=RECOGNIZE_EXTRA,
    responses=problems.responses(409, 413, 415, 422, 503),
)
async def recognize(request: Request) -> Response:
    """Recognise a batch of samples as known or novel objects.

    Send `{"samples": [...]}` as JSON, or the same batch as a binary `.npy` body
    with `Content-Type: application/x-npy`. A model fitted on raw BioTac trials
    (`input_kind` `raw_trials` in `GET /v1/models/active`) takes `{"trials": [...]}`
    instead, or an HDF5 body, and answers once per trial from all its fingers; the other
    kind of input is a 409 that says which the model takes.
    """
    return Response(await answer(request), media_type=JSON)


async def answer(request: Request) -> bytes:
    """The JSON body of ``POST /v1/recognize``'s 200 answer; errors are raised, for the
    app's exception handlers. The route above calls it, and so does
    ``app.api.fast_path.RecognizeFastPath``, which answers this route without FastAPI's
    routing (the route robots call hundreds of times a second)."""
    # called, not declared with Depends: FastAPI's dependency machinery cost ~15 µs a
    # request on the route robots call most (RECOGNIZE_EXTRA documents the key it checks)
    model, service = await get_recognizing(request)
    wanted = _min_model_version(request)
    if wanted is not None and model.version < wanted:
        model = await _serving_at_least(request, wanted)
    same_object = _same_object(request)
    target = _target_confidence(request)
    kept = _known_kept(request)
    outliers = _outliers(request)
    rec = model.recognizer
    body = await read_body(
        request, rec.input_shape, service.batch_limit, rec.procedures, rec.input_kind
    )
    takes_kind(rec, body)
    labelled = _labels_given(request)
    if labelled is not None or body.objects is not None:
        objects = _table_labels(labelled, body, same_object)
        return await _table(service, model, body, objects, target, kept, outliers)
    if body.trials is not None:
        with blame("trials"):
            results = await service.recognize_trials(model, body.trials, same_object, kept)
    elif same_object:
        with blame("samples"):
            results = await service.recognize_object(model, body.samples, target, kept)
    else:
        with blame("samples"):
            records = await service.recognize(model, body.samples, body.n, target, kept, outliers)
        return service.json_of(model, records)
    return service.to_json(model, results, outliers)


async def _table(
    service: RecognitionService,
    model: LoadedModel,
    body: Body,
    objects: list[Label],
    target: float | None,
    kept: float | None,
    outliers: str | None,
) -> bytes:
    """The answer to a table of objects (docs/TABLES.md): one result per object."""
    field = "trials" if body.trials is not None else "samples"
    with blame(field):
        table = await service.recognize_table(
            model, objects, body.samples, body.trials, target, kept, outliers
        )
    return service.table_json(model, table, outliers)


def _labels_given(request: Request) -> tuple[str, list[str]] | None:
    """The labels of the query parameter ``objects`` or the header ``X-Tactile-Objects``
    (where they came from, and the labels); None when neither is given. Both given must
    agree."""
    query = _query(request, "objects")
    head = header(request, OBJECTS_HEADER)
    if query is None and head is None:
        return None
    if query is not None and head is not None and split_labels(query) != split_labels(head):
        raise Problem(
            422,
            "objects: the query parameter objects and the header X-Tactile-Objects give "
            "different labels; give them once (the header for long lists)",
            "objects",
        )
    return (
        ("objects", split_labels(query))
        if query is not None
        else (
            "X-Tactile-Objects",
            split_labels(head),
        )
    )


def _table_labels(
    labelled: tuple[str, list[str]] | None, body: Body, same_object: bool
) -> list[Label]:
    """The checked object labels of a table request, from the JSON body's ``objects`` or
    the query/header ones (both given must agree); a 422 naming the fix otherwise."""
    what = "trials" if body.trials is not None else "samples"
    if same_object:
        raise Problem(
            422,
            "objects: same_object=true says every touch is of one object, objects labels "
            "each touch's object; use one or the other (objects with one label throughout "
            "is one object too)",
            "objects",
        )
    labels = body.objects
    if labelled is not None:
        where, given = labelled
        if labels is not None and labels != given:
            raise Problem(
                422,
                f"objects: the body's objects and the {where} labels differ; give the labels once",
                "objects",
            )
        labels = given
    try:
        return check_labels(labels, body.n, what)
    except LabelError as exc:
        raise Problem(422, str(exc), exc.field) from None


def _query(request: Request, name: str) -> str | None:
    """The query parameter ``name`` (read by hand: RECOGNIZE_EXTRA), None when not given."""
    return request.query_params.get(name) if request.scope["query_string"] else None


def _same_object(request: Request) -> bool:
    raw = _query(request, "same_object")
    if raw is None:
        return False
    try:
        return _BOOL.validate_python(raw)
    except ValidationError:
        raise Problem(422, f"same_object: not true or false (got {raw!r})", "same_object") from None


def _min_model_version(request: Request) -> int | None:
    raw = _query(request, "min_model_version")
    if raw is None:
        return None
    value = _valid(_VERSION, raw, 0)
    if value < 1:
        raise Problem(
            422, f"min_model_version: a model version, 1 or more (got {raw!r})", "min_model_version"
        )
    return value


async def _serving_at_least(request: Request, wanted: int) -> LoadedModel:
    """This process's model once it is version ``wanted`` or newer (``ModelHolder.at_least``:
    one load shared by every request that waits, none of them in the thread pool); a 409 or
    503 saying why it cannot be (503 with Retry-After past ``model_wait_seconds``)."""
    state = service_state(request)
    holder = state.holder
    try:
        model = await holder.at_least(wanted, state.settings.model_wait_seconds)
    except ModelWaitTimeout as exc:
        raise Problem(
            503, f"min_model_version: {exc}", "min_model_version", {"Retry-After": "5"}
        ) from None
    if model is not None:
        return model
    if holder.degraded:
        raise Problem(503, f"min_model_version: {holder.degraded}", "min_model_version")
    served = holder.current.version if holder.current is not None else None
    raise Problem(
        409,
        f"min_model_version: model version {wanted} is not active; the active version is "
        f"{served} (a newer one was rolled back, or none has been made yet)",
        "min_model_version",
    )


def _target_confidence(request: Request) -> float | None:
    """The request's ``target_confidence``, None when it gives none (the model's default)."""
    raw = _query(request, "target_confidence")
    if raw is None:
        return None
    value = _valid(_CONFIDENCE, raw, float("nan"))
    if not 0.0 < value <= 1.0:
        raise Problem(
            422,
            f"target_confidence: a probability in (0, 1] is needed (got {raw!r})",
            "target_confidence",
        )
    return value


def _known_kept(request: Request) -> float | None:
    """The request's ``known_kept``, None when it gives none (the service's or model's)."""
    raw = _query(request, "known_kept")
    if raw is None:
        return None
    value = _valid(_CONFIDENCE, raw, float("nan"))
    if not 0.0 < value < 1.0:
        raise Problem(422, f"known_kept: a share in (0, 1) is needed (got {raw!r})", "known_kept")
    return value


def _outliers(request: Request) -> str | None:
    """The request's ``outliers``, None when it gives none (the service's)."""
    raw = _query(request, "outliers")
    if raw is None:
        return None
    if raw not in OUTLIER_POLICIES:
        raise Problem(
            422,
            f"outliers: one of {', '.join(OUTLIER_POLICIES)} is needed (got {raw!r})",
            "outliers",
        )
    return raw


def _valid(adapter: TypeAdapter[Any], raw: str, otherwise: Any) -> Any:
    """``raw`` as ``adapter`` reads it, ``otherwise`` when it cannot."""
    try:
        return adapter.validate_python(raw)
    except ValidationError:
        return otherwise


def takes_kind(rec: TactileRecognizer, body: Body) -> None:
    """A 409 for samples sent to a model of raw trials: its featurizer makes its samples,
    and answers must come from what the robot touched, not from images made elsewhere.
    (``read_body`` refuses trials sent to a model of samples, before reading them.)"""
    if body.samples is not None and rec.input_kind == RAW_TRIALS:
        raise Problem(
            409,
            "this model was fitted on raw BioTac trials and takes raw trials: send "
            '{"trials": [...]} (or an HDF5 body), not samples',
            "samples",
        )


async def read_body(
    request: Request,
    input_shape: tuple[int, ...],
    batch_limit: int,
    procedures: tuple[str, ...] = (),
    input_kind: str = RAW_TRIALS,
) -> Body:
    """The body's samples (JSON or .npy) or raw trials (JSON or HDF5), by its Content-Type,
    at most ``batch_limit``; the model validates samples, the trials are validated here.
    Samples may lack procedures (``app.api.sample_input``), and one sample may come alone,
    without its list, in JSON as in .npy. Trials sent to a model of samples (``input_kind``)
    are a 409 that says what it takes, before they are read."""
    content_type = media_type(request, (JSON, NPY, trials.HDF5))
    body = await request.body()
    if content_type == trials.HDF5:
        if input_kind != RAW_TRIALS:
            raise trials.refused(input_shape, "trials")
        parsed = await run_in_threadpool(trials.from_hdf5, body, batch_limit)
        return Body(None, parsed, len(parsed))
    objects = None  # a JSON body's table labels
    if content_type == NPY:
        samples = _from_npy(body)
        n = 1 if samples.ndim <= len(input_shape) else len(samples)  # one bare sample
    else:
        args = (body, input_shape, batch_limit, procedures, input_kind)
        parsed = (
            await run_in_threadpool(_from_json, *args)
            if len(body) > PARSE_INLINE_BYTES
            else _from_json(*args)
        )
        if parsed.trials is not None:
            return parsed
        samples, n, objects = parsed.samples, parsed.n, parsed.objects
    if n > batch_limit:
        raise Problem(
            422,
            f"{n} samples is more than the batch limit of {batch_limit}: send at most "
            f"{batch_limit} a request, or raise TACTILE_BATCH_LIMIT on the service",
            "samples",
        )
    return Body(samples, None, n, objects)


def _from_json(
    body: bytes,
    input_shape: tuple[int, ...],
    batch_limit: int,
    procedures: tuple[str, ...] = (),
    input_kind: str = RAW_TRIALS,
) -> Body:
    """The samples of a JSON body: an array when well-formed, else pydantic's errors or a
    422 naming the first sample not of ``input_shape``; or its validated ``trials``.

    The fast path (orjson, then one numpy conversion) takes only what the schema accepts:
    an object holding just a non-empty ``samples`` list of numeric samples, each a list
    of numbers or of lists of numbers. Anything else (NaN/Infinity literals, strings,
    ragged or mis-nested lists, extra fields) goes to pydantic, which names the problem.
    """
    objects = None
    try:
        data = orjson.loads(body)
        if isinstance(data, dict) and "trials" in data:
            return _trials(data, input_shape, batch_limit, input_kind)
        if isinstance(data, dict) and len(data) == 1:
            samples = data["samples"]
        elif isinstance(data, dict) and "objects" in data:  # a table (docs/TABLES.md)
            objects = data.pop("objects")
            samples = data["samples"] if len(data) == 1 else None
        else:
            samples = None
        if isinstance(samples, list) and samples:
            x = np.asarray(samples)
            if x.dtype.kind in "fiu" and x.shape == input_shape:  # one sample alone
                x = x[None]
            if x.dtype.kind in "fiu" and x.ndim in (2, 3) and x.shape[1:] == input_shape:
                with np.errstate(over="ignore"):  # beyond float32 is inf: rejected by name below
                    x = x.astype(np.float32, copy=False)
                    return Body(x, None, len(x), objects)
    except (orjson.JSONDecodeError, KeyError, ValueError, OverflowError):
        pass
    # json and pydantic read NaN/Infinity literals, which the trial validator or the
    # framework then rejects by name
    data = None
    with contextlib.suppress(ValueError, RecursionError):
        data = json.loads(body)
        if isinstance(data, dict) and "trials" in data:
            return _trials(data, input_shape, batch_limit, input_kind)
    if isinstance(data, dict) and "objects" in data:  # checked by hand, with their fix
        objects = data.pop("objects")
    alone = isinstance(data, dict) and is_one_sample(data.get("samples"), input_shape, procedures)
    try:
        if alone:  # validated as the batch of one it stands for, its errors named as sent
            request = RecognizeRequest.model_validate({**data, "samples": [data["samples"]]})
        elif objects is not None:
            request = RecognizeRequest.model_validate(data)
        else:
            request = RecognizeRequest.model_validate_json(body)
    except ValidationError as exc:
        errors = exc.errors(include_url=False)
        if alone:
            errors = [{**e, "loc": _unwrapped(e["loc"])} for e in errors]
        raise RequestValidationError(
            [{**e, "loc": ("body", *e["loc"])} for e in errors], body=data
        ) from None
    samples = np.stack(
        [
            sample_array(s, input_shape, "samples" if alone else f"samples[{i}]", procedures, True)
            for i, s in enumerate(request.samples)
        ]
    )
    return Body(samples, None, len(samples), objects)


def _unwrapped(loc: tuple) -> tuple:
    """A location in the batch of one a lone sample was wrapped in, as the sample was sent."""
    return (loc[0], *loc[2:]) if loc[:2] == ("samples", 0) else loc


def _trials(data: dict, input_shape: tuple[int, ...], batch_limit: int, input_kind: str) -> Body:
    """The validated raw trials of a JSON body; a 409 before reading them, for a model of
    samples."""
    if input_kind != RAW_TRIALS:
        raise trials.refused(input_shape, "trials")
    objects = data.pop("objects", None)  # a table's labels (docs/TABLES.md)
    parsed = trials.parse(data, batch_limit)
    return Body(None, parsed, len(parsed), objects)


def _from_npy(body: bytes) -> np.ndarray:
    """The array of a .npy body, read in place: ``np.load`` would copy a batch of 1,024
    samples (4 MB) twice in 256 kB pieces. Never unpickles (object arrays are refused)."""
    stream = io.BytesIO(body)
    try:
        version = np.lib.format.read_magic(stream)
        read_header = {
            (1, 0): np.lib.format.read_array_header_1_0,
            (2, 0): np.lib.format.read_array_header_2_0,
        }.get(version)
        if read_header is None:
            raise ValueError(
                f".npy format version {version[0]}.{version[1]} is not supported (use 1.0 or 2.0)"
            )
        shape, fortran_order, dtype = read_header(stream)
    except (ValueError, EOFError, OSError) as exc:
        raise Problem(422, f"not a readable .npy array: {exc}", "body") from None
    if dtype.hasobject or dtype.kind not in "fiu":
        raise Problem(422, "the .npy array must hold real numbers", "body")
    count = int(np.prod(shape))
    offset = stream.tell()
    if len(body) - offset != count * dtype.itemsize:
        raise Problem(
            422,
            f"not a readable .npy array: {len(body) - offset} bytes of data for an "
            f"array of shape {shape} and type {dtype}",
            "body",
        )
    x = np.frombuffer(body, dtype, count, offset)  # a read-only view of the body
    return x.reshape(shape, order="F" if fortran_order else "C")
