import io

import numpy as np
import orjson
from fastapi import APIRouter, Request, Response
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError
from pydantic import ValidationError

from app.api import problems
from app.api.deps import JSON, NPY, RecognizingDep, api_key_header, media_type
from app.api.problems import Problem, blame
from app.api.schemas import RecognizeRequest, RecognizeResponse
from app.framework.recognizer import RecognitionBatch

router = APIRouter(prefix="/v1", tags=["recognize"], responses=problems.responses(401, 403, 429))

# Bodies above this are parsed in the thread pool, so one big JSON batch cannot stall
# the event loop.
PARSE_INLINE_BYTES = 64 * 1024

# The body is read by hand to accept JSON or .npy; this documents both, and the API key
# that RecognizingDep checks (the other routes' Security dependency documents it for them).
OPENAPI_EXTRA = {
    "security": [{api_key_header.scheme_name: []}],
    "requestBody": {
        "required": True,
        "content": {
            JSON: {"schema": {"$ref": "#/components/schemas/RecognizeRequest"}},
            NPY: {
                "schema": {
                    "type": "string",
                    "format": "binary",
                    "description": "A float array (N, *input_shape) saved with numpy.save.",
                },
            },
        },
    },
}


@router.post(
    "/recognize",
    response_model=RecognizeResponse,
    openapi_extra=OPENAPI_EXTRA,
    responses=problems.responses(413, 415, 422, 503),
)
async def recognize(request: Request, recognizing: RecognizingDep) -> Response:
    """Recognise a batch of samples as known or novel objects.

    Send `{"samples": [...]}` as JSON, or the same batch as a binary `.npy` body
    with `Content-Type: application/x-npy`.
    """
    model, service = recognizing
    samples, n = await read_samples(request, model.recognizer.input_shape, service.batch_limit)
    with blame("samples"):
        results = await service.recognize(model, samples, n)
    return Response(
        _to_json(model.version, results, model.class_ids), media_type="application/json"
    )


async def read_samples(
    request: Request,
    input_shape: tuple[int, ...],
    batch_limit: int,
) -> tuple[np.ndarray | list, int]:
    """The body's samples (JSON, or .npy by its Content-Type) and how many there are, at
    most ``batch_limit``; the model validates them."""
    content_type = media_type(request, (JSON, NPY))
    body = await request.body()
    if content_type == NPY:
        samples = _from_npy(body)
        n = 1 if samples.ndim <= len(input_shape) else len(samples)  # one bare sample
    else:
        samples = (
            await run_in_threadpool(_from_json, body, input_shape)
            if len(body) > PARSE_INLINE_BYTES
            else _from_json(body, input_shape)
        )
        n = len(samples)
    if n > batch_limit:
        raise Problem(422, f"{n} samples is more than the batch limit of {batch_limit}", "samples")
    return samples, n


def _to_json(version: int, batch: RecognitionBatch, class_ids: dict[str, int]) -> bytes:
    """The RecognizeResponse body (the schema documents it), built straight from the arrays."""
    return orjson.dumps({"model_version": version, "results": batch.records(class_ids)})


def _from_json(body: bytes, input_shape: tuple[int, ...]) -> np.ndarray:
    """The samples of a JSON body: an array when well-formed, else pydantic's errors or a
    422 naming the first sample not of ``input_shape``.

    The fast path (orjson, then one numpy conversion) takes only what the schema accepts:
    an object holding just a non-empty ``samples`` list of numeric samples, each a list
    of numbers or of lists of numbers. Anything else (NaN/Infinity literals, strings,
    ragged or mis-nested lists, extra fields) goes to pydantic, which names the problem.
    """
    try:
        data = orjson.loads(body)
        samples = data["samples"] if isinstance(data, dict) and len(data) == 1 else None
        if isinstance(samples, list) and samples:
            x = np.asarray(samples)
            if x.dtype.kind in "fiu" and x.ndim in (2, 3):
                with np.errstate(over="ignore"):  # beyond float32 is inf: rejected by name below
                    return x.astype(np.float32, copy=False)
    except (orjson.JSONDecodeError, KeyError, ValueError, OverflowError):
        pass
    # pydantic's own JSON parser; like json.loads it reads NaN/Infinity literals, which
    # the framework then rejects by name
    try:
        samples = RecognizeRequest.model_validate_json(body).samples
    except ValidationError as exc:
        raise RequestValidationError(
            [{**e, "loc": ("body", *e["loc"])} for e in exc.errors(include_url=False)]
        ) from None
    return np.stack([_one(s, i, input_shape) for i, s in enumerate(samples)])


def _one(sample: list, i: int, input_shape: tuple[int, ...]) -> np.ndarray:
    try:
        with np.errstate(over="ignore"):  # beyond float32 is inf: rejected by name later
            x = np.asarray(sample, dtype=np.float32)
    except ValueError:  # ragged nesting
        raise Problem(
            422,
            f"samples[{i}]: its rows have different lengths; one sample has shape "
            f"{list(input_shape)}",
            f"samples[{i}]",
        ) from None
    if x.shape != input_shape:
        raise Problem(
            422,
            f"samples[{i}]: shape {list(x.shape)}, where one sample has shape {list(input_shape)}",
            f"samples[{i}]",
        )
    return x


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
