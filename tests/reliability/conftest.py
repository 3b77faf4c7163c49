"""Shared service fixtures live in tests/service_fixtures.py."""

from tests.service_fixtures import *  # noqa: F403
