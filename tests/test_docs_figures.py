"""The figures of docs/RESULTS.md and docs/BENCHMARKS.md against the result files they cite.

The convention the documents follow: a figure that a committed result file holds is written
as a link to that file whose fragment names the figure in it,

    [0.984](results/phac2-novel6/results.json#methods.best.mean.known_acc)

the path relative to ``docs/``, the fragment a key path (dict keys and list indices joined
by ``.``), optionally combined strictly left to right with a number or another key path by
``*``, ``/``, ``+`` or ``~`` (minus): ``#in_process.register_s.median*1e3`` (ms from s),
``#sizes.1.recognise_1_us/sizes.0.recognise_1_us`` (a ratio),
``#sizes.3.known_acc~sizes.3.lda_acc`` (a difference), ``#a.x+a.y/b.z`` ((x + y) / z).
The shown figure must equal the file's value rounded to the shown decimals. Every result
file a document names (by link or by path) must exist and must not come from a tree with
uncommitted changes (``machine.dirty``, or a commit stamped ``+changes``): its code is in
no commit.

Every document (README.md, CONTRIBUTING.md, docs/*.md) is read for the paths it points a
reader at: each relative markdown link (from the document's folder), each path under
``docs/``, ``bench/``, ``app/``, ``tests/`` or ``worker/`` in backticks (from the
repository root) and each ``python -m`` module of the tree must exist.
"""

from __future__ import annotations

import json
import operator
import re
import shutil
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
DOCUMENTS = ("RESULTS.md", "BENCHMARKS.md")
EVERY_DOCUMENT = sorted(
    p.relative_to(ROOT).as_posix()
    for p in (ROOT / "README.md", ROOT / "CONTRIBUTING.md", *DOCS.glob("*.md"))
    if p.is_file()
)
MD_LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")
CODE = re.compile(r"`([^`\n]+)`")
TREE_PATH = re.compile(r"(?<![\w./-])((?:docs|bench|app|tests|worker)/[\w./-]*[\w/])")
MODULE = re.compile(r"python -m ((?:app|bench|worker|tests)(?:\.\w+)+)")
PLACEHOLDER = "<*{["  # `docs/results/<run>/`: a pattern, not a path
LINK = re.compile(r"\[([^\]]+)\]\((results/[^)#\s]+\.json)#([^)\s]+)\)")
NAMED = re.compile(r"(?:docs/)?(results/[\w./-]+\.json)")
TERM = re.compile(r"([*/~+])")
OPS = {"*": operator.mul, "/": operator.truediv, "+": operator.add, "~": operator.sub}


def _number(text: str) -> tuple[float, int]:
    """A shown figure (``−0.019``, ``+0.003``, ``3,000``, ``5.6``) and its decimals."""
    t = text.strip().replace("−", "-").replace(",", "").lstrip("+")
    if not re.fullmatch(r"-?\d+(\.\d+)?", t):
        raise ValueError(f"not a plain figure: {text!r}")
    return float(t), len(t.split(".")[1]) if "." in t else 0


def _lookup(data, path: str, where: str) -> float:
    node = data
    for key in path.split("."):
        if isinstance(node, list):
            node = node[int(key)]
        elif isinstance(node, dict) and key in node:
            node = node[key]
        else:
            raise KeyError(f"{where}: no {key!r} on the way to {path!r}")
    if isinstance(node, bool) or not isinstance(node, (int, float)):
        raise TypeError(f"{where}: {path!r} is {node!r}, not a number")
    return float(node)


def _evaluate(data, fragment: str, where: str) -> float:
    """The fragment's value: key paths and numbers combined left to right by * / + ~."""
    parts = TERM.split(fragment)

    def operand(token: str) -> float:
        try:
            return float(token)
        except ValueError:
            return _lookup(data, token, where)

    value = operand(parts[0])
    for op, token in zip(parts[1::2], parts[2::2], strict=True):
        right = operand(token)
        value = OPS[op](value, right)
    return value


