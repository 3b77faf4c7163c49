"""Input health on ``/metrics``: outliers among the answers, and drift of recent inputs.

Every answer carries ``input_outlier`` (``app.framework.input_health``); this module keeps
what an operator alerts on, per API process:

- ``tactile_input_outliers_total``: answers whose input was an outlier (divide its rate by
  ``tactile_recognitions_total``'s for the outlier rate);
- ``tactile_input_outlier_rate``: the share of outliers among the last ``window`` samples;
- ``tactile_input_drift{channel}``: per channel, how far the median of the last ``window``
  samples' channel statistics lies from the training median, in training IQRs
  (``InputProfile.window_drift``);
- ``tactile_input_window_samples``: how many samples the window holds (the two above are
  figures of that many; a window fills after ``window`` samples).

The window holds the channel statistics of the last ``window`` samples (``TACTILE_INPUT_
WINDOW``), written on the hot path into a ring (one row copy per sample); the gauges are
computed from it at each scrape, and in a multi-process ``serve`` by each process every
few seconds (``InputDriftPoller``), since any process may answer the scrape. A new model
whose profile differs empties the window. Answers of a model without a profile (a bundle
written before profiles) are not counted.
"""

from __future__ import annotations

import threading

import numpy as np

from app.framework.input_health import InputProfile
from app.framework.results import RecognitionBatch
from app.service.polling import Poller


class InputMonitor:
    """The window of recent inputs and the metrics made of it (``metrics``: the app's
    ``Metrics``)."""

    def __init__(self, metrics, window: int) -> None:
        if window < 1:
            raise ValueError(f"the input window must hold at least 1 sample, got {window}")
        self.metrics = metrics
        self.window = int(window)
        self._lock = threading.Lock()
        self._profile: InputProfile | None = None
        self._channel_names: tuple[str, ...] = ()
        self._rows: np.ndarray | None = None  # (window, S) float32 statistics
        self._outlier: np.ndarray = np.zeros(self.window, bool)
        self._next = 0  # the ring's next row
        self._filled = 0
        self._seen = 0  # samples written since the gauges were last computed

    def observe(self, batch: RecognitionBatch, profile: InputProfile | None, names=()) -> None:
        """Count ``batch``'s outliers and keep its samples' statistics; ``profile``: the
        answering model's (``names``: its channels' names, if it has them)."""
        if profile is None or batch.input_outlier is None:
            return
        outliers = int(np.count_nonzero(batch.input_outlier))
        if outliers:
            self.metrics.input_outliers.inc(outliers)
        statistics = batch.input_statistics
        if statistics is None:
            return
        # a sample's verdict: its answer's, where each answer is one sample; else its own
        # (a trial's fingers, fused touches: the answer is an outlier where any sample is)
        flags = (
            batch.input_outlier
            if len(batch.input_outlier) == len(statistics)
            else profile.is_outlier(profile.score_features(statistics))
        )
        with self._lock:
            if profile is not self._profile:
                self._adopt(profile, names)
            self._write(statistics[-self.window :], flags[-self.window :])

    def _adopt(self, profile: InputProfile, names) -> None:
        """Take ``profile`` as the window's; a different one (not a copy an enrolment made)
        empties the window and the channels' series."""
        before = self._profile
        same = (
            before is not None
            and before.input_shape == profile.input_shape
            and np.array_equal(before.median, profile.median)
            and np.array_equal(before.inv_width, profile.inv_width)
            and np.array_equal(before.inv_scale, profile.inv_scale)
        )
        self._profile = profile
        if same:
            return
        size = len(profile.median)
        self._rows = np.full((self.window, size), np.nan, np.float32)
        self._outlier[:] = False
        self._next = self._filled = 0
        self._seen = 1  # the gauges change even before a sample arrives
        self._channel_names = tuple(names) or tuple(str(i) for i in range(profile.n_channels))
        self.metrics.forget_input_channels()

    def _write(self, statistics: np.ndarray, flags: np.ndarray) -> None:
        n, start = len(statistics), self._next
        end = start + n
        if end <= self.window:
            self._rows[start:end] = statistics
            self._outlier[start:end] = flags
        else:  # wraps around
            first = self.window - start
            self._rows[start:] = statistics[:first]
            self._rows[: n - first] = statistics[first:]
            self._outlier[start:] = flags[:first]
            self._outlier[: n - first] = flags[first:]
        self._next = end % self.window
        self._filled = min(self.window, self._filled + n)
        self._seen += n

    def refresh(self) -> None:
        """Set the gauges from the window (where samples arrived since the last time)."""
        with self._lock:
            if not self._seen or self._profile is None or self._rows is None:
                return
            self._seen = 0
            filled, profile = self._filled, self._profile
            rows = self._rows[:filled].copy()
            rate = float(self._outlier[:filled].mean()) if filled else 0.0
            names = self._channel_names
        m = self.metrics
        m.input_window_samples.set(filled)
        m.input_outlier_rate.set(rate)
        if not filled:
            return
        for name, value in zip(names, profile.window_drift(rows).tolist(), strict=True):
            m.input_drift.labels(name).set(value)


class InputDriftPoller(Poller):
    """Computes the input gauges every ``poll_seconds`` in one process of a multi-process
    ``serve``, where another process may answer the scrape."""

    _thread_name = "input-drift"
    _failure = "metrics: could not compute the input drift"

    def __init__(self, monitor: InputMonitor, poll_seconds: float = 5.0) -> None:
        super().__init__(poll_seconds)
        self._monitor = monitor

    def refresh(self) -> None:
        self._monitor.refresh()
