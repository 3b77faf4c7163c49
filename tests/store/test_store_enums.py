"""The store's string enums: members are the stored strings, and each fits its column."""

from __future__ import annotations

import json

import pytest

from app.store.enums import ClassKind, JobKind, JobStatus, Origin, VersionReason
from app.store.models import Job, ModelVersion, ObjectClass, Sample


@pytest.mark.parametrize(
    ("enum", "column"),
    [
        (JobKind, Job.kind),
        (JobStatus, Job.status),
        (Origin, ObjectClass.origin),
        (Origin, Sample.origin),
        (ClassKind, ObjectClass.kind),
        (VersionReason, ModelVersion.reason),
    ],
)
def test_every_value_fits_its_column(enum, column):
    assert max(len(member) for member in enum) <= column.type.length


def test_members_are_the_strings_stored_and_sent():
    assert JobStatus.QUEUED == "queued" and "add_sample" in (JobKind.ADD_SAMPLE,)
    assert f"{Origin.ENROLLED}" == "enrolled" and str(ClassKind.NOVEL) == "novel"
    assert json.dumps({"reason": VersionReason.WITHDRAWAL}) == '{"reason": "withdrawal"}'
    assert [m.value for m in JobKind] == [
        "register_class",
        "add_sample",
        "update_class",
        "withdraw_class",
        "withdraw_sample",
        "add_attribute",
        "retire_attribute",
        "choose_method",
    ]
    assert [m.value for m in VersionReason] == [
        "bootstrap",
        "update",
        "promotion",
        "withdrawal",
        "method choice",
    ]


def test_rows_written_with_members_read_back_as_the_strings(store):
    from app.store import repo

    _, sessions = store
    with sessions.begin() as s:
        cls = repo.add_class(s, "mug", "01" * 12)
        job = repo.add_job(s, JobKind.REGISTER_CLASS, cls.id)
        ids = cls.id, job.id
    with sessions() as s:
        cls, job = s.get(ObjectClass, ids[0]), s.get(Job, ids[1])
        assert (cls.kind, cls.origin, job.kind, job.status) == (
            "novel",
            "enrolled",
            "register_class",
            "queued",
        )
        assert type(job.status) is str