def dirty_reason(data: dict) -> str | None:
    """Why a result file may not be cited (its code is in no commit), or None."""
    stamps = [data.get("machine"), data.get("settings")]
    for stamp in (s for s in stamps if isinstance(s, dict)):
        if stamp.get("dirty"):
            return "machine.dirty is true"
        if "+changes" in str(stamp.get("commit", "")):
            return f"commit {stamp['commit']!r}"
        if stamp.get("uncommitted_code_changes"):
            return "uncommitted_code_changes"
    return None


def check_document(text: str, docs: Path, name: str = "document") -> tuple[int, list[str]]:
    """(figures checked, problems) of one document's text, its links read from ``docs``."""
    problems, files, checked = [], {}, 0

    def load(rel: str):
        if rel not in files:
            path = docs / rel
            files[rel] = json.loads(path.read_text()) if path.is_file() else None
            if files[rel] is None:
                problems.append(f"{name}: {rel} does not exist")
            elif isinstance(files[rel], dict) and (why := dirty_reason(files[rel])):
                problems.append(f"{name}: {rel} comes from an uncommitted tree ({why})")
        return files[rel]

    for rel in sorted(set(NAMED.findall(text))):
        load(rel)
    for shown, rel, fragment in LINK.findall(text):
        where = f"{name}: [{shown}]({rel}#{fragment})"
        data = load(rel)
        if data is None:
            continue
        try:
            figure, decimals = _number(shown)
            value = _evaluate(data, fragment, where)
        except (ValueError, KeyError, TypeError, IndexError, ZeroDivisionError) as exc:
            problems.append(f"{where}: {exc}")
            continue
        checked += 1
        if abs(value - figure) > 0.5 * 10**-decimals + 1e-9 * max(1.0, abs(value)):
            problems.append(f"{where}: the file holds {value!r}")
    return checked, problems


def missing_paths(text: str, folder: Path, root: Path = ROOT, name: str = "document") -> list[str]:
    """The paths ``text`` (a document in ``folder``) points at that do not exist: relative
    markdown links, backticked paths of the tree, and ``python -m`` modules."""
    problems = []
    for target in MD_LINK.findall(text):
        path = target.split("#", 1)[0]
        if re.match(r"[a-z][a-z0-9+.-]*:", target) or not path:
            continue  # a URL (http:, mailto:) or an anchor in the same document
        if not (folder / path).exists():
            problems.append(f"{name}: link ({target}) names no file")
    for code in CODE.findall(text):
        for found in TREE_PATH.finditer(code):
            after = code[found.end() : found.end() + 1]
            if after and after in PLACEHOLDER:
                continue
            if not (root / found.group(1)).exists():
                problems.append(f"{name}: `{found.group(1)}` does not exist")
    for module in MODULE.findall(text):
        stem = root / module.replace(".", "/")
        if not (stem.with_suffix(".py").is_file() or (stem / "__main__.py").is_file()):
            problems.append(f"{name}: python -m {module}: no such module in the tree")
    return problems


@pytest.mark.parametrize("document", EVERY_DOCUMENT)
def test_every_path_a_document_names_exists(document):
    path = ROOT / document
    problems = missing_paths(path.read_text(), path.parent, name=document)
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("document", sorted(p.name for p in DOCS.glob("*.md")))
def test_every_result_file_a_document_cites_is_committed_and_its_figures_hold(document):
    _, problems = check_document((DOCS / document).read_text(), DOCS, document)
    assert not problems, "\n".join(problems)


