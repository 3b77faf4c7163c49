"""The input-drift series of a model whose channels no longer apply: dropped in one
process, and in a multi-process ``serve`` (prometheus_client's multiprocess mode, which
cannot drop labelled series) left without the warning prometheus_client gives for it."""

from __future__ import annotations

import warnings

from app.framework.input_health import InputProfile
from app.service.input_monitor import InputMonitor
from app.service.metrics import Metrics


def _two_models(base_model):
    """A batch of the base model's answers, its input profile, and a profile that differs."""
    model, dataset = base_model
    batch = model.recognize_batch(dataset.samples[:4])
    profile = model.input_profile_
    p = profile
    other = InputProfile(p.input_shape, p.scale, p.low, p.high, p.median + 1, p.width, p.threshold)
    return batch, profile, other


def _channels(metrics: Metrics) -> set:
    return {s.labels["channel"] for m in metrics.input_drift.collect() for s in m.samples}


def test_a_new_model_drops_the_drift_series_in_one_process(base_model, monkeypatch):
    monkeypatch.delenv("PROMETHEUS_MULTIPROC_DIR", raising=False)
    batch, profile, other = _two_models(base_model)
    metrics = Metrics()
    monitor = InputMonitor(metrics, window=8)
    monitor.observe(batch, profile)
    monitor.refresh()
    assert _channels(metrics)
    monitor.observe(batch, other)
    assert not _channels(metrics)


def test_a_new_model_gives_no_warning_in_multiprocess_mode(base_model, monkeypatch, tmp_path):
    monkeypatch.setenv("PROMETHEUS_MULTIPROC_DIR", str(tmp_path))
    batch, profile, other = _two_models(base_model)
    monitor = InputMonitor(Metrics(), window=8)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # "Clearing labels has not been implemented ..."
        monitor.observe(batch, profile)
        monitor.refresh()
        monitor.observe(batch, other)
        monitor.refresh()
