"""The simulated fleet: a warehouse with K robots per world in MuJoCo MJX, driven through Nav2's filters.

Rooms: `config` (FleetConfig, PlannerConfig, RobotConfig), `scenario` (map and masks from Nav2
files), `layouts` (random zone layouts), `world` (a scenario as device arrays), `navigation`
(distance fields), `planner` (the local planner), `local_costmap` (each robot's rolling costmap),
`metrics` (compliance counters), `robot` (your own MJCF base, checked against its interface),
`env` (FleetEnv: reset, step, rollouts), `topk` (a shard-friendly top_k), `quiet_mjx` (keeps
mujoco.mjx's import lines off the screen).

Imports: `jaxfilters` and this package only. Everything else in `sims` builds on it.
"""
