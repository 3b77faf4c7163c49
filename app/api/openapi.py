"""The OpenAPI document: FastAPI's, plus what a client generator needs to make a whole client.

- the shared problem components that every error response references (``problems.COMPONENTS``)
  and the JSON body of the routes that read their body by hand (recognize, describe);
- the shape of one sample, which only the served model knows, written where a client looks
  for it: the sample fields' descriptions and the document's introduction;
- the headers the routes promise (``Location`` of every 202, ``Retry-After`` of 429 and
  503, ``WWW-Authenticate`` of 401, ``ETag`` and ``X-Model-Version`` of a bundle);
- OpenAPI links from the ids a response names to the operations that take them: a class's
  202 to its samples, a sample to recognition, an attribute to a class described by it, a
  job to its class (a client or a stateful fuzzer follows them; bench/fuzz.py does).
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any

from fastapi import FastAPI
from pydantic import BaseModel

from app.api import problems
from app.api.problems import COMPONENTS
from app.api.schemas import RecognizeRequest, RecognizeTrialsRequest, SampleCreate
from app.framework.recognizer import RAW_TRIALS

# bodies read by hand, which FastAPI therefore does not list among its components
BODIES: dict[str, type[BaseModel]] = {
    "RecognizeRequest": RecognizeRequest,
    "RecognizeTrialsRequest": RecognizeTrialsRequest,
}
REF = "#/components/schemas/{model}"


def install(app: FastAPI) -> None:
    """Replace ``app.openapi`` by the completed document (one per served input shape)."""
    app.openapi = document_for(app, app.openapi)


def document_for(
    app: FastAPI, fastapi_document: Callable[[], dict[str, Any]]
) -> Callable[[], dict]:
    done: dict[tuple[tuple[int, ...] | None, str | None], dict[str, Any]] = {}

    def document() -> dict[str, Any]:
        model = app.state.service.holder.current
        rec = model.recognizer if model is not None else None
        shape = tuple(rec.input_shape) if rec is not None else None
        kind = rec.input_kind if rec is not None else None
        if (shape, kind) not in done:
            doc = copy.deepcopy(fastapi_document())
            schemas = doc.setdefault("components", {}).setdefault("schemas", {})
            for name, cls in {**COMPONENTS, **BODIES}.items():
                schema = cls.model_json_schema(ref_template=REF)
                schemas.update(schema.pop("$defs", {}))
                schemas[name] = {**schema, "title": name}
            if shape is not None:
                _state_shape(doc, list(shape))
            _add_unreadable_body(doc)
            _add_headers(doc)
            _add_links(doc, "trials" if kind == RAW_TRIALS else "samples")
            done[(shape, kind)] = doc
        return done[(shape, kind)]

    return document


def _state_shape(doc: dict[str, Any], shape: list[int]) -> None:
    """Say the served model's sample shape in the sample fields and the introduction."""
    note = (
        f" On this service one sample has shape {shape} (nested lists, outermost first); "
        "`input_shape` of `GET /v1/models/active` says so too."
    )
    schemas = doc["components"]["schemas"]
    for body, field in (("RecognizeRequest", "samples"), (SampleCreate.__name__, "sample")):
        prop = schemas.get(body, {}).get("properties", {}).get(field)
        if prop is not None:
            prop["description"] = prop.get("description", "") + note
    doc["info"]["description"] += (
        f"\n\nThe served model takes samples of shape `{shape}`: `POST /v1/recognize` and "
        f"`POST /v1/describe` take a batch of them, `POST /v1/classes/{{id}}/samples` one."
    )


def _add_unreadable_body(doc: dict[str, Any]) -> None:
    """The 400 of the routes whose JSON body FastAPI parses before any dependency runs (their
    request body is JSON only; recognize and describe read theirs by hand): a body it cannot
    read as JSON text (not UTF-8, or nested too deeply) is answered so, before the API key
    is checked. A JSON syntax error is a 422."""
    for operations in doc["paths"].values():
        for operation in operations.values():
            content = operation.get("requestBody", {}).get("content", {})
            if set(content) != {"application/json"} or "400" in operation["responses"]:
                continue
            (response,) = problems.responses(400).values()
            response["description"] = (
                "Bad Request: the body could not be read as JSON text (not UTF-8, or nested "
                "too deeply)"
            )
            operation["responses"]["400"] = response


