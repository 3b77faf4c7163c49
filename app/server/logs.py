"""How ``serve``, its API processes and ``worker`` log: one format, INFO, and the
libraries that say too much at INFO held at WARNING.

faiss's loader logs each build it tries at INFO, and a ``ModuleNotFoundError`` for every
CPU extension missing from the installed wheel (``swigfaiss_avx512``, ``swigfaiss_avx2``)
before it loads the generic one: an operator reads that as a failure. Its warnings and
errors still show.
"""

from __future__ import annotations

import logging

LOG_FORMAT = "%(asctime)s %(levelname)s %(name)s: %(message)s"
#: loggers held at WARNING: what they say at INFO is no news to an operator
QUIET_LOGGERS = ("faiss.loader",)


def configure_logging() -> None:
    """INFO in ``LOG_FORMAT`` to stderr (where no handler is set yet), ``QUIET_LOGGERS``
    at WARNING. A logger's level holds whenever its library is imported, before or after."""
    logging.basicConfig(level=logging.INFO, format=LOG_FORMAT)
    for name in QUIET_LOGGERS:
        logging.getLogger(name).setLevel(logging.WARNING)
