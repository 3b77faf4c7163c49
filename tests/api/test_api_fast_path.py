"""POST /v1/recognize through RecognizeFastPath (app/api/fast_path.py) answers as the FastAPI
route below it does, errors included; it is counted in /metrics, keys and the rate limit
hold on it, and what it leaves to the stack (CORS, oversized bodies) still gets there."""

from __future__ import annotations

import re

import numpy as np
import pytest
from fastapi.testclient import TestClient

from app.api.fast_path import RecognizeFastPath
from app.framework.recognizer import RecognitionBatch
from app.service.holder import LoadedModel
from app.service.keys import RateLimiter
from app.service.metrics import Metrics
from app.service.recognition import RecognitionService
from app.store import repo
from tests.service_fixtures import PROBLEM, npy, problem

NPY = {"content-type": "application/x-npy"}


def fast_path_of(app) -> RecognizeFastPath:
    node = app.middleware_stack
    while not isinstance(node, RecognizeFastPath):
        node = node.app
    return node


@pytest.fixture
def stack(app, client) -> TestClient:
    """A client of the same app with the fast path stepped over: POST /v1/recognize reaches
    the FastAPI route (the app's lifespan runs under ``client``)."""
    below = fast_path_of(app).app

    async def asgi(scope, receive, send):
        scope["app"] = app  # as Starlette sets it before its middleware stack
        await below(scope, receive, send)

    return TestClient(asgi, raise_server_exceptions=False)


def requests(dataset) -> list[dict]:
    x = dataset.samples[:3]
    one = dataset.samples[0].tolist()
    bad = dataset.samples[:1].tolist()
    bad[0][0][0] = "many"
    return [
        {"json": {"samples": [one]}},
        {"json": {"samples": x.tolist()}},
        {"json": {"samples": x.tolist()}, "params": {"same_object": "true"}},
        {"content": npy(x), "headers": NPY},
        {"content": npy(dataset.samples[0]), "headers": NPY},
        {"json": {"samples": [one]}, "params": {"same_object": "maybe"}},
        {"json": {"samples": bad}},
        {"json": {"samples": [one[:-1]]}},
        {"json": {"samples": []}},
        {"content": b"{", "headers": {"content-type": "application/json"}},
        {"content": b"[1, 2]", "headers": {"content-type": "text/plain"}},
        {"content": b"\x93NUMPY garbage", "headers": NPY},
        {"json": {"trials": [{"fingers": []}]}},
        {"json": {"samples": [one], "extra": 1}},
    ]


def test_every_answer_is_the_routes_own(client, stack, dataset):
    for kwargs in requests(dataset):
        fast, slow = client.post("/v1/recognize", **kwargs), stack.post("/v1/recognize", **kwargs)
        assert fast.status_code == slow.status_code, (kwargs, fast.text, slow.text)
        assert fast.headers["content-type"] == slow.headers["content-type"]
        assert fast.json() == slow.json(), kwargs
        assert int(fast.headers["content-length"]) == len(fast.content)


def test_no_model_is_the_routes_answer_too(client, stack, app, sample, monkeypatch):
    monkeypatch.setattr(app.state.service.holder, "_current", None)
    fast = client.post("/v1/recognize", json={"samples": [sample]})
    slow = stack.post("/v1/recognize", json={"samples": [sample]})
    assert fast.status_code == slow.status_code == 503
    assert fast.json() == slow.json() and fast.headers["retry-after"] == "5"


def metric(client, pattern: str) -> float:
    """The value on the line of /metrics that ``pattern`` matches; 0 where none does."""
    found = re.search(pattern, client.get("/metrics").text, re.M)
    return float(found.group(1)) if found else 0.0


def counted(client, status: int) -> float:
    return metric(
        client,
        rf'^tactile_http_requests_total\{{method="POST",route="/v1/recognize",'
        rf'status="{status}"\}} (\S+)$',
    )


def latency_count(client) -> float:
    return metric(
        client,
        r'^tactile_http_request_duration_seconds_count\{method="POST",'
        r'route="/v1/recognize"\} (\S+)$',
    )


def test_fast_path_requests_are_counted_by_status(client, sample):
    before_ok, before_bad, before_n = (
        counted(client, 200),
        counted(client, 422),
        latency_count(client),
    )
    for _ in range(3):
        assert client.post("/v1/recognize", json={"samples": [sample]}).status_code == 200
    problem(client.post("/v1/recognize", json={"samples": []}), 422)
    assert counted(client, 200) == before_ok + 3
    assert counted(client, 422) == before_bad + 1
    assert latency_count(client) == before_n + 4
    recognised = re.findall(
        r"^tactile_recognitions_total\{kind=\"(\w+)\"\} (\S+)$", client.get("/metrics").text, re.M
    )
    assert sum(float(v) for _, v in recognised) >= 3


