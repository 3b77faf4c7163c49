"""ClassRegistry's deep copy: as independent as copy.deepcopy's, whatever it shares."""

from __future__ import annotations

import copy

import numpy as np

from app.framework.state import ClassRegistry


def test_a_copied_registry_is_equal_and_changes_apart_from_its_original():
    reg = ClassRegistry(
        attribute_names=("hard", "soft"),
        known_names=["cup", "sponge"],
        known_attributes=np.float32([[1, 0], [0, 1]]),
        novel_names=["mug"],
        novel_attributes=np.float32([[1, np.nan]]),
        novel_samples={"mug": np.ones((1, 3, 2), np.float32)},
    )
    both = copy.deepcopy([reg, reg])
    new = both[0]
    assert both[1] is new  # one copy per object, as copy.deepcopy makes
    assert new is not reg and new.known_names == reg.known_names
    assert new.attribute_names == reg.attribute_names
    np.testing.assert_array_equal(new.novel_attributes, reg.novel_attributes)
    new.known_names.append("teapot")
    new.novel_names[0] = "jug"
    new.known_attributes[0, 0] = 0
    new.novel_samples["mug"][0, 0, 0] = 5
    new.novel_samples["jug"] = np.zeros((1, 3, 2), np.float32)
    assert reg.known_names == ["cup", "sponge"] and reg.novel_names == ["mug"]
    assert reg.known_attributes[0, 0] == 1 and reg.novel_samples["mug"][0, 0, 0] == 1
    assert list(reg.novel_samples) == ["mug"]
