"""The enrolment rules (``app.service.enrolment``) called directly on a real store: the
bootstrapped store of ``tests/service_fixtures.py`` (its dataset classes and vocabulary),
each test once per store."""

from __future__ import annotations

import contextlib
from types import SimpleNamespace

import numpy as np
import pytest
from sqlalchemy.exc import IntegrityError

from app.service import enrolment
from app.store import repo
from app.store.enums import JobKind, JobStatus, Origin
from app.words.interpret import TextInterpreter
from tests.service_fixtures import names_of, unused_vectors

ENROLLER = "key:1"


def described(attributes=None, attribute_vector=None, description=None) -> SimpleNamespace:
    """A description as a request body gives it (``ClassDescription``'s fields)."""
    return SimpleNamespace(
        attributes=attributes, attribute_vector=attribute_vector, description=description
    )


@pytest.fixture
def sessions(store):
    return store[1]


@pytest.fixture
def attributes(dataset) -> list[list[str]]:
    """Attribute lists no dataset class has, two attributes each."""
    return [names_of(v, dataset) for v in unused_vectors(dataset, 3)]


@pytest.fixture(scope="module")
def interpreter() -> TextInterpreter:
    return TextInterpreter()


def register(sessions, name, attributes, interpreter, **kw) -> enrolment.Enrolled:
    with sessions() as s:
        return enrolment.register_class(
            s, name, described(attributes), interpreter, requested_by=ENROLLER, **kw
        )


def jobs_of(sessions, class_id: int) -> list[tuple[str, int | None]]:
    with sessions() as s:
        rows = repo.list_jobs(s, None, 1000, class_id=class_id)
        return [(j.kind, j.sample_id) for j in rows]


def test_a_registration_is_a_committed_class_and_its_job(sessions, attributes, interpreter):
    done = register(sessions, "cup", attributes[0], interpreter)
    assert done.cls.origin == Origin.ENROLLED and done.job.kind == JobKind.REGISTER_CLASS
    assert done.job.requested_by == ENROLLER and done.job.status == JobStatus.QUEUED
    with sessions() as s:  # another session sees it: committed
        cls = repo.class_by_name(s, "cup")
        assert cls.id == done.cls.id
        assert sorted(n for n, v in repo.vocabulary(s).values(cls.attribute_key).items() if v)
        assert jobs_of(sessions, cls.id) == [(JobKind.REGISTER_CLASS, None)]


def test_a_live_name_or_vector_is_refused_naming_the_field(sessions, attributes, interpreter):
    register(sessions, "cup", attributes[0], interpreter)
    with pytest.raises(enrolment.NameTaken, match="a class named 'cup' already exists") as e:
        register(sessions, "cup", attributes[1], interpreter)
    assert e.value.field == "name"
    with pytest.raises(enrolment.SameDescription, match="class 'cup' has the same") as e:
        register(sessions, "mug", attributes[0], interpreter)
    assert e.value.field == "attributes"
    with sessions() as s:
        assert repo.class_by_name(s, "mug") is None  # nothing stored


def test_names_are_compared_without_regard_to_case_and_surrounding_spaces(
    sessions, attributes, interpreter
):
    first = register(sessions, "foam-block", attributes[0], interpreter)
    for name in ("Foam-Block", " FOAM-BLOCK  "):
        with pytest.raises(enrolment.NameTaken) as e:
            register(sessions, name, attributes[1], interpreter)
        assert e.value.field == "name"
        assert str(e.value).startswith(
            f"a class named 'foam-block' already exists (class {first.cls.id}; names are "
            "compared without regard to case)"
        )
    with sessions() as s:
        assert repo.class_by_name(s, "FOAM-block").id == first.cls.id
        enrolment.withdraw_class(s, first.cls.id, requested_by=ENROLLER)
    # a withdrawn class comes back under any spelling of its name, with its own
    again = register(sessions, "Foam-Block", attributes[1], interpreter)
    assert again.cls.id == first.cls.id and again.cls.name == "foam-block"


def test_the_store_refuses_a_second_spelling_of_a_name(sessions):
    """The unique index on the folded name holds even where the rules are bypassed
    (a concurrent registration that checked before the other committed)."""
    with sessions() as s:
        repo.add_class(s, "Mug", "")
        s.commit()
    with sessions() as s, pytest.raises(IntegrityError):
        repo.add_class(s, "mug ", "")


