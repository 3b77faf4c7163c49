"""What a retrain folds in (the plan) and how it builds the new recognizer.

The rule is "bring the active model up to date with the store": every class and
sample whose enrollment succeeded earlier or is claimed now belongs in the new
model; failed enrollments and ones still queued for the next round do not.
Usually that is an incremental update (new FC_Z, one-shot samples); when a novel
class has gathered ``promotion_threshold`` real samples it becomes a known class
and the whole model is retrained from the stored samples.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from sqlalchemy import or_, select
from sqlalchemy.orm import Session

from app.config import Settings
from app.data.dataset import TactileDataset
from app.framework.recognizer import TactileRecognizer
from app.framework.registry import make_method
from app.store import repo
from app.store.models import Job, ModelVersion, ObjectClass, Sample

# enrolled samples get trial ids far above any dataset's, one trial per sample
ENROLLED_TRIAL_OFFSET = 1_000_000_000


@dataclass
class Plan:
    new_classes: list[ObjectClass] = field(default_factory=list)
    new_samples: dict[str, list[Sample]] = field(default_factory=dict)  # by novel class name
    full_retrain: bool = False
    promote: list[ObjectClass] = field(default_factory=list)
    novel: list[ObjectClass] = field(default_factory=list)  # every novel class of the new model
    samples: dict[int, list[Sample]] = field(default_factory=dict)  # its enrolled samples by class
    rejected: dict[int, str] = field(default_factory=dict)  # job id -> why it cannot succeed

    @property
    def changes_model(self) -> bool:
        return bool(self.new_classes or self.new_samples or self.full_retrain)

    @property
    def sample_ids(self) -> list[int]:
        """Enrolled samples the new model contains."""
        return sorted(r.id for rows in self.samples.values() for r in rows)


def make_plan(
    s: Session, base: ModelVersion, model: TactileRecognizer, claimed: list[Job], threshold: int
) -> Plan:
    plan = Plan()
    claimed_ids = {j.id for j in claimed}
    live = s.execute(
        select(Job.id, Job.kind, Job.class_id, Job.sample_id)
        .where(or_(Job.status == "succeeded", Job.id.in_(claimed_ids)))
    ).all()
    live_classes = {cid for _, kind, cid, _ in live if kind == "register_class"}
    classes = repo.list_classes(s)
    by_id = {c.id: c for c in classes}
    live_samples = set()
    for job_id, kind, cid, sid in live:
        if kind != "add_sample":
            continue
        if by_id[cid].origin == "enrolled" and cid not in live_classes:
            if job_id in claimed_ids:
                plan.rejected[job_id] = (
                    f"class '{by_id[cid].name}' is not enrolled: its registration failed"
                )
            continue
        live_samples.add(sid)
    if live_samples:
        rows = s.scalars(select(Sample).where(Sample.id.in_(live_samples)).order_by(Sample.id))
        for row in rows:
            plan.samples.setdefault(row.class_id, []).append(row)

    reg = model.registry
    in_base = set(base.sample_ids)
    for cls in classes:
        if cls.origin == "enrolled" and cls.id not in live_classes:
            continue  # failed, or queued for a later round
        rows = plan.samples.get(cls.id, [])
        missing = [r for r in rows if r.id not in in_base]
        if cls.kind == "known":
            # a promoted class the base lacks as known, or with samples it has not seen
            plan.full_retrain |= cls.name not in reg.known_names or bool(missing)
        elif len(rows) >= threshold:
            plan.promote.append(cls)
            plan.full_retrain = True
        else:
            plan.novel.append(cls)
            if cls.name not in reg.all_names:
                plan.new_classes.append(cls)
            if missing:
                plan.new_samples[cls.name] = missing
    return plan


def build(
    plan: Plan, model: TactileRecognizer, settings: Settings, known: TactileDataset | None = None
) -> TactileRecognizer:
    """The new recognizer; the base model is never modified. A full retrain fits a
    fresh model on ``known`` (from ``known_dataset``) first."""
    if plan.full_retrain:
        model = make_method(settings.method, **settings.method_params).fit(known)
        new_classes = plan.novel
        new_samples = {c.name: plan.samples[c.id] for c in plan.novel if plan.samples.get(c.id)}
    else:
        new_classes, new_samples = plan.new_classes, plan.new_samples
    if new_classes:
        model = model.add_novel_classes(
            [c.name for c in new_classes],
            np.stack([repo.key_vector(c.attribute_key) for c in new_classes]),
        )
    for name, rows in new_samples.items():
        model = model.add_one_shot(name, _stack(rows))
    return model


def known_dataset(s: Session, plan: Plan) -> TactileDataset:
    """Every known class (promoted ones included) with its stored samples, for a full retrain."""
    promoted = {c.id for c in plan.promote}
    live = set(plan.sample_ids)
    known = [c for c in repo.list_classes(s) if c.kind == "known" or c.id in promoted]
    index = {c.id: i for i, c in enumerate(known)}
    rows = [r for r in repo.samples_of(s, list(index)) if r.origin == "dataset" or r.id in live]
    return TactileDataset(
        samples=_stack(rows),
        labels=np.array([index[r.class_id] for r in rows]),
        trials=np.array(
            [r.trial if r.trial is not None else ENROLLED_TRIAL_OFFSET + r.id for r in rows]
        ),
        class_attributes=np.stack([repo.key_vector(c.attribute_key) for c in known]),
        attribute_names=repo.attribute_names(s),
        class_names=[c.name for c in known],
        object_ids=[c.id for c in known],
        name="store",
    )


def _stack(rows: list[Sample]) -> np.ndarray:
    return np.stack([repo.decode_sample(r.data, r.shape) for r in rows])
