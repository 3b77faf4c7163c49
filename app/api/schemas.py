"""Request and response bodies (pydantic): the OpenAPI schema is generated from these."""

from __future__ import annotations

from datetime import datetime
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    BeforeValidator,
    ConfigDict,
    Field,
    StringConstraints,
    computed_field,
    field_validator,
    model_validator,
)

from app.api.sample_input import missing_as_null
from app.data.procedures import block
from app.store.enums import ClassKind, JobKind, JobStatus, Origin, VersionReason
from app.words.interpret import MAX_TEXT

# One tactile sample: a [C, T] tactile image or a flat [D] feature vector.
SampleData = list[list[float]] | list[float]
# A sample to recognise or describe: a row may be null, a procedure not done yet, and the
# sample may come as one entry per procedure (app/api/sample_input.py). A row of null or
# NaN cells is a null row (what orjson and JSON.stringify write for NaN).
ProbeData = Annotated[
    list[list[float] | None] | list[float] | list[list[list[float]] | None],
    BeforeValidator(missing_as_null),
]

# no control characters: PostgreSQL text cannot hold NUL, and no one names an object with a tab
ClassName = Annotated[
    str,
    StringConstraints(
        strip_whitespace=True, min_length=1, max_length=200, pattern=r"^[^\x00-\x1f\x7f]+$"
    ),
]
# a table's object label (docs/TABLES.md): the route checks them by hand, naming the fix
ObjectLabel = Annotated[str, StringConstraints(min_length=1, max_length=200)] | int
# an attribute's value for a class: 1 has it, 0 has it not, graded in between ("somewhat
# soft": 0.5); kept to 4 decimals
AttributeValue = Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)]
AttributeName = Annotated[
    str,
    StringConstraints(
        strip_whitespace=True, min_length=1, max_length=100, pattern=r"^[^\x00-\x1f\x7f,]+$"
    ),
]


class Strict(BaseModel):
    """Request bodies reject unknown fields, so a misspelt field is named, not ignored."""

    model_config = ConfigDict(extra="forbid")


# ------------------------------------------------------------------ attributes
class AttributeOut(BaseModel):
    model_config = ConfigDict(from_attributes=True)

    name: str
    origin: Origin = Field(
        description="`dataset`: the bootstrap dataset's (its values for the dataset's classes "
        "stay fixed); `enrolled`: added through `POST /v1/attributes`."
    )
    created_at: datetime | None
    retired_at: datetime | None = Field(
        description="When it was retired (`DELETE /v1/attributes/{name}`): later models leave "
        "it out; null while it is in use."
    )


class AttributeList(BaseModel):
    attributes: list[str] = Field(
        description="The vocabulary now in use, in attribute-vector order (`attribute_vector` "
        "and `POST /v1/describe` use it); an attribute added later comes after the others."
    )
    vocabulary: list[AttributeOut] = Field(
        description="Every attribute, retired ones included (names are never reused)."
    )


class AttributeCreate(Strict):
    """A new attribute, and its value for the classes an operator knows it for."""

    name: AttributeName = Field(examples=["sticky"])
    values: dict[str, AttributeValue] = Field(
        default_factory=dict,
        description="Class name -> value in [0, 1]. Classes given no value are not known for "
        "the attribute: they are left out of its training, never counted as 0.",
        examples=[{"tape": 1, "sponge": 0, "rubber band": 0.5}],
    )


class AttributeChanged(BaseModel):
    attribute: AttributeOut
    job: JobOut = Field(
        description="Poll it: the attribute is in the served model when it succeeds."
    )


class TextIn(Strict):
    """A description of an object in a person's own words."""

    text: str = Field(
        description='What the object feels like, in words: graded ("slightly rough", '
        '"very hard"), negated ("not hard"), synonyms and paraphrases ("spongy", '
        '"slick", "soaks up water"), or just a name ("steel vase"). At most '
        f"{MAX_TEXT} characters.",
        examples=["a soft, spongy foam block that soaks up water"],
    )


