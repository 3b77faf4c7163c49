"""Checks on the tables that ``evaluate`` prints and writes: nothing but what was measured."""

from __future__ import annotations

import re

EMPTY = "—"


def markdown_tables(text: str) -> list[list[list[str]]]:
    """Every markdown table of ``text``: its rows (header first, the ``---`` line left out),
    each a list of cells."""
    tables: list[list[list[str]]] = []
    current: list[list[str]] = []
    for line in text.splitlines() + [""]:
        if line.startswith("|"):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if not all(set(c) <= {"-", " "} for c in cells):
                current.append(cells)
        elif current:
            tables.append(current)
            current = []
    return tables


def empty_markdown_rows(text: str) -> list[str]:
    """Table rows whose every value cell (all but the first) is ``—``."""
    return [
        " | ".join(row)
        for table in markdown_tables(text)
        for row in table[1:]
        if len(row) > 1 and all(c == EMPTY for c in row[1:])
    ]


def empty_markdown_columns(text: str) -> list[str]:
    """Table columns whose every value (all rows but the header) is ``—``."""
    out = []
    for table in markdown_tables(text):
        head, body = table[0], table[1:]
        for j, name in enumerate(head):
            if body and all(len(row) > j and row[j] == EMPTY for row in body):
                out.append(name)
    return out


def empty_definitions(text: str) -> list[str]:
    """Items of a figure list (``- `name`: what it is``) with nothing after the colon."""
    return re.findall(r"^- `([^`]+)`:\s*$", text, flags=re.MULTILINE)


def empty_printed_rows(text: str) -> list[str]:
    """Lines of a printed plain-text table whose cells after the first are all ``—``."""
    out = []
    for line in text.splitlines():
        cells = line.split()
        if len(cells) > 1 and all(c == EMPTY for c in cells[1:]):
            out.append(line)
    return out
