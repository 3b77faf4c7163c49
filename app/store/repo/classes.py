"""Classes and their samples (enrolment, withdrawal, new descriptions) and the attribute
vocabulary that describes them."""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from typing import Any

import numpy as np
from sqlalchemy import Row, Select, func, insert, or_, select, update
from sqlalchemy.orm import Session, aliased, defer

from app.data.biotac import RawTrial
from app.store.enums import ClassKind, JobKind, Origin
from app.store.models import Attribute, Job, ObjectClass, Sample, fold_name, utcnow
from app.store.repo.encoding import encode
from app.store.vocabulary import Vocabulary

# ---------------------------------------------------------------- attributes


def vocabulary(session: Session) -> Vocabulary:
    """Every attribute by position, which are retired and which the dataset brought."""
    rows = session.execute(
        select(Attribute.name, Attribute.origin, Attribute.retired_at).order_by(Attribute.position)
    ).all()
    return Vocabulary(
        names=tuple(r.name for r in rows),
        retired=frozenset(r.name for r in rows if r.retired_at is not None),
        fixed=frozenset(r.name for r in rows if r.origin == Origin.DATASET),
    )


def attribute_names(session: Session) -> list[str]:
    """The active attributes (not retired), in the order attribute vectors use."""
    return list(
        session.scalars(
            select(Attribute.name)
            .where(Attribute.retired_at.is_(None))
            .order_by(Attribute.position)
        )
    )


def list_attributes(session: Session) -> list[Attribute]:
    """Every attribute, retired ones included, by position."""
    return list(session.scalars(select(Attribute).order_by(Attribute.position)))


def attribute_by_name(session: Session, name: str) -> Attribute | None:
    """The attribute of that name, retired or not (names are never reused)."""
    return session.scalar(select(Attribute).where(Attribute.name == name))


def add_attributes(session: Session, names: Sequence[str]) -> None:
    """The bootstrap dataset's vocabulary."""
    session.add_all(
        Attribute(position=i, name=n, origin=Origin.DATASET) for i, n in enumerate(names)
    )


def add_attribute(session: Session, name: str) -> Attribute:
    """An attribute added through the API, after every existing one: existing keys keep
    their meaning (it is not known for them)."""
    last = session.scalar(select(func.max(Attribute.position)))
    row = Attribute(position=0 if last is None else last + 1, name=name, origin=Origin.ENROLLED)
    session.add(row)
    session.flush()
    return row


def describe(session: Session, keys: Mapping[int, str]) -> None:
    """New keys for classes, by class id (an attribute's values, or a class's own)."""
    for class_id, key in keys.items():
        session.execute(
            update(ObjectClass).where(ObjectClass.id == class_id).values(attribute_key=key)
        )


def retire_attribute(session: Session, attribute: Attribute, vocab: Vocabulary) -> None:
    """Later models leave the attribute out; every class's value for it is blanked, so keys
    compare as the active descriptions they are."""
    attribute.retired_at = utcnow()
    rows = session.execute(select(ObjectClass.id, ObjectClass.attribute_key)).all()
    blanked = {cid: (key, vocab.without(key, attribute.name)) for cid, key in rows}
    describe(session, {cid: new for cid, (old, new) in blanked.items() if new != old})
    session.flush()


# ------------------------------------------------------------------- classes


LIVE_CLASS = ObjectClass.withdrawn_at.is_(None)
LIVE_SAMPLE = Sample.withdrawn_at.is_(None)


def get_class(session: Session, class_id: int) -> ObjectClass | None:
    """The class, unless it does not exist or was withdrawn."""
    cls = session.get(ObjectClass, class_id)
    return cls if cls is not None and cls.withdrawn_at is None else None


def class_by_name(session: Session, name: str, withdrawn: bool = False) -> ObjectClass | None:
    """The live class of that name, compared without regard to case and surrounding spaces
    (``fold_name``); with ``withdrawn``, the withdrawn one (names are unique over both, so a
    withdrawn class's name comes back with its row). The exact name first, where a store
    kept two names differing only in case (migration 0010)."""
    state = ObjectClass.withdrawn_at.is_not(None) if withdrawn else LIVE_CLASS
    same = or_(ObjectClass.name_key == fold_name(name), ObjectClass.name == name)
    stmt = select(ObjectClass).where(same, state)
    return session.scalar(stmt.order_by((ObjectClass.name == name).desc()).limit(1))


