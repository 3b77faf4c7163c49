"""The reader of descriptions in words, with the real sentence-embedding model."""

import pytest

from app.words.interpret import (
    MAX_TEXT,
    EmptyText,
    NothingRecognised,
    TextInterpreter,
    TextTooLong,
)

VOCAB = (
    "absorbent bumpy compressible cool fuzzy hard hairy metallic porous rough scratchy "
    "slippery smooth soft solid springy squishy textured thick"
).split()


@pytest.fixture(scope="module")
def reader() -> TextInterpreter:
    return TextInterpreter()


def values(reader, text, vocab=VOCAB):
    return {a: r.value for a, r in reader.interpret(text, vocab).items()}


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("slightly rough", {"rough": 0.6}),
        ("very hard", {"hard": 1.0}),
        ("not hard", {"hard": 0.0}),
        ("it is not very thick", {"thick": 0.3}),
        ("spongy", {"squishy": 0.9, "absorbent": 0.9}),
        ("furry", {"hairy": 0.9}),  # WordNet: covered with a dense coat of fine hairs
        ("stiff", {"hard": 0.9, "soft": 0.1}),
        ("slick", {"slippery": 0.9}),
        ("it soaks up water", {"absorbent": 0.9}),
        ("Softer than it looks", {"soft": 0.9}),
        ("cold to the touch", {"cool": 0.9}),
    ],
)
def test_grades_negations_synonyms_and_paraphrases(reader, text, expected):
    got = values(reader, text)
    for name, value in expected.items():
        assert got[name] == pytest.approx(value), (text, got)


def test_attributes_the_text_does_not_speak_of_are_absent(reader):
    read = reader.interpret("a soft, spongy foam block that soaks up water", VOCAB)
    assert {"soft", "absorbent", "squishy"} <= set(read)
    assert not {"metallic", "cool", "rough", "bumpy", "hairy"} & set(read)
    text = "a soft, spongy foam block that soaks up water"
    for r in read.values():
        assert r.words in text and 0.0 <= r.value <= 1.0


def test_a_negated_word_says_nothing_of_its_opposite(reader):
    read = reader.interpret("not soft at all", VOCAB)
    assert read["soft"].value == 0.0 and "hard" not in read


def test_a_name_alone_reads_its_material(reader):
    read = reader.interpret("steel vase", VOCAB)
    assert read["metallic"].value >= 0.5 and read["metallic"].source == "material"
    assert read["metallic"].words == "steel"


@pytest.mark.parametrize("strong", ["very", "extremely"])
def test_a_graded_word_inside_a_material_phrase_keeps_its_grade(reader, strong):
    # "hard steel" is a material phrase of the lexicon: its "hard" is a word about the feel
    read = reader.interpret(f"a {strong} hard steel block", VOCAB)
    assert read["hard"].value == 1.0 and read["hard"].source == "word"
    assert read["hard"].words == f"{strong} hard"
    assert read["metallic"].source == "material" and read["soft"].value == 0.0
    assert values(reader, "a hard steel block")["hard"] == pytest.approx(0.9)
    assert values(reader, "not very hard steel")["hard"] == pytest.approx(0.3)


def test_a_word_added_to_the_vocabulary_is_read_by_its_name(reader):
    got = values(reader, "a rubbery ball", VOCAB + ["rubbery"])
    assert got["rubbery"] == pytest.approx(0.9)
    assert reader.value_of("a rubbery ball", "rubbery").words == "rubbery"
    assert reader.value_of("a glass jar", "rubbery") is None


def test_bad_text_is_refused_with_the_reason(reader):
    for empty in ("", "   \n"):
        with pytest.raises(EmptyText, match="empty"):
            reader.interpret(empty, VOCAB)
    with pytest.raises(TextTooLong, match=str(MAX_TEXT)):
        reader.interpret("soft " * MAX_TEXT, VOCAB)
    with pytest.raises(NothingRecognised, match="closest") as caught:
        reader.interpret("a blue thing from the shop", VOCAB)
    assert len(caught.value.closest) == 3 and set(caught.value.closest) <= set(VOCAB)
    with pytest.raises(ValueError, match="vocabulary is empty"):
        reader.interpret("soft", [])
