"""Benchmarks and measurements of the service and its methods (docs/BENCHMARKS.md,
docs/RELIABILITY.md, docs/RESULTS.md).

The scripts that borrow the test suite's harness (``tests/reliability``,
``tests/service_fixtures.py``) or a sibling script run as modules from the repository
root, ``.venv/bin/python -m bench.load``; the others (``bench_framework.py``,
``withdrawal.py``, ``describe_quality.py``) also run by path. The exploration scripts
behind docs/RESULTS.md's development figures are in ``bench/research`` and run by path.
"""
