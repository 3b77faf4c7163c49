from typing import Annotated

from fastapi import APIRouter, Header, Response
from sqlalchemy.orm import Session

from app.api import problems
from app.api.deps import (
    AdminAccess,
    Enroller,
    ExportsDep,
    HolderDep,
    PageDep,
    ReadAccess,
    RowId,
    SessionDep,
    SettingsDep,
)
from app.api.problems import Problem, not_found
from app.api.schemas import JobOut, ModelList, ModelOut, ModelSummary
from app.framework.errors import BundleError
from app.service.method_choice import NothingToChoose, ask_for_choice
from app.store import bundles, repo
from app.store.bundles import ExportCache
from app.store.models import ModelVersion

router = APIRouter(
    prefix="/v1/models", tags=["models"], responses=problems.responses(401, 403, 422, 429)
)


@router.get("", response_model=ModelList, dependencies=[ReadAccess])
def list_models(session: SessionDep, page: PageDep) -> ModelList:
    """The model versions the store keeps (``TACTILE_KEEP_VERSIONS``), oldest first, a
    page at a time, each without its class list (``GET /v1/models/{version}`` has it)."""
    rows, next_after = page.cut(
        repo.list_versions(session, page.after, page.limit + 1, summary=True), lambda v: v.version
    )
    return ModelList(models=[ModelSummary.model_validate(v) for v in rows], next_after=next_after)


@router.get(
    "/active",
    response_model=ModelOut,
    dependencies=[ReadAccess],
    responses=problems.responses(404),
)
def active_model(session: SessionDep) -> ModelOut:
    row = repo.active_version(session)
    if row is None:
        raise Problem(404, "no model version is active yet", "version")
    return ModelOut.model_validate(row)


@router.get(
    "/{version}",
    response_model=ModelOut,
    dependencies=[ReadAccess],
    responses=problems.responses(404),
)
def get_model(version: RowId, session: SessionDep) -> ModelOut:
    """One stored model version with the classes it recognises."""
    row = repo.get_version(session, version)
    if row is None:
        raise not_found("model version", "version", version)
    return ModelOut.model_validate(row)


BUNDLE_MEDIA_TYPE = "application/zip"
BUNDLE_RESPONSES = {
    200: {
        "description": "The model bundle (`tactile-zsl recognize --model FILE` reads it); "
        "`X-Model-Version` names its version",
        "content": {BUNDLE_MEDIA_TYPE: {"schema": {"type": "string", "format": "binary"}}},
    },
    304: {"description": "The client's copy, named by `If-None-Match`, is this version already"},
    **problems.responses(404, 409),
}
IfNoneMatch = Annotated[str | None, Header(description="the ETag of a bundle the client holds")]


@router.get(
    "/active/bundle", dependencies=[ReadAccess], response_class=Response, responses=BUNDLE_RESPONSES
)
def download_active_model(
    session: SessionDep,
    exports: ExportsDep,
    if_none_match: IfNoneMatch = None,
) -> Response:
    """The active version as a single bundle file, as `GET /v1/models/{version}/bundle`
    gives it: one request for a robot to stay current (304 while its copy is the active one)."""
    row = repo.active_version(session)
    if row is None:
        raise Problem(404, "no model version is active yet", "version")
    return _bundle_response(session, exports, row, if_none_match)


@router.get(
    "/{version}/bundle",
    dependencies=[ReadAccess],
    response_class=Response,
    responses=BUNDLE_RESPONSES,
)
def download_model(
    version: RowId, session: SessionDep, exports: ExportsDep, if_none_match: IfNoneMatch = None
) -> Response:
    """One stored model version as a single self-contained bundle file, to recognise on a
    robot without the network (`tactile-zsl recognize --model FILE SAMPLES`) with exactly
    the answers this service gives. The `ETag` names the version's content: send it back
    in `If-None-Match` to get 304 instead of the file when nothing changed."""
    row = repo.get_version(session, version)
    if row is None:
        raise not_found("model version", "version", version)
    return _bundle_response(session, exports, row, if_none_match)


def _bundle_response(
    session: Session, exports: ExportCache, row: ModelVersion, if_none_match: str | None
) -> Response:
    headers = {"ETag": f'"{row.bundle_sha256}"', "X-Model-Version": str(row.version)}
    if if_none_match is not None and _matches(if_none_match, headers["ETag"]):
        return Response(status_code=304, headers=headers)
    try:
        data = exports.export(session, row.bundle_sha256)
    except BundleError as exc:
        raise Problem(409, f"version {row.version} cannot be exported: {exc}", "version") from None
    return Response(
        data,
        media_type=BUNDLE_MEDIA_TYPE,
        headers={
            **headers,
            "Content-Disposition": f'attachment; filename="tactile-model-v{row.version}.bundle"',
        },
    )


def _matches(if_none_match: str, etag: str) -> bool:
    """RFC 9110 weak comparison of ``etag`` with an ``If-None-Match`` list (or ``*``)."""
    tags = [t.strip().removeprefix("W/") for t in if_none_match.split(",")]
    return "*" in tags or etag in tags


@router.post(
    "/{version}/activate",
    response_model=ModelOut,
    dependencies=[AdminAccess],
    responses=problems.responses(404, 409),
)
def activate_model(version: RowId, session: SessionDep, holder: HolderDep) -> ModelOut:
    """Make ``version`` the active model in every API process (activating an earlier
    version is the rollback). Later enrollments are folded in again by the next retrain.
    Only the versions the store keeps can be activated (``TACTILE_KEEP_VERSIONS``)."""
    row = repo.get_version(session, version)
    if row is None:
        raise not_found("model version", "version", version)
    try:  # never activate a bundle that cannot be loaded
        bundles.load_model(session, row.bundle_sha256)
    except BundleError as exc:
        if repo.get_version(session, version) is None:  # pruned by the worker meanwhile
            raise not_found("model version", "version", version) from None
        raise Problem(409, f"version {version} cannot be loaded: {exc}", "version") from None
    if not repo.activate(session, version):  # pruned by the worker meanwhile
        session.rollback()
        raise not_found("model version", "version", version)
    session.commit()
    session.refresh(row)
    holder.refresh()  # this process answers with it at once; others poll
    return ModelOut.model_validate(row)


@router.post(
    "/choice",
    status_code=202,
    response_model=JobOut,
    dependencies=[AdminAccess],
    responses=problems.responses(409),
)
def choose_method(
    session: SessionDep, settings: SettingsDep, response: Response, principal: Enroller
) -> JobOut:
    """Ask method `auto` to choose again: the worker's next round fits it anew on every
    stored sample (a probe of them, then the winner), where refits otherwise keep the method
    chosen before until the known classes have grown `TACTILE_RECHOOSE_GROWTH` times. The
    job's `model_version` is the version it made; that version's `method_choice` says what
    was chosen and why. A 409 where the service's method is fixed (not `auto`)."""
    try:
        job = ask_for_choice(session, settings.method, principal.id)
    except NothingToChoose as exc:
        raise Problem(409, str(exc), "method") from None
    session.commit()
    session.refresh(job)
    response.headers["Location"] = f"/v1/jobs/{job.id}"
    return JobOut.model_validate(job)
