"""The README documents every setting (a new setting is easy to forget)."""

from pathlib import Path

from app.config import Settings

README = Path(__file__).resolve().parents[1] / "README.md"


def test_every_setting_is_in_the_readme():
    text = README.read_text()
    missing = [
        f"TACTILE_{name.upper()}"
        for name in Settings.model_fields
        if f"TACTILE_{name.upper()}" not in text
    ]
    assert missing == []