def test_a_dataset_class_name_is_taken(sessions, dataset, attributes, interpreter):
    with pytest.raises(enrolment.NameTaken):
        register(sessions, dataset.class_names[0], attributes[0], interpreter)


def test_a_withdrawn_name_revives_its_class_with_or_without_samples(
    sessions, dataset, attributes, interpreter
):
    first = register(sessions, "cup", attributes[0], interpreter)
    with sessions() as s:
        enrolment.withdraw_class(s, first.cls.id, requested_by=ENROLLER)
    again = register(sessions, "cup", attributes[1], interpreter)
    assert again.cls.id == first.cls.id  # the same class back, described anew
    with sessions() as s:
        enrolment.withdraw_class(s, first.cls.id, requested_by=ENROLLER)
    x = dataset.samples[0]
    learnt = register(
        sessions,
        "cup",
        attributes[2],
        interpreter,
        samples=lambda: [x, x],
        method=SimpleNamespace(learns_classes_from_samples=False, graded_attributes=False),
    )
    assert learnt.cls.id == first.cls.id
    with sessions() as s:
        assert repo.sample_counts(s, [first.cls.id]) == {first.cls.id: 2}
        kept = repo.samples_of(s, [first.cls.id])
        assert all(np.array_equal(repo.decode(r), x) for r in kept)
    queued = jobs_of(sessions, first.cls.id)
    assert sorted(k for k, sid in queued if sid is not None) == [JobKind.ADD_SAMPLE] * 2


def test_a_failed_registration_registered_again_is_a_new_attempt(sessions, attributes, interpreter):
    first = register(sessions, "cup", attributes[0], interpreter)
    with sessions.begin() as s:
        repo.finish_jobs(s, [first.job.id], JobStatus.FAILED, error="it broke")
    with pytest.raises(enrolment.NameTaken):  # another description is another class
        register(sessions, "cup", attributes[1], interpreter)
    again = register(sessions, "cup", attributes[0], interpreter)
    assert again.cls.id == first.cls.id and again.job.id != first.job.id


def test_samples_are_read_only_once_the_method_can_learn_from_them(sessions, dataset):
    read = []

    def samples():
        read.append(1)
        return [dataset.samples[0]]

    cannot = SimpleNamespace(method="paper", learns_classes_from_samples=False)
    with pytest.raises(enrolment.CannotLearn, match="method 'paper'") as e:
        register(
            sessions, "cup", None, None, samples=samples, samples_field="trials", method=cannot
        )
    assert e.value.field == "trials" and read == []
    needs = SimpleNamespace(graded_attributes=False, learns_classes_from_samples=True)
    with pytest.raises(enrolment.CannotLearn, match="by attributes"):
        register(
            sessions, "cup", None, None, samples=samples, method=needs, model_has_attributes=True
        )
    assert read == []
    learns = SimpleNamespace(graded_attributes=True, learns_classes_from_samples=True)
    done = register(
        sessions, "cup", None, None, samples=samples, method=learns, model_has_attributes=True
    )
    assert read == [1] and done.cls.attribute_key == ""  # described by nothing: its samples


def test_descriptions_name_what_is_wrong(sessions, dataset, interpreter):
    with pytest.raises(enrolment.InvalidDescription, match="unknown attribute") as e:
        register(sessions, "cup", ["hard", "no-such-word"], interpreter)
    assert e.value.field == "attributes"
    n = dataset.n_attributes
    with sessions() as s, pytest.raises(enrolment.InvalidDescription, match="expected") as e:
        enrolment.register_class(
            s, "cup", described(attribute_vector=[1] * (n - 1)), None, requested_by=ENROLLER
        )
    assert e.value.field == "attribute_vector"
    with sessions() as s, pytest.raises(enrolment.InvalidDescription, match="above 0"):
        enrolment.register_class(
            s, "cup", described(attributes={"hard": 0}), None, requested_by=ENROLLER
        )


def test_a_description_in_words_is_read_and_kept(sessions, interpreter):
    text = "not hard, slightly rough"
    with sessions() as s:
        done = enrolment.register_class(
            s, "cup", described(description=text), interpreter, requested_by=ENROLLER
        )
    with sessions() as s:
        cls = repo.get_class(s, done.cls.id)
        values = repo.vocabulary(s).values(cls.attribute_key)
        assert cls.description == text and (values["hard"], values["rough"]) == (0.0, 0.6)
        assert {r["attribute"]: r["value"] for r in cls.description_readings} == values
    with sessions() as s, pytest.raises(enrolment.InvalidDescription) as e:
        enrolment.register_class(
            s,
            "mug",
            described(attributes={"hard": 1}, description="not hard, slightly rough, thick"),
            interpreter,
            requested_by=ENROLLER,
        )
    assert "correct one of them" in str(e.value) and e.value.field == "attributes"