class ReadingOut(BaseModel):
    """One attribute value read from a text, and the words that gave it."""

    attribute: str
    value: float = Field(description="In [0, 1]: 1 has it, 0 has not, between: somewhat.")
    words: str = Field(description="The part of the text that gave the value.")
    source: str = Field(
        description="`word`: a word about the feel; `implied`: what a word says of its "
        'opposite ("soft": not hard); `material`: what such material usually is '
        '("steel": cool); `embedding`: a word the lexicon lacks, matched by the sentence-'
        "embedding model; `estimated`: an attribute the text does not mention, estimated "
        "from what it does say and which attributes go together in the live classes "
        "(`words` names the attributes read it follows from). A value given beside the "
        "text overrides an estimate, never a value read."
    )


class TextRead(BaseModel):
    values: dict[str, float] = Field(
        description="Attribute -> value, for the attributes the text speaks of; the others are "
        "absent (not known), never 0.",
        examples=[{"soft": 0.9, "hard": 0.1, "squishy": 0.9, "absorbent": 0.9}],
    )
    readings: list[ReadingOut]
    not_mentioned: list[str] = Field(description="Attributes in use the text says nothing of.")


# --------------------------------------------------------------------- classes
class ClassDescription(Strict):
    """How an operator describes an object: by attribute names (a list: these it has, every
    other it has not), by values (a mapping of names to values in [0, 1], or null for not
    known; attributes left out are not known, or, in a `PATCH`, keep their value), or by a
    vector in `GET /v1/attributes` order (null: not known), or in words (`description`: the
    values read from it, `POST /v1/attributes/interpret`), alone or beside values it must not
    contradict. At least one value above 0."""

    attributes: list[str] | dict[str, AttributeValue | None] | None = Field(
        None,
        description="Attribute names the object has, or a mapping of names to values in [0, "
        "1] (0.5: somewhat; null: not known).",
        examples=[["hard", "smooth"], {"hard": 1, "smooth": 0.5}],
    )
    attribute_vector: list[AttributeValue | None] | None = Field(
        None,
        description="A value in [0, 1] (or null: not known) per attribute, in "
        "`GET /v1/attributes` order.",
    )
    description: str | None = Field(
        None,
        description="The object in words; the class keeps the text and the values read from "
        f"it. At most {MAX_TEXT} characters. Values given beside it win where the text says "
        "nothing; where both speak of an attribute they must agree (within 0.5).",
        examples=["a soft, spongy foam block that soaks up water", "steel vase"],
    )

    @model_validator(mode="after")
    def _one_description(self) -> ClassDescription:
        if self.attributes is not None and self.attribute_vector is not None:
            raise ValueError("give one of 'attributes' or 'attribute_vector', not both")
        if self.attributes is None and self.attribute_vector is None and self.description is None:
            raise ValueError("give 'attributes', 'attribute_vector' or 'description'")
        return self


class ClassCreate(ClassDescription):
    """A novel class: described by its attributes (zero-shot), learnt from real samples or
    raw trials sent with it, or both."""

    name: ClassName
    samples: list[SampleData] | None = Field(
        None,
        min_length=1,
        description="Real samples of the object: without a description, the class is "
        "recognised from them alone (method `best`).",
    )
    trials: list[TrialIn] | None = Field(
        None,
        min_length=1,
        description="Raw BioTac trials of the object, the same for a model of raw trials.",
    )

    @model_validator(mode="after")
    def _one_description(self) -> ClassCreate:
        described = [f for f in ("attributes", "attribute_vector") if getattr(self, f) is not None]
        shown = [f for f in ("samples", "trials") if getattr(self, f) is not None]
        worded = self.description is not None
        if len(described) > 1 or len(shown) > 1 or not (described or shown or worded):
            raise ValueError(
                "give one of 'attributes' or 'attribute_vector' and/or 'description' (a "
                "description), one of 'samples' or 'trials' (the object's touches), or both"
            )
        return self


