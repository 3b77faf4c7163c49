"""Everyday words for haptic attributes: what ``TextInterpreter`` reads before it asks the
sentence-embedding model.

A sentence-embedding model places antonyms side by side (all-MiniLM-L6-v2 gives "hard" and
"soft" a cosine of 0.55, "rough" and "soft" 0.64), so it cannot tell which of two opposite
attributes a word means. The readings here are therefore explicit: a phrase (one to four
words, lower case, matched whole) gives values to attributes. 1.0 means "has it", 0.0 "has
not"; a material gives the values such material usually has, at ``MATERIAL`` strength.
An attribute that is not listed (one added to the vocabulary at run time, e.g. "rubbery")
is matched by its own name and, failing that, by the embedding model.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

#: the lexicon ``app.words.lexicon_build`` wrote from WordNet, the attributes' definitions
#: and the development set (never from a PHAC-2 description); frozen on 2026-11-28
LEXICON = Path(__file__).resolve().parent / "lexicon.json"
#: strength of a value that follows from a material ("steel" is usually cool) rather than
#: from a word about the feel
MATERIAL = 0.8


@functools.cache
def _load(path: Path) -> dict[str, tuple[dict[str, float], float]]:
    phrases = json.loads(path.read_text(encoding="utf-8"))["phrases"]
    return {p: (dict(e["values"]), float(e["strength"])) for p, e in phrases.items()}


def readings(path: Path = LEXICON) -> dict[str, tuple[dict[str, float], float]]:
    """Phrase -> (attribute values, strength): words about the feel at 1, materials at
    ``MATERIAL``. A copy: the caller may keep it."""
    return dict(_load(path))


def sources(path: Path = LEXICON) -> dict[str, str]:
    """Phrase -> where it came from (a WordNet sense, ``definition``, ``development``)."""
    phrases = json.loads(path.read_text(encoding="utf-8"))["phrases"]
    return {p: e["source"] for p, e in phrases.items()}


#: words that negate the reading after them in the same clause
NEGATIONS = frozenset(
    "not no never without hardly barely isn't aren't doesn't don't wasn't won't nor "
    "neither n't".split()
)
#: words that make a reading stronger, and weaker
STRONG = frozenset("very extremely really super so totally completely quite incredibly".split())
WEAK = frozenset("slightly somewhat mildly fairly bit little rather kinda partly".split())
#: words read as nothing on their own (articles, fillers, modifiers)
STOP = frozenset(
    "a an the it its it's is are was be this that of to in on at for by as like one side "
    "other and but with feels feel when you your yet or so very really slightly somewhat "
    "bit little not no quite has have made from up down".split()
)