def test_keys_scopes_and_the_rate_limit_hold_on_the_fast_path(client, app, sample):
    body = {"samples": [sample]}
    assert client.post("/v1/recognize", json=body).status_code == 200  # open: no key exists
    with app.state.service.sessions.begin() as s:
        read, _ = repo.create_api_key(s, "read", None)
    app.state.service.keys.refresh()
    problem(client.post("/v1/recognize", json=body), 401, "X-API-Key")
    problem(client.post("/v1/recognize", json=body, headers={"X-API-Key": "tzk_no"}), 401)
    h = {"X-API-Key": read}
    assert client.post("/v1/recognize", json=body, headers=h).status_code == 200
    app.state.service.limiter = RateLimiter(rate=0.5, burst=2)
    assert client.post("/v1/recognize", json=body, headers=h).status_code == 200
    assert client.post("/v1/recognize", json=body, headers=h).status_code == 200
    r = client.post("/v1/recognize", json=body, headers=h)
    problem(r, 429, "X-API-Key")
    assert int(r.headers["retry-after"]) >= 1
    assert counted(client, 429) >= 1


def test_an_unexpected_error_is_a_500_problem_without_internals(app, sample, monkeypatch):
    async def broken(*_args, **_kwargs):
        raise RuntimeError("Traceback: secret internals")

    with TestClient(app, raise_server_exceptions=False) as c:
        monkeypatch.setattr(app.state.service.recognition, "recognize", broken)
        r = c.post("/v1/recognize", json={"samples": [sample]})
        assert r.status_code == 500 and r.headers["content-type"] == PROBLEM
        assert "secret" not in r.text and "Traceback" not in r.text
        assert counted(c, 500) == 1


def test_bodies_over_the_cap_are_413_declared_or_chunked(tmp_path, base_model):
    from app.api.main import create_app
    from app.testing.service import quick_settings

    app = create_app(
        quick_settings(tmp_path / "d", max_body_bytes=1024), trainer=lambda: base_model
    )
    with TestClient(app) as c:
        body = npy(base_model[1].samples[:2])
        declared = c.post("/v1/recognize", content=body, headers=NPY)
        chunked = c.post("/v1/recognize", content=iter([body[:900], body[900:]]), headers=NPY)
        for r in (declared, chunked):
            problem(r, 413, "body")
            assert r.json()["detail"] == "request body is larger than 1024 bytes"
        # the declared one is answered before any route is matched ("unmatched"), as before
        assert counted(c, 413) == 1


def test_with_cors_a_request_with_an_origin_gets_its_headers(settings, base_model, sample):
    from app.api.main import create_app

    app = create_app(
        settings.model_copy(update={"cors_origins": ["https://ops.example"]}),
        trainer=lambda: base_model,
    )
    with TestClient(app) as c:
        body = {"samples": [sample]}
        r = c.post("/v1/recognize", json=body, headers={"Origin": "https://ops.example"})
        assert r.status_code == 200
        assert r.headers["access-control-allow-origin"] == "https://ops.example"
        r = c.post("/v1/recognize", json=body)  # a robot: no Origin
        assert r.status_code == 200 and "access-control-allow-origin" not in r.headers
        assert counted(c, 200) == 2


def test_records_match_the_frameworks_for_known_novel_and_padded_answers():
    names = ("a", "b", "c", "novel-1")
    batch = RecognitionBatch(
        names,
        3,
        np.array([[3, 0, 1], [1, 2, -1], [0, -1, -1]]),
        np.array([[0.5, 0.3, 0.2], [0.9, 0.1, np.nan], [1.0, np.nan, np.nan]]),
        np.array([True, False, False]),
        np.array([2.5, -1.0, 0.0]),
    )
    service = RecognitionService(Metrics(), top_k=3, batch_limit=10)
    model = LoadedModel(4, object(), {"a": 11, "b": 12, "novel-1": 40})  # "c": no id
    assert service.records(model, batch) == batch.records(model.class_ids)
    assert service.records(model, batch[1:2]) == batch[1:2].records(model.class_ids)
    # another model (another version): its own labels
    other = LoadedModel(5, object(), {"a": 1, "b": 2, "c": 3, "novel-1": 4})
    assert service.records(other, batch) == batch.records(other.class_ids)