def test_a_path_that_does_not_exist_fails(tmp_path):
    """The path check can fail: a broken link, a backticked path and a module, each named;
    URLs, anchors and patterns pass."""
    (tmp_path / "app").mkdir()
    (tmp_path / "app" / "real.py").write_text("")
    (tmp_path / "docs").mkdir()
    (tmp_path / "docs" / "HERE.md").write_text("")
    text = (
        "[here](HERE.md#a-part) [gone](GONE.md) [web](https://example.org) [up](#top) "
        "`app/real.py` `app/lost.py` `see app/real.py and tests/none/` `docs/results/<run>/` "
        "`python -m app.real` `python -m app.absent`"
    )
    problems = missing_paths(text, tmp_path / "docs", tmp_path)
    assert problems == [
        "document: link (GONE.md) names no file",
        "document: `app/lost.py` does not exist",
        "document: `tests/none/` does not exist",
        "document: python -m app.absent: no such module in the tree",
    ], problems


def opening(text: str) -> str:
    """A document's opening screen: everything before its first ``## `` heading."""
    head = re.search(r"^## ", text, flags=re.M)
    return text[: head.start()] if head else text


@pytest.mark.parametrize("document", DOCUMENTS)
def test_every_linked_figure_is_what_its_committed_file_holds(document):
    checked, problems = check_document((DOCS / document).read_text(), DOCS, document)
    assert not problems, "\n".join(problems)
    assert checked >= 20, f"{document}: only {checked} figures linked to their files"


@pytest.mark.parametrize("document", DOCUMENTS)
def test_the_opening_screen_links_its_figures(document):
    checked, _ = check_document(opening((DOCS / document).read_text()), DOCS, document)
    assert checked >= 10, f"{document}'s opening links {checked} figures to their files"


def test_a_figure_that_differs_from_its_file_fails(tmp_path):
    """The check can fail: a copy of RESULTS.md with one linked figure changed."""
    text = (DOCS / "RESULTS.md").read_text()
    shown, rel, fragment = LINK.findall(text)[0]
    figure, decimals = _number(shown)
    wrong = f"{figure + 3 * 10**-decimals:.{decimals}f}"
    copy = tmp_path / "RESULTS.md"
    copy.write_text(text.replace(f"[{shown}]({rel}#{fragment})", f"[{wrong}]({rel}#{fragment})", 1))
    _, problems = check_document(copy.read_text(), DOCS, "copy")
    assert len(problems) == 1 and f"[{wrong}]" in problems[0], problems
    # a key the file lacks fails too, with the key named
    broken = text.replace(f"#{fragment})", f"#{fragment}_missing)", 1)
    _, problems = check_document(broken, DOCS, "copy")
    assert problems and "_missing" in problems[0], problems


def test_a_file_from_an_uncommitted_tree_may_not_be_cited(tmp_path):
    (tmp_path / "results").mkdir()
    source = DOCS / "results/scale/prototypes/scale.json"
    shutil.copy(source, tmp_path / "results/clean.json")
    data = json.loads(source.read_text())
    data["machine"]["dirty"] = True
    (tmp_path / "results/dirty.json").write_text(json.dumps(data))
    value = data["sizes"][0]["known_acc"]
    text = (
        f"[{value:.3f}](results/clean.json#sizes.0.known_acc) and "
        f"[{value:.3f}](results/dirty.json#sizes.0.known_acc), "
        "and `docs/results/missing.json`"
    )
    checked, problems = check_document(text, tmp_path)
    assert checked == 2
    assert any("dirty.json" in p and "uncommitted" in p for p in problems), problems
    assert any("missing.json does not exist" in p for p in problems), problems
    assert not any("clean.json" in p for p in problems), problems


def test_the_fragment_combines_keys_and_numbers():
    data = {"a": {"s": 0.0056}, "b": [{"x": 4.0}, {"x": 1.0}]}
    assert _evaluate(data, "a.s*1e3", "t") == pytest.approx(5.6)
    assert _evaluate(data, "b.0.x/b.1.x", "t") == 4.0
    assert _evaluate(data, "b.1.x~b.0.x", "t") == -3.0
    assert _evaluate(data, "b.0.x+b.1.x/b.0.x", "t") == 1.25  # left to right
    assert _number("−0.019") == (-0.019, 3) and _number("3,000") == (3000.0, 0)
