"""A robot's client of the service: recognition that goes on when the network does not,
and enrolments that a retry never doubles.

    client = TactileClient("http://fleet-server:8000", api_key=KEY,
                           model_file="/var/lib/robot/tactile.bundle")
    client.sync_model()                      # downloads the active version only when it changed
    answer = client.recognize(touches)       # the service's answer, or the model file's offline
    created = client.register_class("teapot", attributes=["hard", "smooth"], wait=20)
    class_id = created["class"]["id"]        # POST /v1/classes' answer: {"class", "job"}
    added = client.add_sample(class_id, touch, wait=20)  # added["recognized_as"]: what the
                                             # model made of the touch before learning it
    created = client.register_class("mug", samples=touches, wait=20)  # learnt from its touches

Every call answers as its route does (docs/CLIENT.md lists them), with ``wait`` reading the
``job`` of a 202 again once it finished or the wait ran out. ``recognize`` answers as
``POST /v1/recognize`` does, plus ``"source"``: ``"service"``, or ``"offline"`` when the
service cannot be reached (connection errors and timeouts, after ``retries``, or 502 / 503 /
504): then the model file of the last ``sync_model`` answers, with the version and class ids
of that moment. Input the service refuses (4xx) is not
answered offline: it raises ``ServiceError`` with the service's explanation. Enrolments
need the service; every one carries an ``Idempotency-Key``, so a retry after a lost answer
gets the original job and never enrols twice.
"""

from __future__ import annotations

import hashlib
import io
import json
import time
import uuid
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import httpx
import numpy as np

from app.framework import bundle
from app.framework.recognizer import (
    ABSTAIN,
    TARGET_CONFIDENCE,
    TactileRecognizer,
    check_outliers,
)

UNREACHABLE_STATUS = frozenset({502, 503, 504})
LISTS = frozenset({"classes", "jobs", "models"})  # the lists every() reads, page by page
PAGE_MAX = 1000  # the most rows a list's page holds (app/api/deps.py)


class ServiceError(RuntimeError):
    """The service refused a request (``status``, and its problem detail in the message;
    ``problem``: the service's RFC 9457 body, where it answered with one)."""

    def __init__(
        self, message: str, status: int | None = None, problem: dict[str, Any] | None = None
    ) -> None:
        super().__init__(message)
        self.status = status
        self.problem = problem


class ServiceUnreachable(ServiceError):
    """The service could not be reached, and no model file could answer instead."""


