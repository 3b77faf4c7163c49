"""The test suite, a regular package like each of its folders: pytest imports a test module
as ``tests.<folder>.<module>`` with the repository root on sys.path, so ``tests/worker`` is
``tests.worker`` and never stands in for the top-level ``worker`` package."""
