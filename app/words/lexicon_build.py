"""Builds ``app/words/lexicon.json``, the reader's lexicon, from general sources only.

    apt-get install wordnet-base     # Princeton WordNet 3.0, Debian's package
    .venv/bin/python -m app.words.lexicon_build [--wordnet /usr/share/wordnet]

Nothing here comes from a PHAC-2 description. The sources, each phrase tagged with its own:

- ``wordnet``: for each attribute, the WordNet senses whose gloss says the attribute's
  definition (``DEFINITIONS``; the offsets were picked by reading the glosses). Their
  lemmas read as the attribute; the senses WordNet lists as similar (satellites) and the
  nouns and verbs it derives from them read as it too, and their antonyms as its absence.
  A lemma other than the attribute's own name counts only where the sense is among its
  two commonest (satellites: its commonest), so "lively" (springy) and "heavy" (thick)
  are left out: most of the time they mean something else.
- ``wordnet material``: the materials WordNet files under a material's sense (its
  hyponyms: steel, aluminium and iron under metal), read as that material usually is
  (``MATERIALS``, written from general knowledge, at ``MATERIAL`` strength).
- ``definition``: everyday phrases that say an attribute's definition in other words
  ("springs back", "soaks up"), written with the definitions.
- ``development``: words the development set (``bench/data/everyday_descriptions.csv``,
  51 objects outside PHAC-2, written before this lexicon) uses that the sources above miss.

Inflections (plurals, -s/-ed/-ing of verbs) are generated. The output is committed, so
the service never needs WordNet installed; building again gives the same file.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

from app.words.lexicon import LEXICON as OUT
from app.words.lexicon import MATERIAL, NEGATIONS, STOP, STRONG, WEAK

#: each attribute's definition, as a person would say it
DEFINITIONS = {
    "absorbent": "takes in liquid, as a towel or sponge soaks up water",
    "bumpy": "its surface has bumps, lumps or ridges you can feel",
    "compressible": "gets smaller when pressed; gives under the fingers",
    "cool": "feels cold to the touch, drawing heat from the hand",
    "fuzzy": "covered with short, soft, fine fibres, like felt or a peach",
    "hard": "resists pressure; does not yield when pressed",
    "hairy": "covered with hairs or long fibres",
    "metallic": "made of metal, or feels like metal",
    "porous": "full of small holes or pores",
    "rough": "its surface is uneven and not smooth",
    "scratchy": "rough in a way that scratches or itches the skin",
    "slippery": "the finger slides on it easily, with little grip",
    "smooth": "its surface is even, free of roughness or bumps",
    "soft": "yields readily to pressure; gentle to the touch",
    "solid": "firm and filled with matter throughout, not hollow",
    "springy": "springs back to its shape after being pressed or stretched",
    "squishy": "easily squashed, soft and yielding like a sponge",
    "textured": "its surface has a pattern or grain you can feel",
    "thick": "of great extent from one surface to the other",
}

#: attribute -> WordNet 3.0 senses ("pos offset") whose gloss is its definition
SENSES = {
    "absorbent": ["adj 00006336", "adj 00007516", "verb 01539081"],
    "bumpy": ["adj 02240007", "noun 13894434"],
    "compressible": ["adj 01153435", "adj 00514396"],
    "cool": ["adj 02529946", "adj 01251128"],
    "fuzzy": ["adj 00214165", "adj 01154030", "adj 01153141"],
    "hard": ["adj 01150915", "adj 01151740"],
    "hairy": ["adj 00212173"],
    "metallic": ["adj 01527420"],
    "porous": ["adj 00329396", "noun 13912115"],
    "rough": ["adj 02238463", "adj 02230991"],
    "scratchy": ["adj 02239290"],
    "slippery": ["adj 02234782"],
    "smooth": ["adj 02236843"],
    "soft": ["adj 01152746"],
    "solid": ["adj 02263681", "adj 01151740"],
    "springy": ["adj 00843595"],
    "squishy": ["adj 01154964"],
    "textured": ["adj 02243087"],
    "thick": ["adj 02410394"],
}

#: attributes that are each other's absence ("soft" says "not hard")
OPPOSITES = {"hard": "soft", "soft": "hard", "smooth": "rough", "rough": "smooth"}

#: everyday phrases for the definitions
DEFINITION_PHRASES = {
    "absorbent": ["soaks up", "soak up", "absorbs", "takes in water", "drinks up"],
    "compressible": [
        "gives under",
        "gives way",
        "gives a little",
        "gives",
        "squeezable",
        "compresses",
    ],
    "hard": ["does not give", "doesn't give", "does not yield", "stiff", "rigid"],
    "porous": ["holes", "holey", "full of holes", "airy"],
    "springy": [
        "springs back",
        "bounces back",
        "comes back",
        "snaps back",
        "stretchy",
        "elastic",
        "stretchable",
        "bounce",
        "bounces",
    ],
    "squishy": ["squashes", "squishes", "squeezes"],
    "scratchy": ["itchy", "prickly", "scratches"],
    "slippery": ["slides", "glides", "slick"],
    "textured": ["texture", "textures", "grain", "woven", "knitted", "ribbed", "ridged", "ridges"],
    "bumpy": ["lumpy", "bumps", "lumps", "studs", "dimpled"],
    "hairy": ["fibres", "fibers", "bristles", "bristly"],
    "fuzzy": ["fluffy", "plush", "fleecy", "velvety"],
    "thick": ["chunky", "bulky"],
    "metallic": ["metal"],
}
#: phrases read as an attribute's absence
DEFINITION_ABSENT = {
    "slippery": ["grippy", "grips", "tacky", "sticky"],
    "thick": ["thin", "flat"],
    "cool": ["warm"],
    "absorbent": ["waterproof"],
}

#: from the development set: words it uses that the sources above miss
DEVELOPMENT_PHRASES = {
    "compressible": ["sinks", "keeps the dent", "dent", "bendy", "supple"],
    "springy": ["rubbery"],
    "scratchy": ["scratch"],
    "rough": ["pitted", "sandy", "crusty", "powdery"],
    "smooth": ["shiny", "polished", "glazed", "worn smooth"],
    "squishy": ["squash", "squashes"],
}

#: material sense -> the values such material usually has (general knowledge)
MATERIALS = {
    "noun 14625458": {"metallic": 1, "hard": 1, "cool": 1, "smooth": 1, "solid": 1},  # metal
    "noun 14586769": {"metallic": 1, "hard": 1, "cool": 1, "smooth": 1, "solid": 1},  # alloy
    "noun 14881303": {"hard": 1, "smooth": 1, "cool": 1, "slippery": 1, "solid": 1},  # glass
    "noun 02997391": {"hard": 1, "smooth": 1, "cool": 1, "solid": 1},  # ceramic
    "noun 14696793": {"hard": 1, "cool": 1, "solid": 1},  # rock, stone (material)
    "noun 15098161": {"hard": 1, "solid": 1},  # wood
    "noun 14592610": {"hard": 1, "smooth": 1},  # plastic
    "noun 14872697": {"soft": 1, "squishy": 1, "compressible": 1, "porous": 1},  # foam
    "noun 14597758": {"soft": 1, "squishy": 1, "compressible": 1, "absorbent": 1, "porous": 1},
    "noun 15006258": {"springy": 1, "compressible": 1, "smooth": 1},  # rubber
    "noun 15006789": {"springy": 1, "compressible": 1, "smooth": 1},  # synthetic rubber
    "noun 03309808": {"soft": 1, "textured": 1},  # fabric, cloth
    "noun 15104217": {"soft": 1, "fuzzy": 1, "hairy": 1},  # wool (fibre)
    "noun 04599235": {"soft": 1, "fuzzy": 1},  # wool (fabric)
    "noun 14764061": {"soft": 1, "fuzzy": 1, "hairy": 1},  # fur
    "noun 14974264": {"smooth": 1},  # paper
    "noun 14799601": {"hard": 1, "smooth": 1},  # cardboard
    "noun 14759722": {"smooth": 1, "soft": 1},  # leather
    "noun 14823227": {"porous": 1, "compressible": 1},  # cork
    "noun 14820180": {"hard": 1, "rough": 1, "cool": 1, "solid": 1},  # concrete
    "noun 02897820": {"hard": 1, "rough": 1, "solid": 1},  # brick
    "noun 14870078": {"soft": 1, "absorbent": 1, "fuzzy": 1},  # cotton (fibre)
    "noun 03115180": {"soft": 1, "absorbent": 1},  # cotton (fabric)
    "noun 03326795": {"soft": 1, "fuzzy": 1},  # felt
}

#: a material's adjective the sources above miss, from the development set ("wooden chopstick")
MATERIAL_WORDS = {"noun 15098161": ["wooden"]}

POS = {"a": "adj", "s": "adj", "n": "noun", "v": "verb", "r": "adv"}


class WordNet:
    """The parts of WordNet's data files the build reads: synsets and sense order."""

    def __init__(self, root: Path) -> None:
        self.synsets: dict[str, dict] = {}
        self.senses: dict[tuple[str, str], list[str]] = {}
        for pos in ("adj", "noun", "verb"):
            with open(root / f"data.{pos}", encoding="latin-1") as f:
                for line in f:
                    if not line.startswith(" "):
                        self._synset(pos, line)
            with open(root / f"index.{pos}", encoding="latin-1") as f:
                for line in f:
                    if not line.startswith(" "):
                        parts = line.split()
                        count = int(parts[2])
                        self.senses[(pos, parts[0].replace("_", " "))] = [
                            f"{pos} {o}" for o in parts[-count:]
                        ]

    def _synset(self, pos: str, line: str) -> None:
        head, _, gloss = line.partition("|")
        f = head.split()
        n = int(f[3], 16)
        words = [re.sub(r"\(.*\)$", "", f[4 + 2 * i]).lower().replace("_", " ") for i in range(n)]
        k = 4 + 2 * n
        pointers = [
            (f[k + 1 + 4 * i], f"{POS[f[k + 3 + 4 * i]]} {f[k + 2 + 4 * i]}")
            for i in range(int(f[k]))
        ]
        self.synsets[f"{pos} {f[0]}"] = {
            "words": words,
            "pointers": pointers,
            "gloss": gloss,
            "ss": f[2],
        }

    def mostly_noun(self, lemma: str) -> bool:
        """WordNet lists more noun senses of the lemma than verb and adjective ones."""
        count = {p: len(self.senses.get((p, lemma), [])) for p in ("noun", "verb", "adj")}
        return count["noun"] > count["verb"] + count["adj"]

    def rank(self, lemma: str, synset: str) -> int:
        """1 for the lemma's commonest sense in that part of speech, 2 the next, …"""
        senses = self.senses.get((synset.split()[0], lemma), [])
        return senses.index(synset) + 1 if synset in senses else 99

    def related(self, synset: str, symbols: str) -> list[str]:
        return [t for s, t in self.synsets[synset]["pointers"] if s in symbols]

    def hyponyms(self, synset: str) -> list[str]:
        out, todo = [], [synset]
        while todo:
            for h in self.related(todo.pop(), "~"):
                if h not in out:
                    out.append(h)
                    todo.append(h)
        return out


