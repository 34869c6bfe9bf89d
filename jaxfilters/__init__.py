"""jaxfilters: Nav2-faithful costmap filters as batched, jittable JAX functions."""
