"""One module per thing the bench measures; each returns its results to bench/harness/run.py, and the
ones with a ``main`` also run alone (``python -m bench.sections.NAME``)."""
