"""Dependencies: settings, a database session per request, the served model, the API key."""

from __future__ import annotations

import hmac
from collections.abc import Iterator
from typing import Annotated

from fastapi import Depends, Path, Request, Security
from fastapi.security import APIKeyHeader
from sqlalchemy.orm import Session

from app.api.problems import Problem
from app.config import Settings
from app.service.batcher import RecognitionBatcher
from app.service.holder import LoadedModel, ModelHolder
from app.service.metrics import Metrics

# async: trivial dependencies then run on the event loop, not in the thread pool


async def get_settings(request: Request) -> Settings:
    return request.app.state.settings


async def get_holder(request: Request) -> ModelHolder:
    return request.app.state.holder


async def get_batcher(request: Request) -> RecognitionBatcher:
    return request.app.state.batcher


async def get_metrics(request: Request) -> Metrics:
    return request.app.state.metrics


def get_session(request: Request) -> Iterator[Session]:
    with request.app.state.sessions() as session:
        yield session


async def get_model(request: Request) -> LoadedModel:
    """The snapshot a request works with from start to end, even if a swap happens."""
    model = request.app.state.holder.current
    if model is None:
        raise Problem(503, "no model is loaded yet; try again shortly", "model", {"Retry-After": "5"})
    return model


api_key_header = APIKeyHeader(name="X-API-Key", auto_error=False, description="Needed on POST when keys are configured.")


async def require_api_key(
    request: Request, key: Annotated[str | None, Security(api_key_header)]
) -> None:
    keys = request.app.state.settings.api_keys
    if not keys:
        return
    # compare against every key in constant time: timing reveals nothing about the keys
    if key is None or not any(hmac.compare_digest(key.encode(), k.encode()) for k in keys):
        raise Problem(
            401, "a valid X-API-Key header is required", "X-API-Key", {"WWW-Authenticate": "APIKey"}
        )


# ids fit a 32-bit INTEGER column on every backend; beyond that is a 422, not a database error
RowId = Annotated[int, Path(ge=1, le=2_147_483_647)]

SettingsDep = Annotated[Settings, Depends(get_settings)]
SessionDep = Annotated[Session, Depends(get_session)]
HolderDep = Annotated[ModelHolder, Depends(get_holder)]
MetricsDep = Annotated[Metrics, Depends(get_metrics)]
BatcherDep = Annotated[RecognitionBatcher, Depends(get_batcher)]
ModelDep = Annotated[LoadedModel, Depends(get_model)]
WriteAccess = Depends(require_api_key)