def test_redescription_keeps_a_dataset_class_s_values(sessions, dataset, attributes, interpreter):
    with sessions() as s:
        cid = repo.class_by_name(s, dataset.class_names[0]).id
    with sessions() as s, pytest.raises(enrolment.DatasetClass, match="stay fixed") as e:
        enrolment.redescribe_class(
            s, cid, described(attributes={"hard": 1}), interpreter, requested_by=ENROLLER
        )
    assert e.value.field == "attributes.hard"
    with sessions() as s, pytest.raises(enrolment.DatasetClass, match="mapping"):
        enrolment.redescribe_class(s, cid, described(["hard"]), interpreter, requested_by=ENROLLER)
    with sessions() as s, pytest.raises(enrolment.NotFound, match="no class with class_id 9999"):
        enrolment.redescribe_class(s, 9999, described(["hard"]), None, requested_by=ENROLLER)


def test_redescription_refuses_another_class_s_vector(sessions, attributes, interpreter):
    cup = register(sessions, "cup", attributes[0], interpreter).cls.id
    register(sessions, "mug", attributes[1], interpreter)
    with sessions() as s, pytest.raises(enrolment.SameDescription, match="class 'mug'"):
        enrolment.redescribe_class(
            s, cup, described(attributes[1]), interpreter, requested_by=ENROLLER
        )
    with sessions() as s:
        done = enrolment.redescribe_class(
            s, cup, described(attributes[2]), interpreter, requested_by=ENROLLER
        )
    assert done.job.kind == JobKind.UPDATE_CLASS
    assert jobs_of(sessions, cup)[-1] == (JobKind.UPDATE_CLASS, None)


def test_only_enrolled_classes_and_samples_are_withdrawn(
    sessions, dataset, attributes, interpreter
):
    with sessions() as s:
        known = repo.class_by_name(s, dataset.class_names[0]).id
        sample_id = repo.list_samples(s, known, None, 1)[0].id
    with sessions() as s, pytest.raises(enrolment.DatasetClass, match="only enrolled classes"):
        enrolment.withdraw_class(s, known, requested_by=ENROLLER)
    with sessions() as s, pytest.raises(enrolment.DatasetClass, match="only enrolled samples"):
        enrolment.withdraw_sample(s, known, sample_id, requested_by=ENROLLER)
    x = dataset.samples[0]
    learns = SimpleNamespace(learns_classes_from_samples=True, graded_attributes=True)
    cup = register(
        sessions, "cup", attributes[0], interpreter, samples=lambda: [x], method=learns
    ).cls.id
    with sessions() as s:
        row = repo.list_samples(s, cup, None, 1)[0]
    with sessions() as s, pytest.raises(enrolment.NotFound, match="sample_id"):
        enrolment.withdraw_sample(s, cup, row.id + 10_000, requested_by=ENROLLER)
    with sessions() as s:
        done = enrolment.withdraw_sample(s, cup, row.id, requested_by=ENROLLER)
    assert (done.job.kind, done.job.sample_id) == (JobKind.WITHDRAW_SAMPLE, row.id)
    with sessions() as s:
        assert repo.sample_counts(s, [cup]).get(cup, 0) == 0


def test_a_concurrent_registration_of_the_name_is_named_as_the_conflict(
    sessions, attributes, interpreter
):
    """The name is free when checked, then taken by another writer before this one
    writes: the store's unique constraint stops it, and the conflict is named."""

    @contextlib.contextmanager
    def racing(session, recheck):
        with sessions.begin() as other:
            repo.add_class(other, "cup", repo.vocabulary(other).key({attributes[1][0]: 1.0}))
        with enrolment.guarded(session, recheck):
            yield

    with pytest.raises(enrolment.NameTaken) as e:
        register(sessions, "cup", attributes[0], interpreter, writing=racing)
    assert isinstance(e.value.__context__, IntegrityError)


