"""Attribute values from a description in a person's own words.

``TextInterpreter.interpret("a soft, spongy foam block that soaks up water", vocabulary)``
gives each attribute the text speaks of a value in [0, 1] and the words that gave it;
attributes it says nothing about are absent (not known), never 0.

How a text is read:

1. It is cut into clauses at punctuation and at "and", "but", "with", "yet", "while".
2. In each clause, the longest phrases of the lexicon (``app.words.lexicon``) are found,
   word by word with simple endings removed ("softer", "softly" read as "soft"); a word
   that names a vocabulary attribute not in the lexicon (one added at run time, such as
   "rubbery"), by its name or stem, is read as that attribute.
3. Left-over content words are compared with the vocabulary by the sentence-embedding
   model; one counts when its cosine with an attribute's anchor reaches ``threshold`` and
   beats every other attribute's by ``margin`` (antonyms lie close in such models, so
   this is a last resort, kept strict).
4. Up to three words before a reading in its clause grade it: a negation ("not", "no",
   "doesn't", "without") makes "has it" 0 and drops what the word implied about
   opposites; "not very" gives ``NOT_VERY``; "very" and the like give 1; "slightly" and
   the like give ``WEAK``; a plain word gives ``PLAIN``. A material ("steel", "foam")
   gives the values such material usually has, scaled by ``MATERIAL``. A material
   phrase whose words speak of the feel on their own ("hard steel") gives both readings,
   each word graded by the words before it: "a very hard steel block" is hard 1.
5. Per attribute the strongest source wins (a word about the feel over a material, an
   attribute named directly over one implied), then the earlier mention.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from app.words.embedding import SentenceEmbedder, shared_embedder
from app.words.lexicon import NEGATIONS, STOP, STRONG, WEAK, readings

PLAIN, WEAK_VALUE, NOT_VERY = 0.9, 0.6, 0.3
MAX_TEXT = 1000  # characters of a description read at most
_CLAUSE = re.compile(r"[,.;:!?()]|\b(?:and|but|with|yet|while|whereas|though|although)\b")
_WORD = re.compile(r"[a-z]+(?:'[a-z]+)?")
_ENDINGS = (("iest", "y"), ("ier", "y"), ("est", ""), ("er", ""), ("ly", ""), ("ness", ""))


class TextError(ValueError):
    """A description that cannot be read; the message says why."""


class EmptyText(TextError):
    pass


class TextTooLong(TextError):
    pass


class NothingRecognised(TextError):
    """No attribute of the vocabulary was found; ``closest`` names the nearest ones."""

    def __init__(self, message: str, closest: list[str]) -> None:
        super().__init__(message)
        self.closest = closest


@dataclass(frozen=True)
class Reading:
    """One attribute value read from a text."""

    attribute: str
    value: float  # in [0, 1]
    words: str  # the part of the text that gave it
    # "word", "implied" (what a word says of its opposite), "material", "embedding"; or
    # "estimated": not said, estimated from what was said (``app.words.estimate``)
    source: str


_RANK = {"word": 3, "implied": 2, "embedding": 1, "material": 0, "estimated": -1}


def _stem(word: str) -> str:
    for ending, repl in _ENDINGS:
        if word.endswith(ending) and len(word) - len(ending) >= 3:
            base = word[: -len(ending)] + repl
            return base[:-1] if len(base) > 3 and base[-1] == base[-2] else base  # bigg -> big
    return word


def _name_stems(name: str) -> set[str]:
    low = name.lower()
    out = {low, _stem(low)}
    if low.endswith("y") and len(low) > 4:  # rubbery -> rubber, bumpy -> bump
        out.add(low[:-1])
    return out


class TextInterpreter:
    """Reads attribute values from text (see the module docstring).

    Parameters
    ----------
    threshold : float, default 0.7
        Least cosine, in the sentence-embedding model, between a left-over word and an
        attribute's name for the word to count as that attribute. Set by hand above the
        cosines of antonyms and near-synonyms in this model (hard/soft 0.55, rough/soft 0.64,
        furry/hairy 0.66), so only a near-identical word passes; never tuned on PHAC-2.
    margin : float, default 0.1
        How much that cosine must beat the best other attribute's.
    max_chars : int, default 1000
        Longest text read; longer is ``TextTooLong``.
    embedder : SentenceEmbedder or None
        The model; None takes the process's shared one.
    lexicon : path or None
        A lexicon file as ``app.words.lexicon_build`` writes it; None takes the frozen one
        (``app.words.lexicon.LEXICON``).
    """

    def __init__(
        self,
        threshold: float = 0.7,
        margin: float = 0.1,
        max_chars: int = MAX_TEXT,
        embedder: SentenceEmbedder | None = None,
        lexicon: Path | None = None,
    ) -> None:
        self.threshold = threshold
        self.margin = margin
        self.max_chars = max_chars
        self.embedder = embedder
        self.lexicon = lexicon
        self._lexicon = readings() if lexicon is None else readings(Path(lexicon))
        self._longest = max(len(p.split()) for p in self._lexicon)

    def _model(self) -> SentenceEmbedder:
        return self.embedder if self.embedder is not None else shared_embedder()

    # ------------------------------------------------------------------ reading
    def interpret(self, text: str, vocabulary: Sequence[str]) -> dict[str, Reading]:
        """Attribute -> its ``Reading``, for the attributes of ``vocabulary`` the text speaks
        of. EmptyText, TextTooLong, or NothingRecognised (naming the closest attributes)."""
        vocab = self._check(text, vocabulary)
        found = self._read(text, vocab)
        if not found:
            closest = self.closest(text, vocab)
            raise NothingRecognised(
                f"the text names no attribute of the vocabulary; the closest are "
                f"{', '.join(closest)}",
                closest,
            )
        return found

    def value_of(self, text: str, attribute: str) -> Reading | None:
        """The reading of one attribute (say, one just added to the vocabulary), or None
        when the text says nothing of it."""
        return self._read(text, self._check(text, [attribute])).get(attribute)

    def closest(self, text: str, vocabulary: Sequence[str], k: int = 3) -> list[str]:
        """The ``k`` attributes whose names lie nearest the whole text in the embedding."""
        vocab = list(vocabulary)
        vectors = self._model().encode([text.strip().lower(), *vocab])
        order = np.argsort(-(vectors[1:] @ vectors[0]), kind="stable")
        return [vocab[i] for i in order[:k]]

    # ----------------------------------------------------------------- helpers
    def _read(self, text: str, vocab: list[str]) -> dict[str, Reading]:
        """Every attribute of ``vocab`` the text speaks of, by the strongest source."""
        names = {s: a for a in vocab for s in _name_stems(a)}  # a vocabulary word's forms
        found: dict[str, Reading] = {}
        for clause in self._clauses(text):
            for reading in self._read_clause(text, clause, vocab, names):
                old = found.get(reading.attribute)
                if old is None or _RANK[reading.source] > _RANK[old.source]:
                    found[reading.attribute] = reading
        return found

    def _check(self, text: str, vocabulary: Sequence[str]) -> list[str]:
        if not isinstance(text, str) or not text.strip():
            raise EmptyText("the description is empty")
        if len(text) > self.max_chars:
            raise TextTooLong(
                f"the description has {len(text)} characters; at most {self.max_chars} are read"
            )
        vocab = [str(v) for v in vocabulary]
        if not vocab:
            raise ValueError("the vocabulary is empty: there is nothing to read a text into")
        return vocab

    @staticmethod
    def _clauses(text: str) -> list[list[tuple[str, int, int]]]:
        """Clauses as lists of (word, start, end) in ``text``."""
        low = text.lower().replace("’", "'")
        out, current, last = [], [], 0
        cuts = [m.start() for m in _CLAUSE.finditer(low)] + [len(low)]
        for cut in cuts:
            for m in _WORD.finditer(low, last, cut):
                word = m.group()
                if word.endswith("n't") and word not in NEGATIONS:
                    word = "n't"  # "doesn't", "isn't": a negation whatever the verb
                current.append((word, m.start(), m.end()))
            if current:
                out.append(current)
            current, last = [], cut + 1
        return out

    def _read_clause(
        self,
        text: str,
        clause: list[tuple[str, int, int]],
        vocab: list[str],
        names: dict[str, str],
    ) -> list[Reading]:
        words = [w for w, _, _ in clause]
        stems = [_stem(w) for w in words]
        out: list[Reading] = []
        used = [False] * len(words)
        i = 0
        while i < len(words):
            named = names.get(words[i], names.get(stems[i]))  # a vocabulary word, by its name
            hit = None
            for n in range(min(self._longest, len(words) - i), 0, -1):
                for phrase in (" ".join(words[i : i + n]), " ".join(stems[i : i + n])):
                    if phrase in self._lexicon:
                        hit = (n, self._lexicon[phrase])
                        break
                if hit:
                    break
            if hit is None and named is None:
                i += 1
                continue
            n, (values, strength) = hit or (1, ({named: 1.0}, 1.0))
            for j in range(i, i + n):
                used[j] = True
            out.extend(self._graded(text, clause, i, n, values, strength, vocab))
            if n == 1 and named is not None and named not in values:  # the lexicon reads the
                out.extend(self._graded(text, clause, i, 1, {named: 1.0}, 1.0, vocab))  # word too
            if strength < 1.0 and n > 1:  # "hard steel" is a material and says "hard" too
                for j in range(i, i + n):
                    feel = self._feel(words[j], stems[j], names)
                    if feel:
                        out.extend(self._graded(text, clause, j, 1, feel, 1.0, vocab))
            i += n
        left = [
            k
            for k, w in enumerate(words)
            if not used[k] and w not in STOP and w not in NEGATIONS and len(w) > 2
        ]
        if left:
            out.extend(self._embedded(text, clause, left, vocab))
        return out

    def _feel(self, word: str, stem: str, names: dict[str, str]) -> dict[str, float]:
        """What one word says of the feel on its own (a lexicon word of full strength, or a
        vocabulary attribute's name); empty for a word that is not one."""
        for form in (word, stem):
            values, strength = self._lexicon.get(form, ({}, 0.0))
            if values and strength >= 1.0:
                return values
        named = names.get(word, names.get(stem))
        return {named: 1.0} if named is not None else {}

    def _graded(self, text, clause, i, n, values, strength, vocab) -> list[Reading]:
        """The readings of the phrase at words i … i+n-1, graded by up to 3 words before it."""
        before = [w for w, _, _ in clause[max(0, i - 3) : i]]
        negated = any(w in NEGATIONS for w in before)
        strong = any(w in STRONG for w in before)
        weak = any(w in WEAK for w in before)
        start = i
        for k in range(max(0, i - 3), i):  # the words quoted begin at the first modifier
            if clause[k][0] in NEGATIONS | STRONG | WEAK:
                start = k
                break
        words = text[clause[start][1] : clause[i + n - 1][2]]
        grade = NOT_VERY if negated and strong else 1.0 if strong else WEAK_VALUE if weak else PLAIN
        out = []
        primary = [a for a, v in values.items() if v >= 0.5]
        for attr in values:
            if attr not in vocab:
                continue
            direct = attr in primary
            if negated and not direct:
                continue  # "not soft" says nothing of hard
            if strength < 1.0:
                source = "material"
            else:
                source = "word" if direct else "implied"
            if negated and grade != NOT_VERY:
                value = 0.0
            elif direct:
                value = grade * strength if source == "material" else grade
            else:
                value = 1.0 - grade
            out.append(Reading(attr, round(float(value), 3), words, source))
        return out

    def _embedded(self, text, clause, left, vocab) -> list[Reading]:
        """Left-over content words matched to the vocabulary's names by the embedding."""
        model = self._model()
        anchors = model.encode(vocab)
        queries = model.encode([clause[k][0] for k in left])
        sim = queries @ anchors.T
        out = []
        for row, k in enumerate(left):
            order = np.argsort(-sim[row])
            best = sim[row, order[0]]
            second = sim[row, order[1]] if len(order) > 1 else -1.0
            if best >= self.threshold and best - second >= self.margin:
                before = [w for w, _, _ in clause[max(0, k - 3) : k]]
                value = 0.0 if any(w in NEGATIONS for w in before) else PLAIN
                words = text[clause[k][1] : clause[k][2]]
                out.append(Reading(vocab[order[0]], value, words, "embedding"))
        return out
