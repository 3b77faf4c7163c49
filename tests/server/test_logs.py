"""How serve and worker processes log: faiss's loader, which logs every CPU build it
tries at INFO (with a ``ModuleNotFoundError`` for each one missing), is held at WARNING."""

from __future__ import annotations

import subprocess
import sys

IMPORT_FAISS = "import faiss; faiss.IndexFlatL2(4)"


def _stderr(code: str) -> str:
    """What a fresh interpreter running ``code`` writes to stderr (faiss not yet loaded)."""
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    return run.stderr


def test_faiss_loading_says_nothing_at_info_once_logging_is_configured():
    unquiet = _stderr(f"import logging; logging.basicConfig(level=logging.INFO); {IMPORT_FAISS}")
    assert "faiss.loader" in unquiet  # what it says when left at INFO
    quiet = _stderr(
        "from app.server.logs import configure_logging; import logging; configure_logging(); "
        f"{IMPORT_FAISS}; logging.getLogger('app').info('still logging')"
    )
    assert "faiss" not in quiet and "swigfaiss" not in quiet, quiet
    assert "INFO app: still logging" in quiet