def test_samples_are_added_to_novel_classes_only(sessions, dataset, attributes, interpreter):
    with sessions() as s, pytest.raises(enrolment.KnownClass, match="is a known class") as e:
        enrolment.novel_class(s, repo.class_by_name(s, dataset.class_names[0]).id)
    assert e.value.field == "class_id"
    with sessions() as s, pytest.raises(enrolment.NotFound, match="class_id 9999"):
        enrolment.novel_class(s, 9999)
    cup = register(sessions, "cup", attributes[0], interpreter).cls.id
    x = dataset.samples[1]
    with sessions() as s:
        row, job = enrolment.add_sample(s, enrolment.novel_class(s, cup), x, requested_by=ENROLLER)
    assert (job.kind, job.sample_id, job.requested_by) == (JobKind.ADD_SAMPLE, row.id, ENROLLER)
    with sessions() as s:
        assert np.array_equal(repo.decode(repo.sample_record(s, cup, row.id)), x)


def test_an_attribute_is_added_with_values_and_readings_of_class_texts(sessions, interpreter):
    with sessions() as s:
        worded = enrolment.register_class(
            s, "sponge", described(description="soft and squishy"), interpreter, requested_by=None
        ).cls.id
    with sessions() as s, pytest.raises(enrolment.UnknownClassName) as e:
        enrolment.add_attribute(s, "wet", {"nothing": 1}, interpreter, requested_by=ENROLLER)
    assert e.value.field == "values.nothing"
    with sessions() as s:
        done = enrolment.add_attribute(s, "sticky", {}, interpreter, requested_by=ENROLLER)
    assert done.job.kind == JobKind.ADD_ATTRIBUTE and done.job.attribute_id == done.cls.id
    with sessions() as s:
        assert "sticky" in repo.vocabulary(s).active
        cls = repo.get_class(s, worded)
        assert "sticky" not in repo.vocabulary(s).values(cls.attribute_key)  # its text is silent
    with sessions() as s, pytest.raises(enrolment.AttributeTaken, match="exists"):
        enrolment.add_attribute(s, "sticky", {}, interpreter, requested_by=ENROLLER)


def test_retiring_an_attribute_keeps_classes_apart_and_described(
    sessions, dataset, attributes, interpreter
):
    a, b = attributes[0]  # two attributes: "cup" has both, "mug" only the first
    register(sessions, "cup", [a, b], interpreter)
    register(sessions, "mug", [a], interpreter)
    with sessions() as s, pytest.raises(enrolment.SameDescription, match=f"retiring '{b}'"):
        enrolment.retire_attribute(s, b, requested_by=ENROLLER)
    with sessions() as s, pytest.raises(enrolment.NotFound, match="no attribute with name"):
        enrolment.retire_attribute(s, "no-such-word", requested_by=ENROLLER)
    with sessions() as s:
        free = next(n for n in dataset.attribute_names if n not in (a, b))
        done = enrolment.retire_attribute(s, free, requested_by=ENROLLER)
    assert done.job.kind == JobKind.RETIRE_ATTRIBUTE
    with sessions() as s, pytest.raises(enrolment.RetiredAttribute):
        enrolment.retire_attribute(s, free, requested_by=ENROLLER)


def test_doubts_name_a_confident_answer_of_another_class_unless_the_sample_is_new():
    cls = SimpleNamespace(name="foam-block")

    def answer(name, p, novel=False):
        top = [{"class_id": 7, "class_name": name, "probability": p}]
        return {"top_k": top, "is_novel": novel}

    sure = enrolment.doubts(cls, answer("blend-5-9", 0.99999996), ["foam-block", "blend-5-9"])
    assert sure == [
        "the served model recognises this sample as 'blend-5-9' (class 7) with probability "
        "0.99999996, not as 'foam-block': it is kept; if it was taken of another object, "
        "withdraw it (DELETE /v1/classes/{class_id}/samples/{sample_id})"
    ]
    served = ["foam-block", "blend-5-9"]
    assert enrolment.doubts(cls, answer("blend-5-9", 0.5), served) == []  # unsure
    assert enrolment.doubts(cls, answer("foam-block", 0.99), served) == []  # its own class
    # a class the model does not know yet: a novel sample goes to some other class
    assert enrolment.doubts(cls, answer("blend-5-9", 0.99, novel=True), ["blend-5-9"]) == []
    assert enrolment.doubts(cls, answer("blend-5-9", 0.99), ["blend-5-9"]) != []
