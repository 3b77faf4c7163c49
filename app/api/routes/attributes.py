from fastapi import APIRouter

from app.api.deps import SessionDep
from app.api.schemas import AttributeList
from app.store import repo

router = APIRouter(prefix="/v1/attributes", tags=["attributes"])


@router.get("", response_model=AttributeList)
def list_attributes(session: SessionDep) -> AttributeList:
    """The attribute vocabulary, in the order attribute vectors use."""
    return AttributeList(attributes=repo.attribute_names(session))
