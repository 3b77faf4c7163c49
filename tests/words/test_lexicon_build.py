"""The committed lexicon is what ``app.words.lexicon_build`` writes from WordNet."""

import json
from pathlib import Path

import pytest

from app.words import lexicon_build
from app.words.lexicon import LEXICON

WORDNET = Path("/usr/share/wordnet")


@pytest.mark.skipif(
    not (WORDNET / "data.adj").is_file(), reason="WordNet not installed (wordnet-base)"
)
def test_building_again_gives_the_committed_lexicon(tmp_path):
    out = tmp_path / "lexicon.json"
    assert lexicon_build.main(["--wordnet", str(WORDNET), "--out", str(out)]) == 0
    assert json.loads(out.read_text()) == json.loads(LEXICON.read_text())


def test_a_missing_wordnet_is_named(tmp_path):
    with pytest.raises(SystemExit) as done:
        lexicon_build.main(["--wordnet", str(tmp_path)])
    assert done.value.code == 2


def test_inflections():
    assert lexicon_build.forms("soak up", "verb") == [
        "soak up", "soaks up", "soaked up", "soaking up"
    ]  # fmt: skip
    assert lexicon_build.forms("pore", "noun") == ["pore", "pores"]
    assert lexicon_build.forms("spongy", "adj") == ["spongy"]
