import os
import sys

# Before JAX starts (see tests/conftest.py): XLA:CPU's new fusion emitter recomputes the
# exact cell-index arithmetic per fused cell; the flag is ignored by the GPU backend.
_FLAG = "--xla_cpu_use_fusion_emitters=false"
if "xla_cpu_use_fusion_emitters" not in os.environ.get("XLA_FLAGS", ""):
  os.environ["XLA_FLAGS"] = (os.environ.get("XLA_FLAGS", "") + " " + _FLAG).strip()

from benchmarks.run import main  # noqa: E402

sys.exit(main())