class ClassOut(BaseModel):
    id: int
    name: str
    kind: ClassKind
    attributes: list[str] = Field(description="The attributes it has (value 0.5 or more).")
    attribute_values: dict[str, float] = Field(
        default_factory=dict,
        description="Every known value, by attribute name; attributes not known are absent.",
    )
    n_samples: int = Field(description="Real tactile samples stored for the class.")
    description: str | None = Field(None, description="Its description in words, if any.")
    description_readings: list[ReadingOut] | None = Field(
        None,
        description="The values read from `description`, with the words behind each, and "
        "the values estimated for the attributes it does not mention (source `estimated`).",
    )
    created_at: datetime
    in_active_model: bool = Field(description="Whether the model now serving covers the class.")


NEXT_AFTER = Field(None, description="Pass as `after` to get the next page; null on the last page.")


class ClassList(BaseModel):
    classes: list[ClassOut]
    next_after: int | None = NEXT_AFTER


# ------------------------------------------------------------------------ jobs


class JobOut(BaseModel):
    model_config = ConfigDict(from_attributes=True)

    id: int
    kind: JobKind
    status: JobStatus
    class_id: int | None = Field(description="The class it is about; null for an attribute's.")
    sample_id: int | None
    attribute_id: int | None = Field(
        None, description="The attribute it is about (`add_attribute`, `retire_attribute`)."
    )
    model_version: int | None = Field(
        description="The version that includes the enrollment; for a withdrawal, the first "
        "active version without the class or sample."
    )
    created_at: datetime
    started_at: datetime | None
    finished_at: datetime | None
    error: str | None
    requested_by: str | None = Field(
        description="Who queued it: `key:<id>` of an API key (`tactile-zsl apikey list` names "
        "it), `env:<hash prefix>` for a key from the environment, `addr:<ip>` while no keys "
        "exist; null for jobs older than this field."
    )
    warnings: list[str] = Field(
        default_factory=list,
        description="What the request that queued it was warned of, as its 202 said: e.g. a "
        "sample the served model gave to another class with probability 0.9 or more.",
    )

    @field_validator("warnings", mode="before")
    @classmethod
    def _none_is_no_warning(cls, value: Any) -> Any:
        return [] if value is None else value


class JobList(BaseModel):
    jobs: list[JobOut]
    next_after: int | None = NEXT_AFTER


class ClassCreated(BaseModel):
    model_config = ConfigDict(populate_by_name=True)

    class_: ClassOut = Field(alias="class")
    job: JobOut


# --------------------------------------------------------------------- samples
class SampleCreate(Strict):
    """One sample, or one raw trial for a model fitted on raw trials."""

    sample: SampleData | None = Field(
        None,
        description="One sample, of the shape `input_shape` of `GET /v1/models/active` says.",
    )
    trial: TrialIn | None = Field(
        None,
        description="One raw BioTac trial, for a model whose `input_kind` is `raw_trials`; "
        "stored as sent, so a later model can featurize it anew.",
    )

    @model_validator(mode="after")
    def _one_input(self) -> SampleCreate:
        if (self.sample is None) == (self.trial is None):
            raise ValueError("give exactly one of 'sample' or 'trial'")
        return self


class SampleCreated(BaseModel):
    sample_id: int
    job: JobOut
    recognized_as: RecognitionOut = Field(
        description="What the model served when the sample arrived said of it, before learning "
        "from it (as `POST /v1/recognize` answers). Advisory: a sample recognised confidently as "
        "another class may be of the wrong object (withdraw it with `DELETE`)."
    )
    model_version: int = Field(description="The version that gave `recognized_as`.")
    warnings: list[str] = Field(
        default_factory=list,
        description="What may be wrong with the sample, which is kept all the same (the job "
        "keeps these too): the served model gave it to another class with probability 0.9 "
        "or more (where it knows the class; before it does, to a known class it found no "
        "novelty in), so it may be of the wrong object. Withdraw it with `DELETE` if so.",
    )


class SampleOut(BaseModel):
    """A stored sample, without its data."""

    id: int
    origin: Origin
    trial: int | None = Field(description="The dataset's trial id; null for enrolled samples.")
    created_at: datetime
    enrolled_by: str | None = Field(
        description="Who added it (as a job's `requested_by`); null for dataset samples."
    )


