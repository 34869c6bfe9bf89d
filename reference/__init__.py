"""Independent references that tests and benchmarks check the library against (not installed).

    nav2     float64 NumPy loops of Nav2's costmap filters (keepout, speed, binary, zone), written
             from docs/nav2_semantics.md and sharing no code with jaxfilters.
    planner  the fleet planner and navigation-field lookups in their straightforward form, which
             sims/fleet/planner.py and sims/fleet/navigation.py must match.

This package lives at the repository root beside tests/ and benchmarks/ so both can import it
(`from reference import nav2`); pyproject.toml installs only jaxfilters and sims.
"""