def _header(description: str, schema: dict[str, Any]) -> dict[str, Any]:
    return {"description": description, "required": True, "schema": schema}


SECONDS = {"type": "string", "pattern": "^[0-9]+$"}
# status -> the headers every response of that status carries
HEADERS: dict[str, dict[str, dict[str, Any]]] = {
    "202": {
        "Location": _header(
            "The job that says when the change is in the served model: `/v1/jobs/{id}`.",
            {"type": "string", "pattern": "^/v1/jobs/[0-9]+$"},
        )
    },
    "401": {
        "WWW-Authenticate": _header("`APIKey`: send an `X-API-Key` header.", {"type": "string"})
    },
    "429": {"Retry-After": _header("Seconds to wait before the next request.", SECONDS)},
    "503": {"Retry-After": _header("Seconds to wait before trying again.", SECONDS)},
}
ETAG = _header(
    "The bundle's SHA-256, quoted: send it back in `If-None-Match`.",
    {"type": "string", "pattern": '^"[0-9a-f]{64}"$'},
)
VERSION = _header("The bundle's model version.", {"type": "integer", "minimum": 1})
BUNDLE_PATHS = ("/v1/models/active/bundle", "/v1/models/{version}/bundle")


def _add_headers(doc: dict[str, Any]) -> None:
    """Document the headers the routes set (``problems.responses`` leaves them out)."""
    for path, operations in doc["paths"].items():
        for operation in operations.values():
            for status, response in operation["responses"].items():
                headers = dict(HEADERS.get(status, {}))
                if path in BUNDLE_PATHS and status in ("200", "304"):
                    headers.update({"ETag": ETAG, "X-Model-Version": VERSION})
                if headers:
                    response["headers"] = {**response.get("headers", {}), **headers}


CLASS_ID = "$response.body#/class/id"
JOB_ID = "$response.body#/job/id"


