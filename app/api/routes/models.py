from fastapi import APIRouter

from app.api import problems
from app.api.deps import AdminAccess, HolderDep, PageDep, ReadAccess, RowId, SessionDep
from app.api.problems import Problem, not_found
from app.api.schemas import ModelList, ModelOut, ModelSummary
from app.framework.errors import BundleError
from app.store import bundles, repo

router = APIRouter(prefix="/v1/models", tags=["models"], responses=problems.responses(401, 403, 422, 429))


@router.get("", response_model=ModelList, dependencies=[ReadAccess])
def list_models(session: SessionDep, page: PageDep) -> ModelList:
    """The model versions the store keeps (``TACTILE_KEEP_VERSIONS``), oldest first, a
    page at a time, each without its class list (``GET /v1/models/{version}`` has it)."""
    rows, next_after = page.cut(repo.list_versions(session, page.after, page.limit + 1, summary=True),
                                lambda v: v.version)
    return ModelList(models=[ModelSummary.model_validate(v) for v in rows], next_after=next_after)


@router.get(
    "/active", response_model=ModelOut, dependencies=[ReadAccess],
    responses=problems.responses(404),
)
def active_model(session: SessionDep) -> ModelOut:
    row = repo.active_version(session)
    if row is None:
        raise Problem(404, "no model version is active yet", "version")
    return ModelOut.model_validate(row)


@router.get(
    "/{version}", response_model=ModelOut, dependencies=[ReadAccess],
    responses=problems.responses(404),
)
def get_model(version: RowId, session: SessionDep) -> ModelOut:
    """One stored model version with the classes it recognises."""
    row = repo.get_version(session, version)
    if row is None:
        raise not_found("model version", "version", version)
    return ModelOut.model_validate(row)


@router.post(
    "/{version}/activate", response_model=ModelOut, dependencies=[AdminAccess],
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