class TactileClient:
    """``base_url`` and ``api_key`` name the service; ``model_file`` is where ``sync_model``
    keeps the model for offline recognition (with ``<model_file>.json`` beside it: its
    version, ETag and class ids). ``http`` replaces the HTTP client (e.g. a TestClient)."""

    def __init__(
        self,
        base_url: str = "",
        api_key: str | None = None,
        model_file: str | Path | None = None,
        timeout: float = 10.0,
        retries: int = 2,
        offline_top_k: int = 3,
        http: httpx.Client | None = None,
    ) -> None:
        if retries < 0 or offline_top_k < 1 or timeout <= 0:
            raise ValueError("retries must be ≥ 0, offline_top_k ≥ 1 and timeout > 0")
        self._owns_http = http is None
        self.http = http if http is not None else httpx.Client(base_url=base_url, timeout=timeout)
        self.headers = {"X-API-Key": api_key} if api_key else {}
        self.model_file = Path(model_file).expanduser() if model_file is not None else None
        self.timeout, self.retries, self.offline_top_k = timeout, retries, offline_top_k
        self._offline = bundle.BundleFile(self.model_file) if self.model_file is not None else None
        self._offline_meta: dict[str, Any] = {}
        self._batch_limit: int | None = None

    def close(self) -> None:
        """Close the HTTP connections (the client's own; one passed in as ``http`` stays open)."""
        if self._owns_http:
            self.http.close()

    def __enter__(self) -> TactileClient:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------ recognition
    def recognize(
        self,
        samples: Any,
        same_object: bool = False,
        *,
        target_confidence: float | None = None,
        min_model_version: int | None = None,
        known_kept: float | None = None,
        outliers: str | None = None,
        objects: Sequence[str | int] | None = None,
    ) -> dict[str, Any]:
        """Recognise one sample or a batch (N, *input shape); with ``same_object``, the
        samples are touches of one object and get one answer, their evidence fused. A
        procedure not done yet is NaN throughout its block; each result names the
        procedures it used and ``next_procedure``, null once its probability reaches
        ``target_confidence`` (None: the model's default). ``min_model_version``: the
        ``model_version`` of an enrolment job waited for, so that the answer includes it
        whichever API process gives it (offline, the model file answers as it is).
        ``known_kept``: the novelty operating point, the share of known touches the
        threshold kept at fit (None: the service's; offline ``DEFAULT_KNOWN_KEPT``, 0.90,
        as the service's default, else the model's own threshold where it holds no
        calibration curve); each result names the threshold it used. ``outliers``:
        what an input outlier's answer is, ``"abstain"`` (no class named, ``kind``
        ``"input_outlier"``) or ``"answer"`` (the model's guess, flagged); None: the
        service's, offline ``"abstain"``. ``objects``: a table of objects
        (docs/TABLES.md), the label (str or int) of the object each sample was touched on;
        one answer per object, named jointly (no class given to two objects), with
        ``object``, ``alone``, ``margin`` and ``touches``; offline, the model file names
        the table as the service would. Not with ``same_object``.

        A batch of more samples than the service's batch limit (``batch_limit()``) is sent
        in requests under it and the answers joined in order, all from one model version;
        touches of one object (``same_object``) and a table (``objects``) are one request,
        which the service refuses (422) past its limit."""
        if objects is not None:  # a table: one JSON request (labels keep their type)
            objects = list(objects)
            if same_object:
                raise ValueError(
                    "objects labels each touch's object and same_object says all are one: "
                    "use one or the other"
                )
            x = np.asarray(samples, dtype=np.float32)
            params = _query(
                outliers=None if outliers is None else check_outliers(outliers),
                target_confidence=target_confidence,
                known_kept=known_kept,
                min_model_version=min_model_version,
            )
            # one sample alone goes without its list, as the route takes it
            body = {"samples": _json_sample(x), "objects": objects}
            try:
                answer = self._send("POST", "/v1/recognize", json=body, params=params).json()
            except ServiceUnreachable as exc:
                from app.service.table_answers import table_body

                model, meta = self._offline_model(exc)
                body = table_body(
                    model,
                    meta,
                    objects,
                    x,
                    self.offline_top_k,
                    target_confidence,
                    model.operating_point(known_kept),
                    outliers or ABSTAIN,
                )
                return {**body, "source": "offline"}
            return {**answer, "source": "service"}
        x = np.asarray(samples, dtype=np.float32)
        params = _query(
            same_object=same_object,
            outliers=None if outliers is None else check_outliers(outliers),
            target_confidence=target_confidence,
            known_kept=known_kept,
            min_model_version=min_model_version,
        )
        try:
            split = None if same_object else self._split(x)
            answer = self._in_batches(
                lambda part, query: self._send(
                    "POST",
                    "/v1/recognize",
                    content=_npy(part),
                    params=query,
                    headers={"Content-Type": "application/x-npy"},
                ).json(),
                [x] if split is None else split,
                params,
            )
        except ServiceUnreachable as exc:
            model, meta = self._offline_model(exc)
            x = model.validate_samples(x, partial=True)
            groups = np.zeros(len(x), np.int64) if same_object else None
            target = TARGET_CONFIDENCE if target_confidence is None else target_confidence
            kept = model.operating_point(known_kept)
            batch = model.recognize_batch(x, self.offline_top_k, groups, target, kept)
            return self._offline_answer(batch, meta, outliers)
        return {**answer, "source": "service"}

    def batch_limit(self, refresh: bool = False) -> int:
        """The most samples (or trials) one recognize request may carry, as the service's
        ``GET /healthz`` states it (``TACTILE_BATCH_LIMIT``); read once, then remembered
        (``refresh``: read it again)."""
        if self._batch_limit is None or refresh:
            self._batch_limit = int(self._send("GET", "/healthz").json()["batch_limit"])
        return self._batch_limit

    def _split(self, x: np.ndarray) -> list[np.ndarray] | None:
        """``x`` in parts of at most the batch limit, or None where one request takes it:
        a batch within the limit, or one sample alone (told apart from a batch by the
        served model's input shape, asked only when the first axis is over the limit)."""
        if x.ndim < 2 or len(x) <= (limit := self.batch_limit()):
            return None
        if x.ndim <= len(self.active_model()["input_shape"]):
            return None
        return [x[i : i + limit] for i in range(0, len(x), limit)]

    def _in_batches(
        self, post: Callable[[Any, dict[str, Any]], dict[str, Any]], parts: list, params: dict
    ) -> dict[str, Any]:
        """``post(part, query)`` for each part, the results joined in order. Every part is
        answered by one model version: a part that an older version answered, while a newer
        one went live during the batch, is asked again at the newer one."""
        answers: list[dict[str, Any] | None] = [None] * len(parts)
        newest = params.get("min_model_version")
        for _ in range(3):  # a new version a round would be a very busy service
            for i, part in enumerate(parts):
                if answers[i] is None or answers[i]["model_version"] < newest:
                    query = params if newest is None else {**params, "min_model_version": newest}
                    answers[i] = post(part, query)
                    newest = max(newest or 0, answers[i]["model_version"])
            if all(a["model_version"] == newest for a in answers):
                results = [r for a in answers for r in a["results"]]
                return {**answers[-1], "results": results}
        raise ServiceError(
            f"the served model changed version in every round of a batch of {len(parts)} "
            "requests; send the batch again"
        )

    def explore(
        self, touch: Callable[[str], Any], target_confidence: float | None = None
    ) -> dict[str, Any]:
        """Recognise one object with the fewest procedures: do the served model's
        ``first_procedure``, then each answer's ``next_procedure`` until it is null.
        ``touch(name)`` has the robot do that procedure and returns its values (the
        procedure's block of a sample: e.g. 47 numbers of PHAC-2's 188). Returns the last
        answer with ``procedures_done``, in the order they were done. ServiceError where
        the served model answers complete samples only."""
        active = self._send("GET", "/v1/models/active").json()
        names, name = active.get("procedures") or [], active.get("first_procedure")
        if not name:
            raise ServiceError(
                "the served model answers complete samples only (it names no first procedure)"
            )
        sample = np.full(active["input_shape"], np.nan, np.float32)
        rows = sample.shape[0] // len(names)
        done: list[str] = []
        while name:
            if name in done or name not in names:
                raise ServiceError(f"the service asked for procedure {name!r} again or unknown")
            j = names.index(name)
            values = np.asarray(touch(name), dtype=np.float32)
            block = sample[j * rows : (j + 1) * rows]
            block[...] = values.reshape(block.shape)
            done.append(name)
            result = self.recognize(sample, target_confidence=target_confidence)
            answer = result["results"][0]
            name = answer["next_procedure"]
        return {**answer, "model_version": result["model_version"], "procedures_done": done}

    def recognize_trials(
        self,
        trials: Any,
        same_object: bool = False,
        outliers: str | None = None,
        *,
        known_kept: float | None = None,
        min_model_version: int | None = None,
    ) -> dict[str, Any]:
        """Recognise raw BioTac trials (``RawTrial``s or their JSON form), one answer per
        trial from all its fingers (with ``same_object``, one for all of them); offline,
        the model file's own featurizer makes the images. ``outliers``, ``known_kept`` and
        ``min_model_version`` as ``recognize``; more trials than the batch limit are sent in
        parts, as ``recognize`` sends samples."""
        body = [_json_trial(t) for t in trials]
        params = _query(
            same_object=same_object,
            outliers=None if outliers is None else check_outliers(outliers),
            known_kept=known_kept,
            min_model_version=min_model_version,
        )
        try:
            one = same_object or len(body) <= 1
            limit = max(1, len(body)) if one else self.batch_limit()
            answer = self._in_batches(
                lambda part, query: self._send(
                    "POST", "/v1/recognize", json={"trials": part}, params=query
                ).json(),
                [body[i : i + limit] for i in range(0, len(body), limit)] or [body],
                params,
            )
        except ServiceUnreachable as exc:
            model, meta = self._offline_model(exc)
            images, groups = model.trial_samples(body)
            touches = None  # one trial a group
            if same_object:
                groups, touches = np.zeros_like(groups), np.array([len(body)])
            batch = model.recognize_batch(
                images,
                self.offline_top_k,
                groups,
                known_kept=model.operating_point(known_kept),
                touches=touches,
            )
            return self._offline_answer(batch, meta, outliers)
        return {**answer, "source": "service"}

    @staticmethod
    def _offline_answer(
        batch: Any, meta: dict[str, Any], outliers: str | None = None
    ) -> dict[str, Any]:
        return {
            "model_version": meta.get("version"),
            "results": batch.records(meta.get("class_ids", {}), outliers or ABSTAIN),
            "source": "offline",
        }

    def active_model(self) -> dict[str, Any]:
        """The served model (``GET /v1/models/active``): its version, input shape and kind,
        procedures and classes."""
        return self._send("GET", "/v1/models/active").json()

    def describe(self, samples: Any, same_object: bool = False) -> dict[str, Any]:
        """What each touch feels like (``POST /v1/describe``): every attribute's probability
        and a suggested description, for a person to check before registering the object;
        with ``same_object``, also one description from all the touches (``"object"``)."""
        return self._send(
            "POST",
            "/v1/describe",
            content=_npy(samples),
            params={"same_object": same_object},
            headers={"Content-Type": "application/x-npy"},
        ).json()

    def sync_model(self) -> bool:
        """Keep ``model_file`` at the service's active version; True when a new one was
        written. A file is replaced only by a bundle that loads."""
        if self.model_file is None:
            raise ValueError("this client has no model_file to keep the model in")
        held = self._meta().get("etag") if self.model_file.is_file() else None
        r = self._send(
            "GET", "/v1/models/active/bundle", headers={"If-None-Match": held} if held else {}
        )
        if r.status_code == 304:
            return False
        version = int(r.headers["X-Model-Version"])
        bundle.from_bytes(
            r.content
        )  # raises BundleError rather than keep a file that does not load
        class_ids = {c["name"]: c["id"] for c in self._every("/v1/classes", "classes")}
        bundle.write_atomic(self.model_file, r.content)
        bundle.write_atomic(
            self._meta_file(),
            json.dumps(
                {
                    "version": version,
                    "etag": r.headers.get("etag"),
                    "class_ids": class_ids,
                    "sha256": hashlib.sha256(r.content).hexdigest(),
                }
            ).encode(),
        )
        return True

    # --------------------------------------------------------------- enrolment
    def register_class(
        self,
        name: str,
        attributes: list[str] | dict[str, float | None] | None = None,
        attribute_vector: list[float | None] | None = None,
        wait: float = 0,
        description: str | None = None,
        *,
        samples: Any = None,
        trials: Any = None,
    ) -> dict[str, Any]:
        """Register a never-touched object by its attribute names, by names with values in
        [0, 1] (``{"soft": 0.5}``; others not known), by a vector (None: not known), or in
        words (``description="a soft, spongy foam block"``; values given beside it must
        agree with it); or learn it from its touches: ``samples`` (a batch (N, *input
        shape), or a list of samples) or ``trials`` (raw BioTac trials, ``RawTrial``s or
        their JSON form, for a model of raw trials), with or without a description. Returns
        ``POST /v1/classes``' answer, ``{"class": ..., "job": ...}``, its ``job`` read again
        after up to ``wait`` seconds for it to finish (``class`` as the 202 gave it)."""
        if samples is not None and trials is not None:
            raise ValueError("give samples or trials, not both")
        described = (attributes, attribute_vector, description) != (None, None, None)
        if not described and samples is None and trials is None:
            raise ValueError("give attributes, attribute_vector, description, samples or trials")
        body = {
            "name": name,
            **_attributes_body(attributes, attribute_vector, description, required=False),
        }
        if samples is not None:
            body["samples"] = [_json_sample(x) for x in samples]
        if trials is not None:
            body["trials"] = [_json_trial(t) for t in trials]
        return self.create_class(body, wait)

    def create_class(self, body: dict[str, Any], wait: float = 0) -> dict[str, Any]:
        """``POST /v1/classes`` with ``body``, its JSON as a robot relays it (``name`` and
        attributes, a description, samples or raw trials); returns its answer, ``{"class",
        "job"}``, the job after up to ``wait`` seconds for it to finish."""
        created = self._send("POST", "/v1/classes", json=body, idempotency_key=str(uuid.uuid4()))
        return self._waited(created.json(), wait)

    def redescribe_class(
        self,
        class_id: int,
        attributes: list[str] | dict[str, float | None] | None = None,
        attribute_vector: list[float | None] | None = None,
        wait: float = 0,
        description: str | None = None,
    ) -> dict[str, Any]:
        """Correct the attributes a class was registered with, keeping its samples (names
        with values set those and keep the rest; for a dataset class, its values for
        attributes added since), or replace its description in words; returns ``PATCH
        /v1/classes/{id}``'s answer, ``{"class", "job"}``, the job after up to ``wait``
        seconds."""
        updated = self._send(
            "PATCH",
            f"/v1/classes/{int(class_id)}",
            json=_attributes_body(attributes, attribute_vector, description),
            idempotency_key=str(uuid.uuid4()),
        )
        return self._waited(updated.json(), wait)

    def interpret(self, text: str) -> dict[str, Any]:
        """The attribute values the service reads from ``text`` (nothing is stored):
        ``{"values": {attribute: value}, "readings": [...], "not_mentioned": [...]}``."""
        return self._send("POST", "/v1/attributes/interpret", json={"text": text}).json()

    def add_attribute(
        self, name: str, values: dict[str, float] | None = None, wait: float = 0
    ) -> dict[str, Any]:
        """Add an attribute to the vocabulary (an admin key), with its value for the classes
        it is known for (class name -> value in [0, 1]); returns ``POST /v1/attributes``'
        answer, ``{"attribute", "job"}``, the job after up to ``wait`` seconds for the model
        to learn it."""
        body = {"name": name, "values": values or {}}
        added = self._send("POST", "/v1/attributes", json=body, idempotency_key=str(uuid.uuid4()))
        return self._waited(added.json(), wait)

    def retire_attribute(self, name: str, wait: float = 0) -> dict[str, Any]:
        """Take an attribute out of later models (an admin key); returns ``DELETE
        /v1/attributes/{name}``'s answer, ``{"attribute", "job"}``, the job after up to
        ``wait`` seconds."""
        retired = self._send("DELETE", f"/v1/attributes/{name}", idempotency_key=str(uuid.uuid4()))
        return self._waited(retired.json(), wait)

    def add_sample(
        self, class_id: int, sample: Any = None, wait: float = 0, *, trial: Any = None
    ) -> dict[str, Any]:
        """Add one real sample to a class (one-shot learning), or one raw BioTac ``trial``
        (a ``RawTrial`` or its JSON form) for a model of raw trials; returns the service's
        answer: ``sample_id``, ``job`` (after up to ``wait`` seconds for it to finish) and
        what the served model made of the touch before learning from it
        (``recognized_as``)."""
        if (sample is None) == (trial is None):
            raise ValueError("give exactly one of sample or trial")
        body = {"sample": _json_sample(sample)} if trial is None else {"trial": _json_trial(trial)}
        added = self._send(
            "POST",
            f"/v1/classes/{int(class_id)}/samples",
            json=body,
            idempotency_key=str(uuid.uuid4()),
        )
        return self._waited(added.json(), wait)

    def sample(self, class_id: int, sample_id: int) -> np.ndarray:
        """A stored sample's data, e.g. to look at an enrolment again."""
        r = self._send(
            "GET",
            f"/v1/classes/{int(class_id)}/samples/{int(sample_id)}",
            headers={"Accept": "application/x-npy"},
        )
        return np.load(io.BytesIO(r.content), allow_pickle=False)

    def job(self, job_id: int, wait: float = 0) -> dict[str, Any]:
        """A job (``GET /v1/jobs/{id}``), after up to ``wait`` seconds (at most 20) for it to
        succeed or fail."""
        needed = wait + self.timeout  # the answer may take ``wait`` seconds to come
        read = self.http.timeout.read
        extra = {"timeout": needed} if wait > 0 and read is not None and read < needed else {}
        return self._send("GET", f"/v1/jobs/{int(job_id)}", params={"wait": wait}, **extra).json()

    # ------------------------------------------------------------------ lists
    def classes(self, after: int | None = None, limit: int | None = None) -> dict[str, Any]:
        """One page of ``GET /v1/classes``: ``{"classes": [...], "next_after"}``; pass
        ``next_after`` as ``after`` for the next page (``every("classes")``: all of them)."""
        return self._page("/v1/classes", after, limit)

    def get_class(self, class_id: int) -> dict[str, Any]:
        """One class (``GET /v1/classes/{id}``): its attributes, samples count and whether
        the served model covers it (``in_active_model``)."""
        return self._send("GET", f"/v1/classes/{int(class_id)}").json()

    def jobs(
        self,
        after: int | None = None,
        limit: int | None = None,
        *,
        status: str | None = None,
        kind: str | None = None,
        class_id: int | None = None,
    ) -> dict[str, Any]:
        """One page of ``GET /v1/jobs``, ``{"jobs": [...], "next_after"}``, oldest first;
        ``status`` (e.g. ``"failed"``), ``kind`` and ``class_id`` filter it."""
        return self._page(
            "/v1/jobs", after, limit, **_query(status=status, kind=kind, class_id=class_id)
        )

    def models(self, after: int | None = None, limit: int | None = None) -> dict[str, Any]:
        """One page of ``GET /v1/models``, ``{"models": [...], "next_after"}``: the stored
        versions, oldest first, each without its class list."""
        return self._page("/v1/models", after, limit)

    def attributes(self) -> dict[str, Any]:
        """``GET /v1/attributes``: ``{"attributes": [...]}``, the vocabulary in attribute-
        vector order, and ``"vocabulary"``, every attribute with its origin."""
        return self._send("GET", "/v1/attributes").json()

    def every(self, what: str, **filters: Any) -> list[dict[str, Any]]:
        """Every row of a list, all its pages read: ``every("classes")``, ``every("jobs",
        status="failed")``, ``every("models")``."""
        if what not in LISTS:
            raise ValueError(f"every() reads one of {sorted(LISTS)}, not {what!r}")
        return self._every(f"/v1/{what}", what, **_query(**filters))

    # ----------------------------------------------------------------- helpers
    def _send(
        self, method: str, path: str, idempotency_key: str | None = None, **kwargs: Any
    ) -> httpx.Response:
        """One request, retried after transport errors (the same Idempotency-Key each time)."""
        headers = {**self.headers, **kwargs.pop("headers", {})}
        if idempotency_key:
            headers["Idempotency-Key"] = idempotency_key
        attempt = 0
        while True:
            try:
                r = self.http.request(method, path, headers=headers, **kwargs)
            except httpx.TransportError as exc:
                if attempt == self.retries:
                    raise ServiceUnreachable(
                        f"{method} {path}: the service cannot be reached: {exc}"
                    ) from exc
                time.sleep(0.2 * 2**attempt)
                attempt += 1
                continue
            if r.status_code in UNREACHABLE_STATUS:
                raise ServiceUnreachable(
                    f"{method} {path}: the service answered {r.status_code}",
                    r.status_code,
                    _problem(r),
                )
            if r.status_code >= 400:
                raise ServiceError(
                    f"{method} {path}: {r.status_code} {_detail(r)}", r.status_code, _problem(r)
                )
            return r

    def _page(
        self, path: str, after: int | None, limit: int | None, **filters: Any
    ) -> dict[str, Any]:
        return self._send("GET", path, params=_query(after=after, limit=limit, **filters)).json()

    def _every(self, path: str, key: str, **filters: Any) -> list[dict[str, Any]]:
        rows, after = [], None
        while True:
            page = self._page(path, after, PAGE_MAX, **filters)
            rows += page[key]
            after = page.get("next_after")
            if after is None:
                return rows

    def _waited(self, accepted: dict[str, Any], wait: float) -> dict[str, Any]:
        """A 202's answer with its ``job`` read again after up to ``wait`` seconds."""
        return {**accepted, "job": self.job(accepted["job"]["id"], wait)} if wait else accepted

    def _meta_file(self) -> Path:
        assert self.model_file is not None
        return self.model_file.with_name(self.model_file.name + ".json")

    def _meta(self) -> dict[str, Any]:
        try:
            return json.loads(self._meta_file().read_text())
        except (OSError, ValueError):
            return {}

    def _offline_model(self, cause: ServiceUnreachable) -> tuple[TactileRecognizer, dict[str, Any]]:
        """The model file (read again only when it changed) and what is known of it: its
        version and class ids only when the sidecar describes this very file."""
        if self._offline is None or not self.model_file.is_file():
            raise ServiceUnreachable(
                f"{cause}; and there is no model file to recognise offline "
                "(call sync_model while the service is reachable)"
            ) from cause
        model, fresh = self._offline.load()
        if fresh:  # a sidecar of another file: the answers still hold, the labels may not
            meta = self._meta()
            self._offline_meta = meta if meta.get("sha256") == self._offline.sha256 else {}
        return model, self._offline_meta