def _links(input_field: str) -> dict[tuple[str, str, str], dict[str, dict[str, Any]]]:
    """(method, path, status) of a response -> its links: name -> (target operationId,
    parameters, request body, description). ``input_field``: how the served model takes a
    stored sample back (``samples``, or ``trials`` for a model of raw trials)."""
    job = ("jobs-get_job", {"job_id": JOB_ID}, None, "Poll the job this change queued.")
    a_class = {
        "GetClass": ("classes-get_class", {"class_id": CLASS_ID}, None, "Read the class."),
        "RedescribeClass": (
            "classes-redescribe_class",
            {"class_id": CLASS_ID},
            None,
            "Correct the class's description.",
        ),
        "AddSample": (
            "samples-add_sample",
            {"class_id": CLASS_ID},
            None,
            "Add a real sample of the class.",
        ),
        "ListSamples": (
            "samples-list_samples",
            {"class_id": CLASS_ID},
            None,
            "List the class's samples.",
        ),
        "ClassJobs": ("jobs-list_jobs", {"class_id": CLASS_ID}, None, "The class's jobs."),
        "WithdrawClass": (
            "classes-withdraw_class",
            {"class_id": CLASS_ID},
            None,
            "Withdraw the class.",
        ),
        "RetireAttribute": (
            "attributes-retire_attribute",
            {"name": "$response.body#/class/attributes/0"},
            None,
            "Retire the first attribute the class has.",
        ),
        "GetJob": job,
    }
    sample = {"class_id": "$request.path.class_id", "sample_id": "$response.body#/sample_id"}
    stored = {"class_id": "$request.path.class_id", "sample_id": "$request.path.sample_id"}
    touch = {input_field: ["$response.body#/sample"]}
    attribute = "$response.body#/attribute/name"
    return {
        ("post", "/v1/classes", "202"): a_class,
        ("patch", "/v1/classes/{class_id}", "202"): a_class,
        ("get", "/v1/classes/{class_id}", "200"): {
            "ListSamples": (
                "samples-list_samples",
                {"class_id": "$response.body#/id"},
                None,
                "List the class's samples.",
            ),
        },
        ("get", "/v1/classes", "200"): {
            "GetFirstClass": (
                "classes-get_class",
                {"class_id": "$response.body#/classes/0/id"},
                None,
                "Read the page's first class.",
            ),
            "ListFirstClassSamples": (
                "samples-list_samples",
                {"class_id": "$response.body#/classes/0/id"},
                None,
                "List the samples of the page's first class.",
            ),
        },
        ("get", "/v1/classes/{class_id}/samples", "200"): {
            "GetFirstSample": (
                "samples-get_sample",
                {"class_id": "$request.path.class_id", "sample_id": "$response.body#/samples/0/id"},
                None,
                "Read the page's first sample with its data.",
            ),
        },
        ("post", "/v1/classes/{class_id}/samples", "202"): {
            "GetSample": ("samples-get_sample", sample, None, "Read the sample back."),
            "WithdrawSample": ("samples-withdraw_sample", sample, None, "Withdraw the sample."),
            "GetJob": job,
        },
        ("get", "/v1/classes/{class_id}/samples/{sample_id}", "200"): {
            "Recognize": ("recognize-recognize", {}, touch, "Recognise the stored sample."),
            "Describe": ("describe-describe", {}, touch, "Describe the stored sample."),
            "WithdrawSample": ("samples-withdraw_sample", stored, None, "Withdraw the sample."),
        },
        ("delete", "/v1/classes/{class_id}/samples/{sample_id}", "202"): {
            "GetClass": (
                "classes-get_class",
                {"class_id": "$response.body#/class_id"},
                None,
                "Read the class the sample was withdrawn from.",
            ),
            "GetJob": job,
        },
        ("delete", "/v1/classes/{class_id}", "202"): {"GetJob": job},
        ("post", "/v1/attributes", "202"): {
            "RegisterClass": (
                "classes-register_class",
                {},
                {"name": attribute, "attributes": {attribute: 1}},
                "Register a class, named after the attribute, that has it.",
            ),
            "RetireAttribute": (
                "attributes-retire_attribute",
                {"name": attribute},
                None,
                "Retire the attribute.",
            ),
            "GetJob": job,
        },
        ("delete", "/v1/attributes/{name}", "202"): {"GetJob": job},
        ("get", "/v1/jobs/{job_id}", "200"): {
            "GetClass": (
                "classes-get_class",
                {"class_id": "$response.body#/class_id"},
                None,
                "Read the class the job is about (none for an attribute's job).",
            ),
        },
        ("get", "/v1/models/active", "200"): {
            "GetBundle": (
                "models-download_model",
                {"version": "$response.body#/version"},
                None,
                "Download the active version's bundle.",
            ),
            "Activate": (
                "models-activate_model",
                {"version": "$response.body#/version"},
                None,
                "Activate the version again.",
            ),
        },
    }


def _add_links(doc: dict[str, Any], input_field: str) -> None:
    """Write the OpenAPI links of ``_links`` into the responses they start from."""
    ids = {
        op.get("operationId") for operations in doc["paths"].values() for op in operations.values()
    }
    # operationId -> its body's media types: schemathesis cannot tell which one a whole body
    # from a link is for when there are several (recognize: JSON, .npy, HDF5)
    bodies = {
        op.get("operationId"): tuple(op.get("requestBody", {}).get("content", {}))
        for operations in doc["paths"].values()
        for op in operations.values()
    }
    for (method, path, status), links in _links(input_field).items():
        response = doc["paths"].get(path, {}).get(method, {}).get("responses", {}).get(status)
        if response is None:
            continue
        out = response.setdefault("links", {})
        for name, (target, parameters, body, description) in links.items():
            if target not in ids:
                continue
            link: dict[str, Any] = {"operationId": target, "description": description}
            if parameters:
                link["parameters"] = parameters
            if body is not None:
                link["requestBody"] = body
                if len(bodies.get(target, ())) == 1:  # the whole body, as OpenAPI means it
                    link["x-schemathesis"] = {"merge_body": False}  # (schemathesis merges)
            out[name] = link
