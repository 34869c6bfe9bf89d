"""Logs every JAX trace, lowering and XLA compile of a process, and of its children, with the test.

Put this folder first on PYTHONPATH and name a log folder in JAXFILTERS_COMPILE_LOG (see
benchmarks/compile_profile.py, which does both and sums the logs): Python imports this file at
start-up in every process that inherits the two variables (pytest's workers, the CLI subprocesses,
notebook kernels). When `jax._src.monitoring` is imported, a duration listener is registered that
appends one JSON line per event to LOG/<pid>.jsonl: the event's last path part, seconds, the
function's name, and the test running it (pytest's PYTEST_CURRENT_TEST, which child processes
inherit; otherwise the process's argv). It imports no JAX itself and does nothing without the
variable.
"""

import os

if os.environ.get("JAXFILTERS_COMPILE_LOG"):
  import importlib.abc
  import importlib.machinery
  import json
  import sys
  import time

  _LOG = os.environ["JAXFILTERS_COMPILE_LOG"]
  _EVENTS = ("compile", "trace", "mlir", "cache")
  _out = []

  def _on_duration(event, duration, **kw):
    if not any(s in event for s in _EVENTS):
      return
    if not _out:
      _out.append(open(os.path.join(_LOG, f"{os.getpid()}.jsonl"), "a", buffering=1))
    test = os.environ.get("PYTEST_CURRENT_TEST") or "argv: " + " ".join(sys.argv[:3])
    _out[0].write(json.dumps({"test": test, "event": event.rsplit("/", 1)[-1], "s": round(duration, 4),
                              "fun": kw.get("fun_name", ""), "t": round(time.time(), 3)}) + "\n")

  class _RegisterListener(importlib.abc.MetaPathFinder):
    """Registers the listener right after jax._src.monitoring executes."""

    def find_spec(self, name, path, target=None):
      if name != "jax._src.monitoring":
        return None
      spec = importlib.machinery.PathFinder.find_spec(name, path)
      run = spec.loader.exec_module

      def exec_module(module):
        run(module)
        module.register_event_duration_secs_listener(_on_duration)
      spec.loader.exec_module = exec_module
      return spec

  sys.meta_path.insert(0, _RegisterListener())
