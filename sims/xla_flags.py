"""Re-export of `jaxfilters._xla_flags` (XLA options set before JAX starts; imports no JAX)."""

from jaxfilters._xla_flags import FAST_CPU_COMPILE_FLAG, use_fast_cpu_compile  # noqa: F401
