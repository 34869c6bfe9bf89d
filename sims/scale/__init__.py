"""Scale-out and measurement: device meshes for the fleet and the RL env, and throughput benchmarks.

Rooms: `sharding` (1-D meshes over the world axis, multi-process runs with jax.distributed),
`bench` (fleet throughput against bare MJX, compile time apart).

Imports: `jaxfilters`, `sims.fleet` and this package (the RL env is passed in, never imported).
"""