class SampleDetail(SampleOut):
    """A stored sample with its data, as it was enrolled or read from the dataset."""

    shape: list[int] = Field(
        description="The sample's shape (the model's input shape); [] for a raw trial."
    )
    sample: list | TrialIn = Field(
        description="The sample's values, nested as its shape; a raw trial as it was enrolled "
        '(`{"fingers": [...]}`, as `POST /v1/recognize` takes trials).'
    )


class SampleList(BaseModel):
    samples: list[SampleOut]
    next_after: int | None = NEXT_AFTER


# ----------------------------------------------------------------- withdrawals
class Withdrawal(BaseModel):
    """A withdrawn class or sample: gone from the store's live data now, and from the
    served model once ``job`` has succeeded."""

    class_id: int
    sample_id: int | None = Field(description="The withdrawn sample; null when the whole class is.")
    job: JobOut


# ------------------------------------------------------------------- recognize
class FingerIn(Strict):
    """One BioTac finger's channels as recorded (T frames), named as in the BioTac ROS
    driver and the recordings' HDF5 files."""

    pdc: list[float] = Field(description="DC pressure, (T,).")
    tdc: list[float] = Field(description="DC temperature, (T,).")
    tac: list[float] = Field(description="AC temperature (heat flow), (T,).")
    pac: list[list[float]] = Field(description="AC pressure (vibration), (T, 22).")
    electrodes: list[list[float]] = Field(description="The 19 electrodes' impedance, (T, 19).")


class TrialIn(Strict):
    """One raw exploration (a trial): each finger's channels, of any length T."""

    fingers: list[FingerIn] = Field(min_length=1, description="One or more fingers.")
    phases: list[tuple[int, int] | None] | None = Field(
        None,
        description="`[start, end)` frames of each exploration phase (tap, hold, squeeze); "
        "found from `pdc` when absent (docs/DATASETS.md). A phase the robot has not done "
        "is `null` (`[[150, 170], null, [600, 660]]`: no hold): the answer comes from the "
        "others and names the `next_procedure`. Enrolment takes whole trials only.",
    )
    timestamps: list[float] | None = Field(None, description="Time of each frame, (T,).")


class RecognizeRequest(Strict):
    samples: list[ProbeData] = Field(
        min_length=1,
        description="1 … batch_limit samples (`TACTILE_BATCH_LIMIT`), each of the "
        "shape `input_shape` of `GET /v1/models/active` says. Where the model names its "
        "`procedures`, a sample may lack some: their rows are `null` (or NaN in a .npy "
        "body), and a sample may come as one entry per procedure, e.g. PHAC-2's "
        "`[[...47 numbers], null, null, null]` after a squeeze alone. `procedure_rows` of "
        "`GET /v1/models/active` says which rows each procedure takes. The example is for "
        'a model of `input_shape` `[4, 3]` whose `procedure_rows` are `{"squeeze": [0, 2], '
        '"hold": [2, 4]}`: one complete sample, and one after a squeeze alone. One sample '
        "may also come alone, without its list (as a `.npy` body of `input_shape` may).",
        examples=[
            [
                [[0.12, 0.4, 0.31], [0.2, 0.1, 0.05], [0.7, 0.66, 0.61], [0.02, 0.03, 0.01]],
                [[0.12, 0.4, 0.31], [0.2, 0.1, 0.05], None, None],
            ]
        ],
    )
    objects: list[ObjectLabel] | None = Field(
        None,
        description="A table of objects (docs/TABLES.md): the physical object each sample "
        "was touched on, one label per sample (a non-empty string or an integer); distinct "
        "labels are distinct objects. The objects are named jointly: no class, known or "
        "novel, goes to two of them; novel, not any registered class, may repeat. One "
        "result per object, in order of first appearance. Not with `same_object`; a `.npy` "
        "body gives them in the query parameter `objects` or the header `X-Tactile-Objects`.",
        examples=[["cup", "box", "cup"], [1, 2, 1]],
    )