def class_by_key(session: Session, key: str, other_than: int | None = None) -> ObjectClass | None:
    """A live class described by ``key`` (other than class ``other_than``)."""
    stmt = select(ObjectClass).where(ObjectClass.attribute_key == key, LIVE_CLASS)
    if other_than is not None:
        stmt = stmt.where(ObjectClass.id != other_than)
    return session.scalar(stmt.limit(1))


def list_classes(
    session: Session, after: int | None = None, limit: int | None = None
) -> list[ObjectClass]:
    """Live classes by id; with ``after``, those after it; at most ``limit``."""
    stmt = select(ObjectClass).where(LIVE_CLASS).order_by(ObjectClass.id).limit(limit)
    if after is not None:
        stmt = stmt.where(ObjectClass.id > after)
    return list(session.scalars(stmt))


#: a live class as a retrain plans with it: a row of (id, name, kind, origin, attribute_key)
ClassState = Row[tuple[int, str, str, str, str]]


def class_states(session: Session) -> list[ClassState]:
    """Live classes by id, as the columns a retrain compares with its model: rows, not
    ``ObjectClass`` objects, as each round reads them all (building the objects was about
    90 ms of every round at 10,200 classes: docs/BENCHMARKS.md)."""
    stmt = select(
        ObjectClass.id,
        ObjectClass.name,
        ObjectClass.kind,
        ObjectClass.origin,
        ObjectClass.attribute_key,
    )
    return list(session.execute(stmt.where(LIVE_CLASS).order_by(ObjectClass.id)))


def sample_counts(session: Session, class_ids: Sequence[int] | None = None) -> dict[int, int]:
    """Live samples per class."""
    stmt = select(Sample.class_id, func.count()).where(LIVE_SAMPLE).group_by(Sample.class_id)
    if class_ids is not None:
        stmt = stmt.where(Sample.class_id.in_(class_ids))
    return {cid: n for cid, n in session.execute(stmt)}


def class_names_of_samples(session: Session, sample_ids: Collection[int]) -> set[str]:
    """The names of the classes the samples ``sample_ids`` belong to, withdrawn or not."""
    if not sample_ids:
        return set()
    stmt = (
        select(ObjectClass.name)
        .join(Sample, Sample.class_id == ObjectClass.id)
        .where(Sample.id.in_(sample_ids))
    )
    return set(session.scalars(stmt))


def class_ids_by_name(session: Session) -> dict[str, int]:
    rows = session.execute(select(ObjectClass.id, ObjectClass.name).where(LIVE_CLASS))
    return {name: cid for cid, name in rows}


def add_class(
    session: Session,
    name: str,
    key: str,
    kind: str = ClassKind.NOVEL,
    origin: str = Origin.ENROLLED,
) -> ObjectClass:
    obj = ObjectClass(name=name, kind=kind, origin=origin, attribute_key=key)
    session.add(obj)
    session.flush()
    return obj


def promote_classes(session: Session, class_ids: Collection[int]) -> None:
    """These novel classes are known from now on (they gathered enough real samples)."""
    if class_ids:
        session.execute(
            update(ObjectClass)
            .where(ObjectClass.id.in_(class_ids))
            .values(kind=ClassKind.KNOWN, promoted_at=utcnow())
        )


def demote_classes(session: Session, class_ids: Collection[int]) -> None:
    """These promoted classes are novel again (withdrawals left them too few samples)."""
    if class_ids:
        session.execute(
            update(ObjectClass)
            .where(ObjectClass.id.in_(class_ids))
            .values(kind=ClassKind.NOVEL, promoted_at=None)
        )


# ------------------------------------------------------------------- samples


def add_sample(
    session: Session, class_id: int, sample: np.ndarray | RawTrial, origin: str = Origin.ENROLLED
) -> Sample:
    """A sample row: an array, or a raw trial kept as it was sent."""
    data, shape, form = encode(sample)
    row = Sample(class_id=class_id, origin=origin, shape=shape, data=data, form=form)
    session.add(row)
    session.flush()
    return row


