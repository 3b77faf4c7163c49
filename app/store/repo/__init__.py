"""Every query the API and the worker make (being split by concern into this package)."""

from app.store.repo.classes import *  # noqa: F403