class RecognizeTrialsRequest(Strict):
    """Raw trials, for a model fitted on them (`input_kind` `raw_trials`)."""

    trials: list[TrialIn] = Field(
        min_length=1,
        description="1 … batch_limit raw BioTac trials; one answer per trial, from all its "
        "fingers.",
    )
    objects: list[ObjectLabel] | None = Field(
        None,
        description="A table of objects: the object each trial was touched on, one label "
        "per trial (docs/TABLES.md); one answer per object, its trials' fingers together.",
        examples=[["cup", "box", "cup"]],
    )


class ScoreOut(BaseModel):
    class_id: int | None
    class_name: str
    probability: float


class RecognitionOut(BaseModel):
    """One sample's answer. The novelty detector routes it to the known classes or, when
    it is novel and novel classes are registered, to those; the answer is the most
    probable class of that group. An input outlier (`input_outlier` true: a broken
    sensor) is not answered as an object unless the request asks `outliers=answer`: its
    `kind` is `input_outlier`, its class null and its `top_k` empty."""

    class_id: int | None = Field(
        description="The store's id of the answered class; null for an abstention "
        "(`kind` `input_outlier`)."
    )
    class_name: str | None = Field(
        description="The answered class; null for an abstention (`kind` `input_outlier`): "
        "the input is no evidence about any object."
    )
    kind: Literal["known", "novel", "input_outlier"] = Field(
        description="Whether the answered class is known or novel; `input_outlier` where "
        "the input lies outside what the model was trained on (`input_outlier`) and the "
        "answer abstains (the default; `outliers=answer` gives the model's guess instead)."
    )
    is_novel: bool | None = Field(
        description="The novelty detector's verdict: the sample is unlike every known class. "
        "While no novel class is registered, a novel sample is still answered with the closest "
        "known class (`kind` `known`): a cue to register the object. Null for an abstention "
        "(`kind` `input_outlier`): it claims neither a known nor a novel object."
    )
    novelty_score: float = Field(
        description="How unlike the known classes the sample is; above `novelty_threshold` "
        "it is novel. Comparable within one model version only."
    )
    novelty_threshold: float | None = Field(
        description="The novelty threshold this answer was routed by: novel above it. Read "
        "off the model's calibration curve at `known_kept`, or the model's own threshold "
        "(`operating_point` `model_default`).",
        examples=[1.5],
    )
    known_kept: float | None = Field(
        description="The operating point: the share of held-out known touches that "
        "`novelty_threshold` kept known when the model was fitted, as asked for (the "
        "request's `known_kept`, else the service's `TACTILE_KNOWN_KEPT`, 0.90 unless set), "
        "the same for every method. Null where the model holds no calibration curve.",
        examples=[0.9],
    )
    operating_point: Literal["known_kept", "model_default"] | None = Field(
        description="`known_kept`: routed by the threshold keeping `known_kept` of known "
        "touches; `model_default`: by the model's own threshold (a model without a "
        "calibration curve).",
        examples=["known_kept"],
    )
    calibrated_touches: int | None = Field(
        description="The kind of answer the threshold's calibration curve was measured on: "
        "held-out answers fusing this many touches of one known object (trials, for a model "
        "of raw trials). A fused answer (`same_object`, or a trial's fingers) reads the curve "
        "of as many touches where fitting measured one, else the largest measured below "
        "(1: single touches; 0: single images of a raw-trial model, which a model fitted "
        "before 2026-11-28 also reads for trials). Null at the model's own threshold.",
        examples=[1],
    )
    top_k: list[ScoreOut] = Field(
        description="The most probable classes of the group answered from, best first."
    )
    procedures_used: list[str] = Field(
        description="The exploratory procedures the answer came from (those the sample "
        "holds); empty for a model that does not name its procedures."
    )
    next_procedure: str | None = Field(
        description="The procedure whose expected gain per second of robot time is largest "
        "for this answer, to do next and send again with the others; null once two "
        "procedures are done and the answer's probability reaches `target_confidence`, or "
        "every procedure is done."
    )
    input_outlier: bool | None = Field(
        description="The input lies outside what the model was trained on: one of its "
        "channels' level or spread is more than `input_outlier_score`'s threshold, 2.5 "
        "training IQRs, beyond the training data's range of that channel. A sensor that "
        "reads zeros, saturates, is scaled wrongly or has a dead channel; the answer then "
        "abstains (`kind` `input_outlier`, no class) unless the request asks "
        "`outliers=answer`, which gives the model's guess, not to be trusted. Missing "
        "procedures do not count. Null where the model was fitted before input profiles "
        "(not measured); fitting it again measures it. For a trial or `same_object`, true "
        "when any of its samples is.",
        examples=[False],
    )
    input_outlier_score: float | None = Field(
        description="How far the input lies outside the training data, in training "
        "interquartile ranges beyond the range of its farthest channel statistic: 0 within "
        "every channel's training range; above 2.5 the input is an outlier "
        "(`input_outlier`). About 1 % of held-out real samples score above it "
        "(docs/results/input-health/). Null where `input_outlier` is.",
        examples=[0.0],
    )


