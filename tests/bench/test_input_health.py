"""bench.input_health runs end to end on one split of each source and writes its JSON."""

from __future__ import annotations

import json

import pytest

from app.framework.input_health import OUTLIER_THRESHOLD
from bench.input_health import BIOTAC, main


def test_one_split_of_each_source(tmp_path, phac2_path, capsys):
    if not BIOTAC.is_dir():
        pytest.skip(f"BioTac pilot not found at {BIOTAC.resolve()}")
    out = tmp_path / "input_health.json"
    assert main(["--splits", "1", "--out", str(out)]) == 0
    result = json.loads(out.read_text())
    assert result["split_seeds"] == [100] and result["threshold"] == OUTLIER_THRESHOLD
    by_source = {s["source"]: s for s in result["sources"]}
    assert set(by_source) == {"simulator", "phac2", "biotac_pilot"}
    for source in by_source.values():
        assert source["pass_rate"] >= 0.95
        assert source["flagged"]["zeros"] == source["flagged"]["scale_1e6"] == 1.0
    assert (
        by_source["biotac_pilot"]["refused"]["zeros"]
        == by_source["biotac_pilot"]["held_out_trials"]
    )
    assert "timing" not in result
