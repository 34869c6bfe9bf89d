"""Differentiable studies: zone parameters tuned with `jax.grad`, then checked with the hard filters.

Rooms: `corner_speed` (a corner's speed-zone limit tuned through a kinematic fleet rollout).

Imports: `jaxfilters`, `sims.fleet` and this package.
"""
