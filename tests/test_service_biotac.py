"""End to end on raw signals: a real ``tactile-zsl serve --dataset biotac:DIR`` on the real
BioTac pilot recordings (four objects, four of every five trials, written to a temporary
``biotac:`` folder), recognising held-out raw trials over HTTP, then enrolling the fifth
object from two raw trials and recognising its other trials once the job succeeded."""

from __future__ import annotations

from pathlib import Path

import httpx
import numpy as np
import pytest

from app.data.biotac import read_biotac_h5, write_biotac_h5
from app.testing.harness import serving

pytestmark = pytest.mark.slow

PILOT = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "biotac_pilot"
NEW_OBJECT = "metal_bar"


@pytest.fixture(scope="module")
def pilot_split(tmp_path_factory):
    """(biotac: folder of four objects' training trials, held-out trials by object, the
    fifth object's trials)."""
    if not (PILOT / "cork.h5").is_file():
        pytest.skip(f"BioTac pilot data not found at {PILOT.resolve()}")
    folder = tmp_path_factory.mktemp("biotac")
    held: dict[str, list] = {}
    new = []
    for path in sorted(PILOT.glob("*.h5")):
        trials = read_biotac_h5(path)
        if path.stem == NEW_OBJECT:
            new = list(trials.values())
            continue
        names = sorted(trials)
        keep = {n: trials[n] for i, n in enumerate(names) if i % 5 != 2}
        held[path.stem] = [trials[n] for i, n in enumerate(names) if i % 5 == 2]
        write_biotac_h5(folder / path.name, keep)
    return folder, held, new


@pytest.fixture(scope="module")
def service(pilot_split, tmp_path_factory):
    folder = pilot_split[0]
    data_dir = tmp_path_factory.mktemp("biotac-service")
    with serving(data_dir, {"TACTILE_DATASET": f"biotac:{folder}"}) as url:
        yield url


def recognize(url: str, trials: list, **params) -> list[str]:
    r = httpx.post(
        f"{url}/v1/recognize",
        params=params,
        json={"trials": [t.to_dict() for t in trials]},
        timeout=60,
    )
    assert r.status_code == 200, r.text
    return [res["class_name"] for res in r.json()["results"]]


def test_a_served_raw_trial_model_recognises_and_learns_raw_trials(service, pilot_split):
    _, held, new = pilot_split
    active = httpx.get(f"{service}/v1/models/active").json()
    assert active["input_kind"] == "raw_trials" and active["reason"] == "bootstrap"

    trials = [t for ts in held.values() for t in ts]
    truth = [name for name, ts in held.items() for _ in ts]
    answers = recognize(service, trials)
    assert np.mean([a == t for a, t in zip(answers, truth, strict=True)]) >= 0.9, answers

    r = httpx.post(
        f"{service}/v1/classes",
        timeout=60,
        json={"name": NEW_OBJECT, "trials": [t.to_dict() for t in new[:2]]},
    )
    assert r.status_code == 202, r.text
    job = httpx.get(f"{service}/v1/jobs/{r.json()['job']['id']}?wait=20", timeout=60).json()
    for _ in range(10):  # the embedded worker may take a few rounds on 2 busy cores
        if job["status"] in ("succeeded", "failed"):
            break
        job = httpx.get(f"{service}/v1/jobs/{job['id']}?wait=20", timeout=60).json()
    assert job["status"] == "succeeded", job
    # The learnt object's touches reach it only where they are routed novel first: at the
    # default operating point (0.90 of known touches kept) 8 of its 13 other trials were
    # (metal_bar's others went to glass_bottle, a known hard, smooth object), at 0.85 12 of
    # 13, with the held-out known trials named right 1.0 and 0.83 of the time: the pilot's
    # 5 objects give a coarse curve
    answers = recognize(service, new[2:])
    assert np.mean([a == NEW_OBJECT for a in answers]) >= 0.6, answers
    answers = recognize(service, new[2:], known_kept=0.85)
    assert np.mean([a == NEW_OBJECT for a in answers]) >= 0.8, answers
