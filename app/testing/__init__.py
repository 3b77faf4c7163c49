"""Test support shipped with the package, as ``starlette.testclient`` or ``django.test`` are:
what both ``tests/`` and ``bench/`` use to build a quick service and run it for real.

- ``service``    the quick model, its settings and datasets, fresh stores, ``store check``
- ``harness``    real ``serve`` and ``worker`` processes on one store (``Cluster``)
- ``pgserver``   a throwaway PostgreSQL server that may be stopped and crashed
- ``faults``     SQLite store faults: a full tmpfs, injected write errors
- ``scenarios``  the reliability scenarios, sized by their callers (tests small, bench big)

Nothing here imports pytest: the pytest fixtures wrapping these stay in ``tests/``
(``tests/service_fixtures.py``).
"""