def forms(phrase: str, pos: str) -> list[str]:
    """The phrase and its inflections: plurals of nouns, -s/-ed/-ing of verbs (first word)."""
    first, _, rest = phrase.partition(" ")
    tail = f" {rest}" if rest else ""
    if pos == "noun" and not rest:
        return [phrase, phrase + ("es" if phrase.endswith(("s", "sh", "ch", "x")) else "s")]
    if pos != "verb":
        return [phrase]  # adjectives, and phrases written out as they are read
    stem = first[:-1] if first.endswith("e") else first
    third = first + ("es" if first.endswith(("s", "sh", "ch", "x")) else "s")
    return [f"{w}{tail}" for w in (first, third, stem + "ed", stem + "ing")]


def _usable(lemma: str) -> bool:
    """Not a function word (the reader's grading and stop words), nor a symbol ("al")."""
    return (
        len(lemma) > 2
        and not any(c.isdigit() for c in lemma)
        and not set(lemma.split()) <= (STOP | NEGATIONS | STRONG | WEAK)
    )


def build(wordnet: WordNet) -> dict[str, dict]:
    """phrase -> {"values": {attribute: value}, "strength": 1 or MATERIAL, "source": …}.

    Priority: an attribute's name, then the definitions' and the development set's phrases,
    then WordNet's words for an attribute (a lemma in the senses of several attributes
    reads as all of them: "spongy" is squishy and absorbent), then WordNet's antonyms,
    then materials."""
    out: dict[str, dict] = {}

    def reading(attribute: str, present: bool) -> dict[str, float]:
        return {attribute: 1.0 if present else 0.0}

    def with_opposites(values: dict[str, float]) -> dict[str, float]:
        """A present attribute's opposite (``OPPOSITES``) read as absent, unless present."""
        out = dict(values)
        for a, v in values.items():
            if v >= 0.5 and a in OPPOSITES and OPPOSITES[a] not in values:
                out[OPPOSITES[a]] = 0.0
        return out

    def put(phrase, values, strength, source, pos="adj", merge=False) -> None:
        for form in forms(phrase, pos):
            if not _usable(form):
                continue
            if form in out:
                if merge and out[form]["source"].startswith("wordnet +"):
                    out[form]["values"].update(values)
                continue
            out[form] = {"values": dict(values), "strength": strength, "source": source}

    for attribute in DEFINITIONS:
        put(attribute, reading(attribute, True), 1.0, "name")
    for source, table, present in (
        ("definition", DEFINITION_PHRASES, True),
        ("definition", DEFINITION_ABSENT, False),
        ("development", DEVELOPMENT_PHRASES, True),
    ):
        for attribute, phrases in table.items():
            for phrase in phrases:
                put(phrase, reading(attribute, present), 1.0, source, "phrase")
    # WordNet's words for each attribute: the senses, their satellites, derived nouns
    for attribute, senses in SENSES.items():
        for synset in senses:
            pos = synset.split()[0]
            words = [(lemma, synset, 2) for lemma in wordnet.synsets[synset]["words"]]
            if wordnet.synsets[synset]["ss"] == "a":  # a head: its satellites
                words += [
                    (lemma, similar, 1)
                    for similar in wordnet.related(synset, "&")
                    for lemma in wordnet.synsets[similar]["words"]
                ]
            if pos == "adj":  # the nouns it names ("hardness", "pores")
                words += [
                    (lemma, derived, 1)
                    for derived in wordnet.related(synset, "+")
                    if derived.startswith("noun")
                    for lemma in wordnet.synsets[derived]["words"]
                ]
            for lemma, where, most in words:
                if wordnet.rank(lemma, where) <= most:
                    put(lemma, reading(attribute, True), 1.0, "wordnet + " + where,
                        where.split()[0], merge=True)  # fmt: skip
    for entry in out.values():
        entry["values"] = with_opposites(entry["values"])
    # their antonyms: the attribute's absence
    for attribute, senses in SENSES.items():
        for synset in senses:
            for antonym in wordnet.related(synset, "!"):
                for group in (antonym, *wordnet.related(antonym, "&")):
                    for lemma in wordnet.synsets[group]["words"]:
                        if wordnet.rank(lemma, group) == 1:
                            put(lemma, reading(attribute, False), 1.0, "wordnet - " + group)
    for synset, values in MATERIALS.items():
        material = {a: float(v) for a, v in values.items()}
        for lemma in MATERIAL_WORDS.get(synset, []):
            put(lemma, material, MATERIAL, "development")
        for lemma in wordnet.synsets[synset]["words"]:  # the sense picked, by any name
            put(lemma, material, MATERIAL, "wordnet material " + synset, "noun")
        for derived in wordnet.related(synset, "+\\"):  # "wooden", "metal" (adjectives)
            for lemma in wordnet.synsets[derived]["words"]:
                if derived.startswith("adj") and wordnet.rank(lemma, derived) == 1:
                    put(lemma, material, MATERIAL, "wordnet material " + derived)
        for member in wordnet.hyponyms(synset):
            for lemma in wordnet.synsets[member]["words"]:
                # a kind of the material, named by a word that is mostly this noun
                if wordnet.rank(lemma, member) == 1 and wordnet.mostly_noun(lemma):
                    put(lemma, material, MATERIAL, "wordnet material " + member, "noun")
    return dict(sorted(out.items()))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="app.words.lexicon_build", description=__doc__)
    parser.add_argument("--wordnet", type=Path, default=Path("/usr/share/wordnet"))
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    if not (args.wordnet / "data.adj").is_file():
        parser.error(f"no WordNet at {args.wordnet}: apt-get install wordnet-base")
    phrases = build(WordNet(args.wordnet))
    args.out.write_text(json.dumps({"phrases": phrases}, indent=1, sort_keys=True) + "\n")
    print(f"{len(phrases)} phrases -> {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
