"""Benchmarks and measurements of the service and its methods (docs/BENCHMARKS.md,
docs/RELIABILITY.md, docs/RESULTS.md).

The scripts that import a sibling script run as modules from the repository root,
``.venv/bin/python -m bench.load``; the others (``bench_framework.py``, ``withdrawal.py``,
``describe_quality.py``) also run by path. Those that start the service use the test
support in ``app/testing`` (which ``tests/`` uses too), never the ``tests`` folder. The
exploration scripts behind docs/RESULTS.md's development figures are in ``bench/research``
and run by path.
"""