class AloneOut(BaseModel):
    """What a table's object would have been called alone, from its own touches."""

    class_id: int | None = Field(
        description="The store's id of that class; null for novel, not any registered class."
    )
    class_name: str | None = Field(
        description="That class; null for novel, not any registered class."
    )
    kind: Literal["known", "novel"]


def _absent(value: Any) -> bool:
    return value is None


class RecognizeResult(RecognitionOut):
    """One answer of `POST /v1/recognize`: a sample's, a trial's, or (with `objects`) a
    table object's, which alone carries `object`, `alone`, `margin` and `touches`."""

    object: str | int | None = Field(
        None, exclude_if=_absent, description="A table's object (`objects`): its label, as sent."
    )
    alone: AloneOut | None = Field(
        None,
        exclude_if=_absent,
        description="A table's object: what it would have been called alone, from its "
        "own touches, before the joint naming (`class_name` null: novel, not any "
        "registered class). Where it differs from `class_name`, another object's "
        "evidence for that class was stronger.",
    )
    margin: float | None = Field(
        None,
        exclude_if=_absent,
        description="A table's object: the summed log-score the best joint naming that "
        "calls this object anything else loses against the one answered (0: a tie). "
        "Small: the table's naming of it is a guess; large: confident.",
        examples=[2.3],
    )
    touches: int | None = Field(
        None,
        exclude_if=_absent,
        description="A table's object: how many samples (or raw trials) of the request "
        "were of it; its answer fuses them.",
        examples=[3],
    )


class RecognizeResponse(BaseModel):
    model_version: int
    results: list[RecognizeResult] = Field(
        description="One answer per sample (or raw trial); with `same_object`, one; with "
        "`objects`, one per object, in order of first appearance, named jointly: `class_name` "
        "and `kind` are the joint naming (`class_name` null and `kind` `novel`: novel, not any "
        "registered class), the other fields those of the object's touches fused, as "
        "`same_object` gives them."
    )


class AttributeScore(BaseModel):
    name: str
    probability: float = Field(description="That the attribute describes the touched object.")


class Description(BaseModel):
    """What one touch feels like."""

    attributes: list[AttributeScore] = Field(
        description="Every attribute, the most probable first."
    )
    suggested: list[str] = Field(
        description="The attributes more probable than not (at least the most probable one), "
        "in `GET /v1/attributes` order: a starting point for `POST /v1/classes`, for a person "
        "to check."
    )


class DescribeResponse(BaseModel):
    model_version: int
    results: list[Description]
    object: Description | None = Field(
        None,
        description="With `same_object`: the object described from all its touches together "
        "(their mean probabilities), right more often than any one touch (docs/RESULTS.md).",
    )


# ---------------------------------------------------------------------- models
class ModelClass(BaseModel):
    name: str
    kind: ClassKind


