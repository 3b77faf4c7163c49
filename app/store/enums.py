"""The values the store's string columns hold, one ``StrEnum`` per column.

Members are ``str``: they compare equal to the stored strings, are written as them by
every driver and serialise as them in JSON, so stored data and API answers are the same
whether code passes a member or its string. Rows read back hold plain strings.
"""

from __future__ import annotations

from enum import StrEnum


class JobKind(StrEnum):
    """``jobs.kind``: what the worker is asked to fold into the model."""

    REGISTER_CLASS = "register_class"
    ADD_SAMPLE = "add_sample"
    UPDATE_CLASS = "update_class"  # a class described anew (its attributes changed)
    WITHDRAW_CLASS = "withdraw_class"
    WITHDRAW_SAMPLE = "withdraw_sample"
    ADD_ATTRIBUTE = "add_attribute"  # an attribute added to the vocabulary, with values
    RETIRE_ATTRIBUTE = "retire_attribute"  # an attribute taken out of later models
    CHOOSE_METHOD = "choose_method"  # method auto chooses again at a full refit


class JobStatus(StrEnum):
    """``jobs.status``: queued, claimed by a worker (running), then finished either way."""

    QUEUED = "queued"
    RUNNING = "running"
    SUCCEEDED = "succeeded"
    FAILED = "failed"


class Origin(StrEnum):
    """``classes.origin`` and ``samples.origin``: from the training dataset the base model
    was fitted on, or enrolled through the API."""

    DATASET = "dataset"
    ENROLLED = "enrolled"


class ClassKind(StrEnum):
    """``classes.kind``: in the model's known part (trained on real samples) or its novel
    part (described by attributes, with one-shot samples)."""

    KNOWN = "known"
    NOVEL = "novel"


class VersionReason(StrEnum):
    """``model_versions.reason``: why the version was built."""

    BOOTSTRAP = "bootstrap"  # the base model, trained on the dataset at first start
    UPDATE = "update"  # classes or samples added, or a class described anew
    PROMOTION = "promotion"  # fitted again on the stored samples: a class became known
    WITHDRAWAL = "withdrawal"  # something withdrawn left the model
    METHOD_CHOICE = "method choice"  # method auto chose again, as an operator asked


class SampleForm(StrEnum):
    """``samples.form``: how ``samples.data`` holds the sample."""

    ARRAY = "array"  # float32 bytes in C order, of ``samples.shape``
    RAW_TRIAL = "raw_trial"  # a raw BioTac trial as sent, as .npz (``encoding.encode_trial``)
