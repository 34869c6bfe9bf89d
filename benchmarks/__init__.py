"""Throughput harness for jaxfilters: `python -m benchmarks --json`.

Every figure is measured in the run that reports it (compile time apart from the steady state,
the device named, baselines timed on the same inputs); BENCHMARKS.md's tables are generated from
the committed JSON results by `python -m benchmarks.tables`.
"""
