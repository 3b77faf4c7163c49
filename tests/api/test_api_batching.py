"""Concurrent small recognize requests share forward passes and get their own answers."""

from __future__ import annotations

import asyncio

import numpy as np
import pytest

from app.service.batcher import RecognitionBatcher
from app.service.holder import LoadedModel


class Echo:
    """A stand-in recognizer that answers each sample with (its name, the sample's tag, top_k,
    and the operating point it was asked for where one was)."""

    def __init__(self, name: str, fail: bool = False) -> None:
        self.name, self.fail, self.calls = name, fail, []

    def recognize_batch(self, x: np.ndarray, top_k: int, known_kept: float | None = None):
        self.calls.append(len(x))
        if self.fail:
            raise RuntimeError("boom")
        extra = () if known_kept is None else (known_kept,)
        return [(self.name, float(v), top_k, *extra) for v in x[:, 0]]


def test_answers_go_back_to_their_requests_in_shared_passes():
    echo = Echo("m1")
    model = LoadedModel(1, echo, {})
    batcher = RecognitionBatcher(max_samples=64)

    async def main():
        xs = [np.full((1 + i % 3, 1), float(i)) for i in range(40)]
        answers = await asyncio.gather(*[batcher.recognize(model, x, 3) for x in xs])
        return xs, answers

    xs, answers = asyncio.run(main())
    for x, answer in zip(xs, answers, strict=True):
        assert answer == [("m1", float(x[0, 0]), 3)] * len(x)
    assert len(echo.calls) < 40 and max(echo.calls) <= 64  # passes were shared, and capped


def test_each_model_snapshot_top_k_and_operating_point_gets_its_own_pass():
    old, new = Echo("old"), Echo("new")
    batcher = RecognitionBatcher()

    async def main():
        return await asyncio.gather(
            batcher.recognize(LoadedModel(1, old, {}), np.zeros((1, 1)), 3),
            batcher.recognize(LoadedModel(2, new, {}), np.ones((1, 1)), 3),
            batcher.recognize(LoadedModel(2, new, {}), np.ones((1, 1)), 5),
            batcher.recognize(LoadedModel(2, new, {}), np.ones((1, 1)), 3, 0.95),
        )

    a, b, c, d = asyncio.run(main())
    assert a == [("old", 0.0, 3)] and b == [("new", 1.0, 3)]
    assert c == [("new", 1.0, 5)] and d == [("new", 1.0, 3, 0.95)]
    assert new.calls == [1, 1, 1]


def test_a_failing_pass_fails_its_requests_and_the_batcher_recovers():
    batcher = RecognitionBatcher()
    bad = LoadedModel(1, Echo("bad", fail=True), {})
    good = LoadedModel(2, Echo("good"), {})

    async def main():
        with pytest.raises(RuntimeError, match="boom"):
            await batcher.recognize(bad, np.zeros((1, 1)), 3)
        return await batcher.recognize(good, np.zeros((2, 1)), 3)

    assert asyncio.run(main()) == [("good", 0.0, 3)] * 2


def test_concurrent_http_requests_match_single_ones(client, dataset):
    import concurrent.futures

    singles = [
        client.post("/v1/recognize", json={"samples": [s.tolist()]}).json()["results"][0]
        for s in dataset.samples[:12]
    ]
    with concurrent.futures.ThreadPoolExecutor(8) as pool:
        futures = [
            pool.submit(client.post, "/v1/recognize", json={"samples": [s.tolist()]})
            for s in dataset.samples[:12]
        ]
        concurrent_answers = [f.result().json()["results"][0] for f in futures]
    for one, other in zip(singles, concurrent_answers, strict=True):
        assert one["class_name"] == other["class_name"]
        assert one["novelty_score"] == pytest.approx(other["novelty_score"], rel=1e-4)


def test_finish_runs_once_a_pass_with_each_requests_own_finish_with():
    echo, finished = Echo("m"), []

    def finish(model, batch, finish_with):
        finished.append((len(batch), finish_with))
        return [(*row, finish_with) for row in batch]

    model = LoadedModel(1, echo, {})
    batcher = RecognitionBatcher(finish=finish)

    async def main():
        return await asyncio.gather(
            batcher.recognize(model, np.zeros((2, 1)), 3, None, "abstain"),
            batcher.recognize(model, np.ones((1, 1)), 3, None, "abstain"),
            batcher.recognize(model, np.ones((1, 1)), 3, None, "answer"),
        )

    a, b, c = asyncio.run(main())
    assert a == [("m", 0.0, 3, "abstain")] * 2 and b == [("m", 1.0, 3, "abstain")]
    assert c == [("m", 1.0, 3, "answer")]
    assert sorted(finished) == [(1, "answer"), (3, "abstain")]  # one finish a pass