class ModelSummary(BaseModel):
    """A model version without its class list (``GET /v1/models/{version}`` has it)."""

    model_config = ConfigDict(from_attributes=True, protected_namespaces=())

    version: int
    created_at: datetime
    active: bool
    method: str
    reason: VersionReason
    base_version: int | None
    sha256: str = Field(validation_alias="bundle_sha256")
    input_kind: str = Field(
        "samples",
        description="What the version takes: `samples` of `input_shape`, or `raw_trials` (raw "
        "BioTac trials, which its featurizer turns into samples of `input_shape`, one per "
        "finger).",
    )
    input_shape: list[int] = Field(
        description="The shape of one sample to send: `POST /v1/recognize` and `POST /v1/describe` "
        "take a batch of samples of this shape (nested lists), `POST /v1/classes/{id}/samples` one."
    )
    procedures: list[str] | None = Field(
        default_factory=list,
        description="The exploratory procedures a sample holds, in order along its first axis "
        "(e.g. PHAC-2's squeeze, hold, slide, move down); empty where the model does not name "
        "them.",
    )

    @computed_field(
        description="Where each of `procedures` lies in a sample: `[start, stop)` of the rows "
        "of its first axis (of a flat sample, its slice). A procedure not done yet has its "
        "rows `null` (NaN throughout in a `.npy` body): with the rows below, a sample after "
        "squeeze and slide is rows 0-7 and 16-23 of numbers and rows 8-15 and 24-31 `null`, "
        "or one entry per procedure, `[[8 rows], null, [8 rows], null]`. Empty where the "
        "model names no procedures.",
        examples=[{"squeeze": [0, 8], "hold": [8, 16], "slide": [16, 24], "move_down": [24, 32]}],
    )
    @property
    def procedure_rows(self) -> dict[str, list[int]]:
        if not self.procedures or not self.input_shape:
            return {}
        return {
            name: [rows.start, rows.stop]
            for j, name in enumerate(self.procedures)
            for rows in [block(self.procedures, tuple(self.input_shape), j)]
        }

    first_procedure: str | None = Field(
        None,
        description="The procedure to do first when exploring an object; then send the "
        "sample with the procedures done so far (the others null) and do each answer's "
        "`next_procedure` until it is null. Null where the model answers complete samples "
        "only.",
    )
    metrics: dict[str, Any]

    @computed_field(
        description="How method `auto` chose this version's method (`metrics.chosen_by`): "
        "`method`; `reason` (`probe`, or `rule` where the data held no probe); `n_classes` "
        "the known classes it was chosen at and `probe_classes` how many of them the probe "
        "measured; `kept` and `kept_since` where a refit kept the choice of an earlier "
        "version. Null for a fixed method.",
        examples=[
            {
                "method": "prototypes",
                "reason": "probe",
                "n_classes": 3000,
                "probe_classes": 100,
                "kept": True,
                "kept_since": 1,
            }
        ],
    )
    @property
    def method_choice(self) -> dict[str, Any] | None:
        chosen = (self.metrics or {}).get("chosen_by")
        if not isinstance(chosen, dict):
            return None
        keys = ("method", "reason", "n_classes", "probe_classes", "kept", "kept_since")
        return {k: chosen[k] for k in keys if k in chosen}

    class_count: int = Field(description="Classes the version recognises, known and novel.")
    attribute_names: list[str] | None = Field(
        None,
        description="The attribute vocabulary the version was trained with, in its vectors' "
        "order: a rollback answers `POST /v1/describe` with it.",
    )


class ModelOut(ModelSummary):
    classes: list[ModelClass]


class ModelList(BaseModel):
    models: list[ModelSummary]
    next_after: int | None = NEXT_AFTER


# ---------------------------------------------------------------------- health
class Health(BaseModel):
    status: Literal["ok", "ready"]
    model_version: int | None = Field(
        None, description="The model version this process serves; null until one is loaded."
    )


AttributeChanged.model_rebuild()
SampleCreate.model_rebuild()
SampleDetail.model_rebuild()
ClassCreate.model_rebuild()
