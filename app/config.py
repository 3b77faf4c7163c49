"""Service settings: one class, read from ``TACTILE_*`` environment variables."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import Field, field_validator, model_validator
from pydantic_settings import BaseSettings, NoDecode, SettingsConfigDict

from app.framework.defaults import DEFAULT_KNOWN_KEPT, DEFAULT_METHOD

# each API process holds its own interpreter, torch and model (~0.5 GB resident)
MAX_DEFAULT_PROCESSES = 4


class Settings(BaseSettings):
    """Every setting is documented in the README; defaults give the embedded service."""

    model_config = SettingsConfigDict(env_prefix="TACTILE_", extra="ignore")

    data_dir: Path = Field(Path("./tactile-data"), description="Folder for the SQLite database.")
    database_url: str = Field(
        "", description="Any SQLAlchemy URL; empty means sqlite:///<data_dir>/tactile.db."
    )
    host: str = "127.0.0.1"
    port: int = Field(8000, ge=0, le=65535)
    processes: int | None = Field(
        None,
        ge=1,
        description="API processes `serve` runs on its port, each with its own "
        "interpreter so that recognition uses every core; default one per available CPU core, "
        f"at most {MAX_DEFAULT_PROCESSES}.",
    )
    access_log: bool = Field(
        False,
        description="Log every request (uvicorn's access log); off by default because at "
        "robot request rates it costs about a tenth of the API's CPU. /metrics counts requests.",
    )
    opentelemetry: bool = Field(
        False,
        description="FastAPI's native OpenTelemetry traces, metrics and logs, sent to the "
        "providers an OpenTelemetry SDK configures; off by default: /metrics serves Prometheus, "
        "and even unconfigured the per-request check costs several microseconds.",
    )
    # NoDecode: a plain comma-separated list in the environment, not JSON.
    api_keys: Annotated[list[str], NoDecode] = Field(
        default_factory=list,
        description="Admin keys accepted in X-API-Key besides those made by 'apikey create'.",
    )
    api_key_refresh_seconds: float = Field(
        1.0, gt=0, description="How often an API process re-reads the stored API keys."
    )
    rate_limit: float = Field(
        1000.0,
        ge=0,
        description="Requests per second per API key (per client address when "
        "no keys exist) in each API process; 0 = no limit.",
    )
    rate_burst: int = Field(
        2000, ge=1, description="Requests a key may send at once before the rate limit applies."
    )
    db_timeout_seconds: float = Field(
        30.0, gt=0, description="Longest any database statement (or wait for a lock) may take."
    )
    cors_origins: Annotated[list[str], NoDecode] = Field(
        default_factory=list, description="Origins allowed by CORS (comma-separated); empty = none."
    )
    idempotency_ttl_hours: float = Field(
        24.0, gt=0, description="How long an Idempotency-Key is remembered."
    )
    top_k: int = Field(3, ge=1, description="Scores returned per recognised sample.")
    batch_limit: int = Field(1024, ge=1, description="Most samples in one recognize request.")
    known_kept: float | None = Field(
        DEFAULT_KNOWN_KEPT,
        gt=0,
        lt=1,
        description="The novelty operating point of every answer, whatever the method: the "
        "threshold that kept this share of held-out known touches known when the model was "
        "fitted (read off its calibration curve); a request's own `known_kept` overrides it. "
        "A model without a calibration curve answers at its own threshold (`operating_point` "
        "`model_default` in each answer). Every answer states the threshold it used.",
    )
    outliers: Literal["abstain", "answer"] = Field(
        "abstain",
        description="What an answer to an input outlier (a sensor reading zeros, saturated or "
        "with a dead channel: `input_outlier` true) is: `abstain` names no object (`kind` "
        "`input_outlier`, `class_name` null); `answer` gives the model's guess, flagged. A "
        "request's own `outliers` overrides it.",
    )
    input_window: int = Field(
        256,
        ge=1,
        description="Recent samples each API process keeps for /metrics' input health: the "
        "outlier rate and each channel's drift against the training data "
        "(docs/DEPLOY.md, monitoring).",
    )
    max_body_bytes: int = Field(
        64 * 1024 * 1024, ge=1024, description="Largest request body accepted (413 beyond)."
    )
    promotion_threshold: int = Field(
        10, ge=1, description="Real samples after which a novel class becomes a known class."
    )
    grow_fraction: float = Field(
        0.25,
        ge=0,
        description="A promotion (a novel class reaching promotion_threshold samples, or a "
        "known class's new samples) is learnt into the known part without a full refit, by "
        "methods that can (best), while the samples so learnt since the last full refit stay "
        "within this share of that refit's samples; beyond it, or at 0, the whole model is "
        "fitted again.",
    )
    rechoose_growth: float = Field(
        2.0,
        ge=1.0,
        description="With method auto, a full refit keeps the method chosen before until the "
        "known classes number this many times those it was chosen at; then it chooses again. "
        "An operator asks for a new choice at any time (POST /v1/models/choice, or "
        "'tactile-zsl model choose').",
    )
    refit_memory_limit_mb: int = Field(
        0,
        ge=0,
        description="Memory a full refit (a promotion, a withdrawal from the known part) may "
        "take: it runs in a child process of its own whose data segment the kernel caps at "
        "this many MiB (its jobs fail with that reason; the active model stays). 0: half of "
        "the container's cgroup memory limit, else of the machine's memory.",
    )
    refit_seconds: float = Field(
        4 * 3600,
        ge=0,
        description="Wall-clock seconds a refit (a full one, or an attribute rebuild) may "
        "run in its child process: past them the child is killed with any process it "
        "started, its jobs fail with that reason and the active model stays. 0: no limit.",
    )
    keep_versions: int = Field(
        100,
        ge=0,
        description="Model versions kept for listing and rollback: the newest ones, plus the "
        "active and the bootstrap version; the worker deletes older ones and the bundle data "
        "only they use. 0 keeps every version.",
    )
    dataset: str = Field(
        "simulated",
        description="Bootstrap data: simulated, simulated:N, phac2:PATH, folder:DIR, biotac:DIR, "
        "or none (start without classes or attributes; the first model is trained once "
        "classes have samples).",
    )
    base_model: Path | None = Field(
        None,
        description="A model bundle trained on the bootstrap dataset ('tactile-zsl train "
        "--dataset D --out FILE'): on first start it becomes model version 1 instead of a "
        "fit, which at tens of thousands of objects takes many minutes. Its known classes, "
        "attributes and input shape must be the dataset's.",
    )
    method: str = Field(DEFAULT_METHOD, description="Recognition method used for training.")
    method_params: dict[str, dict[str, Any]] = Field(
        default_factory=dict,
        description="JSON keyword arguments by method name, e.g. "
        '{"best": {"n_estimators": 200}, "auto": {"probe_classes": 50}}: each method gets '
        "its own wherever it is fitted (with method auto, its candidates get theirs). "
        "Unknown methods or parameters stop the service at start.",
    )
    torch_threads: int = Field(
        1, ge=1, description="Torch intra-op threads; the networks are tiny, more mostly contend."
    )
    embedded_worker: bool = Field(True, description="Run the retraining worker inside serve.")
    warm_words: bool = Field(
        True,
        description="Load the sentence-embedding model that reads descriptions in words in the "
        "background once an API process is ready (about 4 s and 0.5 GB each), so the first "
        "description is answered as fast as the next; only where the vocabulary has "
        "attributes to read. Off for a service never sent descriptions.",
    )
    model_poll_seconds: float = Field(
        0.5, gt=0, description="How often an API process checks for a new active model."
    )
    model_wait_seconds: float = Field(
        30.0,
        ge=0,
        description="Longest a request waits for its API process to load a newer model "
        "version (a recognition's min_model_version; a finished job's answer does not wait "
        "for it): past it the "
        "answer is 503 with Retry-After, and the load goes on. Every request waiting meanwhile "
        "shares one load and holds no request thread.",
    )
    worker_poll_seconds: float = Field(0.2, gt=0, description="How often a worker looks for jobs.")
    worker_nice: int = Field(
        5,
        ge=0,
        le=19,
        description="Scheduling niceness of the retraining worker, so retrains "
        "yield the CPU to recognition on a shared machine; 0 = same priority.",
    )
    lease_seconds: float = Field(
        30.0,
        gt=0,
        description="A worker or bootstrap lock not renewed for this long is taken over.",
    )

    @field_validator("api_keys", "cors_origins", mode="before")
    @classmethod
    def _split_keys(cls, value: Any) -> Any:
        if isinstance(value, str):
            return [k.strip() for k in value.split(",") if k.strip()]
        return value

    @field_validator("keep_versions")
    @classmethod
    def _enough_versions(cls, value: int) -> int:
        # with one, the version an API process is still loading could be deleted under it
        if value == 1:
            raise ValueError("keep at least 2 versions, or 0 to keep every version")
        return value

    @field_validator("method_params", mode="before")
    @classmethod
    def _parse_params(cls, value: Any) -> Any:
        if isinstance(value, str):
            value = json.loads(value) if value.strip() else {}
        from app.framework.params_by_method import check_params_by_method

        return check_params_by_method(value)

    @model_validator(mode="after")
    def _params_for_methods_fitted(self) -> Settings:
        from app.framework.params_by_method import check_placed

        check_placed(self.method, self.method_params)
        return self

    def params_for(self, method: str | None = None) -> dict[str, Any]:
        """The keyword arguments that make ``method`` (default: ``method``) from
        ``method_params``: its own, and for ``auto`` its candidates' as ``params``."""
        from app.framework.params_by_method import params_for

        return params_for(method or self.method, self.method_params)

    @property
    def api_processes(self) -> int:
        """``processes``, or its default for this machine."""
        if self.processes is not None:
            return self.processes
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
        return max(1, min(cores or 1, MAX_DEFAULT_PROCESSES))

    @property
    def sqlalchemy_url(self) -> str:
        if self.database_url:
            return self.database_url
        return f"sqlite:///{(self.data_dir / 'tactile.db').resolve()}"