def _query(**params: Any) -> dict[str, Any]:
    """A request's query parameters: those given (None: the service's default)."""
    return {k: v for k, v in params.items() if v is not None}


def _npy(samples: Any) -> bytes:
    body = io.BytesIO()
    np.save(body, np.asarray(samples, dtype=np.float32), allow_pickle=False)
    return body.getvalue()


def _json_sample(sample: Any) -> list:
    """One sample as JSON: nested lists of numbers, ``null`` where a value is missing (NaN),
    which JSON cannot write and the service names by its cell."""
    x = np.asarray(sample, dtype=np.float32)
    out = x.astype(object)
    out[~np.isfinite(x)] = None
    return out.tolist()


def _json_trial(trial: Any) -> dict[str, Any]:
    """A raw trial as JSON: a ``RawTrial``'s ``to_dict()``, or its JSON form as it is."""
    return trial.to_dict() if hasattr(trial, "to_dict") else trial


def _attributes_body(
    attributes: list[str] | dict[str, float | None] | None,
    attribute_vector: list[float | None] | None,
    description: str | None = None,
    required: bool = True,
) -> dict[str, Any]:
    """The attributes part of a body; ``required``: one of the three must be given."""
    if attributes is not None and attribute_vector is not None:
        raise ValueError("give attributes or attribute_vector, not both")
    if required and attributes is None and attribute_vector is None and description is None:
        raise ValueError("give attributes, attribute_vector or description")
    body: dict[str, Any] = {} if description is None else {"description": description}
    if attributes is not None:
        body["attributes"] = attributes
    if attribute_vector is not None:
        body["attribute_vector"] = attribute_vector
    return body


def _problem(r: httpx.Response) -> dict[str, Any] | None:
    """The response's problem+json body, None when it is not one."""
    if not r.headers.get("content-type", "").startswith("application/problem+json"):
        return None
    try:
        body = r.json()
    except ValueError:
        return None
    return body if isinstance(body, dict) else None


def _detail(r: httpx.Response) -> str:
    try:
        return str(r.json().get("detail", r.text))
    except ValueError:
        return r.text
