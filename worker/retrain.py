"""What a retrain folds in (the plan) and how it builds the new recognizer.

The rule is "bring the active model up to date with the store": every class and
sample whose enrollment succeeded earlier or is claimed now belongs in the new
model; failed enrollments and ones still queued for the next round do not.
How the new model is made is the plan's ``Rebuild``. Usually that is an incremental
update (new FC_Z, one-shot samples); when a novel class has gathered
``promotion_threshold`` real samples it becomes a known class and the whole model is
fitted again from the stored samples. So is it when the base model holds something the
store has withdrawn (a class, a sample, or a class's old attributes, after a withdrawal
or a PATCH of them) in its known part, or in its novel part where one-shot samples may
have fine-tuned shared parts (the paper's generator): a fresh fit is the one way to leave
no trace of it. Methods whose novel part is rebuilt from the registry alone
(``novel_part_separable``, e.g. ``best``) drop their novel classes and add the live
ones back instead.

When the attribute vocabulary changed (an attribute added or retired) or a known class's
values did, methods whose attribute parts can be refitted alone (``attributes_separable``,
``best``) refit only those on the stored samples (``with_attributes``) and add every live
novel class back; others (the paper's pipeline, whose G takes the vocabulary as its
input) are fitted again. Class descriptions become vectors over the store's active
attributes (``app.store.vocabulary``), NaN where a value is not known.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field
from enum import StrEnum

import numpy as np
from sqlalchemy.orm import Session

from app.config import Settings
from app.data.biotac import BioTacDataset
from app.data.dataset import TactileDataset
from app.framework.recognizer import RAW_TRIALS, ClassRegistry, TactileRecognizer
from app.service.bootstrap import FIRST_MODEL_SAMPLES
from app.store import repo
from app.store.enums import ClassKind, JobKind, JobStatus, Origin, SampleForm, VersionReason
from app.store.models import Job, ModelVersion, Sample
from app.store.repo import ClassState
from app.store.vocabulary import Vocabulary, describes
from worker.refit import attributes_in_child, default_memory_limit, fit_in_child

# enrolled samples get trial ids far above any dataset's, one trial per sample
ENROLLED_TRIAL_OFFSET = 1_000_000_000


class Rebuild(StrEnum):
    """How a retrain makes the new model from the base one."""

    NONE = "none"  # the base model holds everything already: no new version
    INCREMENTAL = "incremental"  # the plan's new classes and samples added to the base
    NOVEL_PART = "novel part"  # the base's novel classes dropped, every live one added anew
    ATTRIBUTES = "attributes"  # the attribute parts refitted, every live novel class added anew
    KNOWN_GROWN = "known grown"  # promoted classes (and known ones' new samples) learnt into
    # the base's known part without a refit, every live novel class added anew
    FULL = "full"  # fitted again on the stored samples, every live novel class added


@dataclass
class Plan:
    vocabulary: Vocabulary = field(default_factory=Vocabulary)  # the store's, as planned
    rebuild: Rebuild = Rebuild.NONE
    reason: VersionReason = VersionReason.UPDATE  # the new model version's
    # what an incremental rebuild adds: classes the base lacks, new samples by class name
    new_classes: list[ClassState] = field(default_factory=list)
    new_samples: dict[str, list[Sample]] = field(default_factory=dict)
    promote: list[ClassState] = field(default_factory=list)
    # what a known-grown rebuild learns: class name -> the stored samples its known part lacks
    grow: dict[str, list[Sample]] = field(default_factory=dict)
    grow_keys: dict[str, str] = field(default_factory=dict)  # their descriptions (keys)
    # promoted classes left with fewer than ``promotion_threshold`` samples: novel again
    demote: list[ClassState] = field(default_factory=list)
    novel: list[ClassState] = field(default_factory=list)  # every novel class of the new model
    samples: dict[int, list[Sample]] = field(default_factory=dict)  # its enrolled samples by class
    rejected: dict[int, str] = field(default_factory=dict)  # job id -> why it cannot succeed
    # an operator asked method auto to choose again (a ``choose_method`` job): a full refit
    choose_method: bool = False
    # what a full refit fits (``worker.kept_method``): "" for the settings' method, and the
    # kept choice's record (None: auto chooses anew)
    method: str = ""
    kept_choice: dict | None = None

    @property
    def changes_model(self) -> bool:
        return self.rebuild is not Rebuild.NONE

    @property
    def sample_ids(self) -> list[int]:
        """Enrolled samples the new model contains."""
        return sorted(r.id for rows in self.samples.values() for r in rows)


def make_plan(
    s: Session,
    base: ModelVersion,
    model: TactileRecognizer,
    claimed: list[Job],
    threshold: int,
    keep_known: int | None = None,
    grow_fraction: float = 0.0,
) -> Plan:
    """``threshold``: samples that promote a novel class; a known enrolled class left with
    fewer than ``keep_known`` (default: ``threshold``) is novel again. A service started
    empty keeps its known classes from ``FIRST_MODEL_SAMPLES`` samples on, as its first
    model took them. ``grow_fraction``: a promotion (or a known class's new samples) is
    learnt into the base's known part without a refit while the samples so learnt since
    the last full fit stay within this share of that fit's samples, for methods that can
    (``learns_known_incrementally``); 0 always refits."""
    keep_known = threshold if keep_known is None else keep_known
    plan = Plan(vocabulary=repo.vocabulary(s))
    claimed_ids = {j.id for j in claimed}
    classes = repo.class_states(s)  # withdrawn ones are not among them
    by_id = {c.id: c for c in classes}
    live_classes = _live_registrations(s, claimed_ids)
    live_samples = set()
    redescribed = False  # an operator changed a class's attributes (PATCH)
    for job in claimed:
        if job.kind == JobKind.CHOOSE_METHOD:
            plan.choose_method = True
            continue
        if job.kind in (JobKind.ADD_ATTRIBUTE, JobKind.RETIRE_ATTRIBUTE):
            continue  # the vocabulary is compared with the base's below
        if (
            job.kind in (JobKind.REGISTER_CLASS, JobKind.ADD_SAMPLE, JobKind.UPDATE_CLASS)
            and job.class_id not in by_id
        ):
            plan.rejected[job.id] = f"class {job.class_id} was withdrawn"
        elif (
            job.kind == JobKind.UPDATE_CLASS
            and by_id[job.class_id].origin == Origin.ENROLLED
            and job.class_id not in live_classes
        ):
            plan.rejected[job.id] = (
                f"class '{by_id[job.class_id].name}' is not enrolled: its registration failed"
            )
        elif job.kind == JobKind.UPDATE_CLASS:
            redescribed = True
    for job_id, cid, sid, withdrawn_at in repo.sample_enrolments(s, claimed_ids):
        cls = by_id.get(cid)
        if cls is None or job_id in plan.rejected:
            continue
        if withdrawn_at is not None:
            if job_id in claimed_ids:
                plan.rejected[job_id] = f"sample {sid} was withdrawn"
            continue
        if cls.origin == Origin.ENROLLED and cid not in live_classes:
            if job_id in claimed_ids:
                plan.rejected[job_id] = (
                    f"class '{cls.name}' is not enrolled: its registration failed"
                )
            continue
        live_samples.add(sid)
    for row in repo.samples_by_id(s, live_samples):
        plan.samples.setdefault(row.class_id, []).append(row)
    for job in claimed:  # a class without a description is learnt from its samples alone
        cls = by_id.get(job.class_id)
        if (
            job.kind == JobKind.REGISTER_CLASS
            and job.id not in plan.rejected
            and cls is not None
            and not describes(plan.vocabulary, cls.attribute_key)
            and not plan.samples.get(cls.id)
        ):
            plan.rejected[job.id] = (
                f"class '{cls.name}' has no description and no live sample to learn it from"
            )
            live_classes.discard(cls.id)

    reg = model.registry
    # sets: a class is looked up in them once per stored class (10,000s)
    known_names, all_names = set(reg.known_names), set(reg.all_names)
    in_base = set(base.sample_ids)
    in_model = []
    full = False  # the model must be fitted again
    grows = False  # ... or its known part grown, when nothing else needs the refit
    for cls in classes:
        if cls.origin == Origin.ENROLLED and cls.id not in live_classes:
            continue  # failed, or queued for a later round
        in_model.append(cls)
        rows = plan.samples.get(cls.id, [])
        missing = [r for r in rows if r.id not in in_base]
        if cls.kind == ClassKind.KNOWN and (
            cls.origin == Origin.DATASET or len(rows) >= keep_known
        ):
            # a promoted class the base lacks as known, or with samples it has not seen
            if cls.name not in known_names:
                plan.grow[cls.name], plan.grow_keys[cls.name] = rows, cls.attribute_key
            elif missing:
                plan.grow[cls.name] = missing
        elif cls.kind == ClassKind.KNOWN:  # withdrawals took it below what keeps it known
            plan.demote.append(cls)
            plan.novel.append(cls)
            full = True
        elif len(rows) >= threshold:
            plan.promote.append(cls)
            plan.grow[cls.name], plan.grow_keys[cls.name] = rows, cls.attribute_key
        else:
            plan.novel.append(cls)
            if cls.name not in all_names:
                plan.new_classes.append(cls)
            if missing:
                plan.new_samples[cls.name] = missing
    same_vocabulary = plan.vocabulary.active == tuple(reg.attribute_names)
    known_part, novel_part, known_values = _holds_withdrawn(
        s, reg, in_base - live_samples, in_model, plan.vocabulary if same_vocabulary else None
    )
    known_part |= bool(plan.demote)
    attributes = known_values or not same_vocabulary  # what the attribute parts learnt changed
    stale = known_part or novel_part or attributes  # the base holds what the store changed
    if plan.grow:
        grows = _may_grow(model, plan.grow, grow_fraction) and not (known_part or attributes)
        full |= not grows
    if (
        full
        or plan.choose_method
        or known_part
        or (novel_part and not model.novel_part_separable)
        or (attributes and not model.attributes_separable)
    ):
        plan.rebuild = Rebuild.FULL
    elif grows:
        plan.rebuild = Rebuild.KNOWN_GROWN
    elif attributes:
        plan.rebuild = Rebuild.ATTRIBUTES
    elif novel_part:
        plan.rebuild = Rebuild.NOVEL_PART
    elif plan.new_classes or plan.new_samples:
        plan.rebuild = Rebuild.INCREMENTAL
    # Changed attributes make the base hold a class as it no longer is, as a withdrawal
    # does; asked for by PATCH, that is an update.
    if plan.choose_method and not (plan.promote or full or grows or stale):
        plan.reason = VersionReason.METHOD_CHOICE
    elif plan.promote or ((full or grows) and not stale):
        plan.reason = VersionReason.PROMOTION
    elif stale and not redescribed and not attributes:
        plan.reason = VersionReason.WITHDRAWAL
    return plan


def _may_grow(model: TactileRecognizer, grow: dict[str, list[Sample]], fraction: float) -> bool:
    """Whether the base model may learn ``grow``'s samples into its known part (see
    ``make_plan``'s ``grow_fraction``)."""
    if not model.learns_known_incrementally or fraction <= 0:
        return False
    fitted = int(model.metrics.get("n_train_samples", 0))
    grown = int(model.metrics.get("n_grown_samples", 0))
    return grown + sum(len(rows) for rows in grow.values()) <= fraction * fitted


def make_first_plan(s: Session, claimed: list[Job]) -> Plan:
    """The first model of a service started without a dataset: every class with
    ``FIRST_MODEL_SAMPLES`` live samples is a known class (promoted), the other classes
    with a sample or a description are its novel classes; a class with neither cannot be
    in it, and its jobs fail."""
    plan = Plan(vocabulary=repo.vocabulary(s), rebuild=Rebuild.FULL, reason=VersionReason.BOOTSTRAP)
    live = _live_registrations(s, {j.id for j in claimed})
    classes = [c for c in repo.class_states(s) if c.id in live]
    for row in repo.samples_of(s, [c.id for c in classes]):
        plan.samples.setdefault(row.class_id, []).append(row)
    for cls in classes:
        n = len(plan.samples.get(cls.id, []))
        if n >= FIRST_MODEL_SAMPLES:
            plan.promote.append(cls)
        elif n or describes(plan.vocabulary, cls.attribute_key):
            plan.novel.append(cls)
    placed = {c.id for c in plan.promote + plan.novel}
    plan.choose_method = any(j.kind == JobKind.CHOOSE_METHOD for j in claimed)
    for job in claimed:
        if job.class_id is not None and job.class_id not in placed:
            plan.rejected[job.id] = f"class {job.class_id} has no live sample and no description"
    return plan


def _live_registrations(s: Session, claimed_ids: set[int]) -> set[int]:
    """Classes whose latest registration succeeded or is being done now. Only the latest
    counts: a withdrawn class registered again must wait for its new registration."""
    return {
        cid
        for job_id, cid, status in repo.latest_registrations(s)
        if status == JobStatus.SUCCEEDED or job_id in claimed_ids
    }


def _holds_withdrawn(
    s: Session,
    reg: ClassRegistry,
    stale_samples: set[int],
    in_model: list[ClassState],
    vocabulary: Vocabulary | None,
) -> tuple[bool, bool, bool]:
    """Whether the base model's known part, and its novel part, hold a withdrawn sample or
    class, or a class as it was before it was withdrawn and registered again: known where
    the store now has it novel (promotion only ever goes the other way), or, for a novel
    class, other attributes; and whether a known class's attributes changed. Descriptions
    are compared only where the base has the store's ``vocabulary`` (None: it has not, and
    every description is learnt anew)."""
    live = {c.name: c for c in in_model}
    known, novel = set(reg.known_names), set(reg.novel_names)
    stale_classes = repo.class_names_of_samples(s, stale_samples)
    stale_classes |= set(reg.all_names) - set(live)
    known_values = False
    if vocabulary is not None and vocabulary.active:
        for names, vectors in (
            (reg.known_names, reg.known_attributes),
            (reg.novel_names, reg.novel_attributes),
        ):
            # one float32 copy of the matrix: a conversion per row cost 40 ms a round at
            # 10,000 classes
            rows = np.ascontiguousarray(vectors, np.float32)
            for name, row in zip(names, rows, strict=True):
                if name not in live:
                    continue
                if _key_of(vocabulary, row.tobytes()) != live[name].attribute_key:
                    if name in known:
                        known_values = True
                    else:
                        stale_classes.add(name)
    stale_classes |= {name for name in known if name in live and live[name].kind == ClassKind.NOVEL}
    unplaced = stale_classes - known - novel  # cannot happen; if it does, retrain it all
    return bool(stale_classes & known or unplaced), bool(stale_classes & novel), known_values


@functools.lru_cache(maxsize=1 << 17)
def _key_of(vocabulary: Vocabulary, vector: bytes) -> str:
    """``vocabulary.key_of_vector`` of a float32 vector's bytes, remembered: every plan
    compares each class of the base model with the store (~70 µs a class, 0.7 s a job at
    10,000 objects), and from one job to the next the vectors are the same."""
    return vocabulary.key_of_vector(np.frombuffer(vector, np.float32).tolist())


def build(
    plan: Plan,
    model: TactileRecognizer | None,
    settings: Settings,
    known: TactileDataset | None = None,
) -> TactileRecognizer:
    """The new recognizer; the base model is never modified. A full retrain fits a
    fresh model on ``known`` (from ``known_dataset``) first; an attribute rebuild refits the
    base's attribute parts on ``known``; a novel-part rebuild starts from the base's known
    part alone. The first model of a service started empty has no base (``model`` None)."""
    vocabulary = plan.vocabulary
    if plan.rebuild in (
        Rebuild.FULL,
        Rebuild.ATTRIBUTES,
        Rebuild.NOVEL_PART,
        Rebuild.KNOWN_GROWN,
    ):
        if plan.rebuild is Rebuild.FULL:
            # off the serving path: a child process under memory and time limits
            # (worker/refit.py)
            limit = settings.refit_memory_limit_mb * 2**20 or default_memory_limit()
            method = plan.method or settings.method
            model = fit_in_child(
                method, settings.params_for(method), known, limit, settings.refit_seconds
            )
        elif plan.rebuild is Rebuild.ATTRIBUTES:  # refits parts on every sample: as a full one
            limit = settings.refit_memory_limit_mb * 2**20 or default_memory_limit()
            model = attributes_in_child(model, known, limit, settings.refit_seconds)
        elif plan.rebuild is Rebuild.KNOWN_GROWN:
            model = _grown(plan, model.without_novel_classes())
        else:
            model = model.without_novel_classes()
        new_classes = plan.novel
        new_samples = {c.name: plan.samples[c.id] for c in plan.novel if plan.samples.get(c.id)}
    else:
        new_classes, new_samples = plan.new_classes, dict(plan.new_samples)
    described = [
        c for c in new_classes if model.has_attributes and describes(vocabulary, c.attribute_key)
    ]
    if described:
        model = model.add_novel_classes(
            [c.name for c in described],
            np.stack([vocabulary.vector(c.attribute_key) for c in described]),
        )
    # classes registered without a description (a model without attributes) are learnt
    # from their samples; one whose samples are not in this round waits for them
    learnt = {
        c.name: _samples(model, new_samples.pop(c.name))
        for c in new_classes
        if c not in described and c.name in new_samples
    }
    if learnt:
        model = model.add_novel_classes_from_samples(learnt)
    for name, rows in new_samples.items():
        model = model.add_one_shot(name, _samples(model, rows))
    return model


def _grown(plan: Plan, model: TactileRecognizer) -> TactileRecognizer:
    """``model`` with the plan's promoted classes and known classes' new samples learnt into
    its known part (``with_known_samples``); a class new to it keeps its description. One
    learnt from its samples alone has none: no vector is given, and the method takes it as
    not known (an all-NaN vector would be refused as describing nothing)."""
    return model.with_known_samples(
        {name: _samples(model, rows) for name, rows in plan.grow.items()},
        {
            name: plan.vocabulary.vector(key)
            for name, key in plan.grow_keys.items()
            if describes(plan.vocabulary, key)
        },
    )


def known_dataset(
    s: Session, plan: Plan, procedures: tuple[str, ...] = ()
) -> TactileDataset | BioTacDataset:
    """Every known class (promoted ones included) with its stored samples, for a full retrain;
    the samples hold ``procedures`` (the served model's), which the new model keeps."""
    promoted, demoted = {c.id for c in plan.promote}, {c.id for c in plan.demote}
    live = set(plan.sample_ids)
    known = [
        c
        for c in repo.class_states(s)
        if (c.kind == ClassKind.KNOWN and c.id not in demoted) or c.id in promoted
    ]
    index = {c.id: i for i, c in enumerate(known)}
    rows = [
        r for r in repo.samples_of(s, list(index)) if r.origin == Origin.DATASET or r.id in live
    ]
    labels = np.array([index[r.class_id] for r in rows])
    trials = np.array(
        [r.trial if r.trial is not None else ENROLLED_TRIAL_OFFSET + r.id for r in rows]
    )
    vocabulary = plan.vocabulary
    attributes = np.stack([vocabulary.vector(c.attribute_key) for c in known])
    names = [c.name for c in known]
    if rows and rows[0].form == SampleForm.RAW_TRIAL:  # the model fits its featurizer anew
        return BioTacDataset(
            trials=[repo.decode_trial(r.data) for r in rows],
            labels=labels,
            trial_ids=trials,
            class_names=names,
            attribute_names=vocabulary.active,
            attribute_values=attributes,
            name="store",
        )
    return TactileDataset(
        samples=_stack(rows),
        labels=labels,
        trials=trials,
        class_attributes=attributes,
        attribute_names=vocabulary.active,
        class_names=names,
        object_ids=[c.id for c in known],
        name="store",
        procedures=procedures,
    )


def _samples(model: TactileRecognizer, rows: list[Sample]) -> np.ndarray:
    """What the model learns from these stored samples: the arrays, or the images its
    featurizer makes of raw trials (one per finger)."""
    if model.input_kind == RAW_TRIALS:
        return model.trial_samples([repo.decode_trial(r.data) for r in rows])[0]
    return _stack(rows)


def _stack(rows: list[Sample]) -> np.ndarray:
    return np.stack([repo.decode_sample(r.data, r.shape) for r in rows])
