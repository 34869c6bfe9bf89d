import sys

from sims import xla_flags

# Before JAX starts (see sims/xla_flags.py).
xla_flags.use_fast_cpu_compile()

from benchmarks.run import main  # noqa: E402

sys.exit(main())
