from fastapi import APIRouter

from app.api import problems
from app.api.deps import ReadAccess, SessionDep
from app.api.schemas import AttributeList
from app.store import repo

router = APIRouter(
    prefix="/v1/attributes",
    tags=["attributes"],
    dependencies=[ReadAccess],
    responses=problems.responses(401, 403, 429),
)


@router.get("", response_model=AttributeList)
def list_attributes(session: SessionDep) -> AttributeList:
    """The attribute vocabulary, in the order attribute vectors use."""
    return AttributeList(attributes=repo.attribute_names(session))
