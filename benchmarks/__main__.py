import sys

from jaxfilters import xla_flags

# Before JAX starts (see jaxfilters/xla_flags.py).
xla_flags.use_fast_cpu_compile()

from benchmarks.run import main  # noqa: E402

sys.exit(main())
