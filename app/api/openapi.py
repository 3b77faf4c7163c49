"""The OpenAPI document: FastAPI's, plus what a client generator needs to make a whole client.

- the shared problem components that every error response references (``problems.COMPONENTS``)
  and the JSON body of the routes that read their body by hand (recognize, describe);
- the shape of one sample, which only the served model knows, written where a client looks
  for it: the sample fields' descriptions and the document's introduction.
"""

from __future__ import annotations

import copy
from collections.abc import Callable
from typing import Any

from fastapi import FastAPI
from pydantic import BaseModel

from app.api.problems import COMPONENTS
from app.api.schemas import RecognizeRequest, RecognizeTrialsRequest, SampleCreate

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
    done: dict[tuple[int, ...] | None, dict[str, Any]] = {}

    def document() -> dict[str, Any]:
        model = app.state.service.holder.current
        shape = tuple(model.recognizer.input_shape) if model is not None else None
        if shape not in done:
            doc = copy.deepcopy(fastapi_document())
            schemas = doc.setdefault("components", {}).setdefault("schemas", {})
            for name, cls in {**COMPONENTS, **BODIES}.items():
                schema = cls.model_json_schema(ref_template=REF)
                schemas.update(schema.pop("$defs", {}))
                schemas[name] = {**schema, "title": name}
            if shape is not None:
                _state_shape(doc, list(shape))
            done[shape] = doc
        return done[shape]

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
