import numpy as np
import pytest

from app.words.estimate import UnmentionedEstimator
from app.words.lexicon import readings, sources

ATTRS = ["soft", "squishy", "compressible", "metallic", "cool"]
KNOWN = np.array(
    [
        [1, 1, 1, 0, 0],  # foam
        [1, 1, 1, 0, np.nan],  # sponge, its coolness not known
        [0, 0, 0, 1, 1],  # steel
        [0, 0, 0, 1, 1],  # aluminium
    ],
    float,
)


def test_unmentioned_attributes_follow_the_known_classes_that_match():
    est = UnmentionedEstimator().fit(KNOWN, ATTRS).estimate({"soft": 0.9, "squishy": 0.9})
    assert set(est) == {"compressible", "metallic", "cool"}  # never what was read
    assert est["compressible"] > 0.9 and est["metallic"] < 0.1 and est["cool"] < 0.1
    hard = UnmentionedEstimator().fit(KNOWN, ATTRS).estimate({"soft": 0.0})
    assert hard["metallic"] > 0.8 and hard["compressible"] < 0.2


def test_a_wider_kernel_moves_estimates_toward_the_known_mean():
    read = {"soft": 0.9}
    narrow = UnmentionedEstimator(width=0.1).fit(KNOWN, ATTRS).estimate(read)
    wide = UnmentionedEstimator(width=100).fit(KNOWN, ATTRS).estimate(read)
    assert narrow["metallic"] < wide["metallic"] == pytest.approx(0.5, abs=0.01)


def test_nothing_to_estimate_from_and_bad_input():
    est = UnmentionedEstimator().fit(KNOWN, ATTRS)
    assert est.estimate({"rubbery": 1.0}) == {}
    with pytest.raises(ValueError, match="one value per attribute"):
        UnmentionedEstimator().fit(KNOWN[:, :3], ATTRS)
    with pytest.raises(ValueError, match="no known class"):
        UnmentionedEstimator().fit(np.zeros((0, 5)), ATTRS)
    with pytest.raises(ValueError, match="width"):
        UnmentionedEstimator(width=0).fit(KNOWN, ATTRS)


def test_the_lexicon_names_no_phac2_object_that_no_general_source_gives():
    lexicon, origin = readings(), sources()
    for name in ("mdf", "loofah", "microfiber", "bubble", "bubbles", "tissues"):
        assert name not in lexicon
    assert set(origin) == set(lexicon)
    assert all(
        s in ("name", "definition", "development") or s.startswith("wordnet ")
        for s in origin.values()
    )


def test_estimated_readings_are_marked_and_name_what_they_follow_from():
    from app.words.estimate import estimated_readings
    from app.words.interpret import Reading

    read = {"soft": Reading("soft", 0.9, "soft", "word")}
    out = estimated_readings(read, UnmentionedEstimator().fit(KNOWN, ATTRS))
    assert set(out) == {"squishy", "compressible", "metallic", "cool"}
    assert {r.source for r in out.values()} == {"estimated"}
    assert out["metallic"].words == "estimated from soft and the known classes"
    assert out["squishy"].value > 0.8 > 0.2 > out["metallic"].value
