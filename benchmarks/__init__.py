"""Throughput harness for jaxfilters (STYLE.md habit 12): `python -m benchmarks --json`."""