def add_dataset_samples(
    session: Session,
    class_ids: Sequence[int],
    samples: np.ndarray | Sequence[RawTrial],
    trials: Sequence[int],
) -> None:
    """Bulk insert (one executemany) of a whole training set: arrays, or raw trials."""
    now = utcnow()
    rows = []
    for cid, x, trial in zip(class_ids, samples, trials, strict=True):
        data, shape, form = encode(x)
        rows.append(
            {
                "class_id": int(cid),
                "origin": Origin.DATASET,
                "trial": int(trial),
                "shape": shape,
                "data": data,
                "form": form,
                "created_at": now,
            }
        )
    if rows:
        session.execute(insert(Sample), rows)


def stored_sample_form(session: Session) -> tuple[str, list[int]] | None:
    """``(form, shape)`` of one live sample: what every sample of a store without a model
    must match (None: the store holds none yet)."""
    row = session.execute(select(Sample.form, Sample.shape).where(LIVE_SAMPLE).limit(1)).first()
    return None if row is None else (row.form, list(row.shape))


def samples_by_id(session: Session, sample_ids: Collection[int]) -> list[Sample]:
    """The samples ``sample_ids``, by id."""
    stmt = select(Sample).where(Sample.id.in_(sample_ids)).order_by(Sample.id)
    return list(session.scalars(stmt))


def samples_of(session: Session, class_ids: Sequence[int]) -> list[Sample]:
    """The live samples of these classes, by id."""
    stmt = select(Sample).where(Sample.class_id.in_(class_ids), LIVE_SAMPLE).order_by(Sample.id)
    return list(session.scalars(stmt))


def list_samples(
    session: Session, class_id: int, after: int | None = None, limit: int | None = None
) -> list[Row]:
    """Rows of ``id, origin, trial, created_at, enrolled_by`` (who added it) of the class's
    live samples by id; the sample data stay unread."""
    stmt = _live_samples(class_id).order_by(Sample.id).limit(limit)
    if after is not None:
        stmt = stmt.where(Sample.id > after)
    return list(session.execute(stmt))


def sample_record(session: Session, class_id: int, sample_id: int) -> Row | None:
    """The ``list_samples`` row of one live sample, with its ``shape``, ``data`` and ``form``
    (``encoding.decode`` reads it)."""
    stmt = _live_samples(class_id, Sample.shape, Sample.data, Sample.form).where(
        Sample.id == sample_id
    )
    return session.execute(stmt).first()


def _live_samples(class_id: int, *columns: Any) -> Select:
    enrolment = aliased(Job)
    return (
        select(
            Sample.id,
            Sample.origin,
            Sample.trial,
            Sample.created_at,
            enrolment.requested_by.label("enrolled_by"),
            *columns,
        )
        .outerjoin(
            enrolment, (enrolment.sample_id == Sample.id) & (enrolment.kind == JobKind.ADD_SAMPLE)
        )
        .where(Sample.class_id == class_id, LIVE_SAMPLE)
    )


def get_sample(session: Session, class_id: int, sample_id: int) -> Sample | None:
    """The live sample ``sample_id`` of class ``class_id`` (its data left unread)."""
    row = session.get(Sample, sample_id, options=[defer(Sample.data)])
    live = row is not None and row.class_id == class_id and row.withdrawn_at is None
    return row if live else None


# ------------------------------------------------- withdrawals, new descriptions


def withdraw_class(session: Session, cls: ObjectClass) -> None:
    """The class and its samples leave every later model (the worker's next round)."""
    now = utcnow()
    cls.withdrawn_at = now
    session.execute(
        update(Sample).where(Sample.class_id == cls.id, LIVE_SAMPLE).values(withdrawn_at=now)
    )
    session.flush()


def withdraw_sample(session: Session, row: Sample) -> None:
    row.withdrawn_at = utcnow()
    session.flush()


def set_description(
    session: Session, cls: ObjectClass, text: str | None, readings: list[dict] | None
) -> None:
    """The class's description in words and what was read from it (None: described by
    values alone; a registration by values clears an old text)."""
    cls.description, cls.description_readings = text, readings
    session.flush()


def redescribe_class(session: Session, cls: ObjectClass, key: str) -> None:
    """New attributes for a live class; its samples stay (the worker's next round)."""
    cls.attribute_key = key
    session.flush()


def revive_class(session: Session, cls: ObjectClass, key: str) -> ObjectClass:
    """A withdrawn class registered again: the same row, the new attributes, no samples."""
    cls.withdrawn_at, cls.attribute_key, cls.kind, cls.promoted_at = (
        None,
        key,
        ClassKind.NOVEL,
        None,
    )
    session.flush()
    return cls
