"""sims/rl/task.py: the task is part of the model's pytree, so per-env randomisation reaches it.

`NavModel` (an mjx.Model) treats a field as pytree data only when mjx can see arrays in its type
annotations; with string annotations (`from __future__ import annotations` in task.py) the task
became static metadata and every randomised env drove the same goals and zones, with no error.
"""

import jax
import jax.numpy as jnp
import mujoco
from mujoco import mjx

from sims.fleet.env import ROBOT_XML
from sims.fleet.layouts import LayoutBank
from sims.fleet.world import WorldParams
from sims.rl.env import nav_model
from sims.rl.task import NavTask


def _task():
  return NavTask(world=None, static_inflated=jnp.zeros((4, 4), jnp.uint8), goal_logits=jnp.zeros(6),
                 bank=None, layout=jnp.zeros((), jnp.int32))


def test_task_leaves_are_model_leaves():
  model = mjx.put_model(mujoco.MjModel.from_xml_path(str(ROBOT_XML)))
  task = _task()
  m = nav_model(model, task)
  leaves = jax.tree.leaves(m)
  assert any(x is task.goal_logits for x in leaves) and any(x is task.layout for x in leaves)
  none = jax.tree.map(lambda _: None, m)
  assert none.task.goal_logits is None                      # mapped like every other array of the model
  paths = {jax.tree_util.keystr(path) for path, _ in jax.tree_util.tree_flatten_with_path(m)[0]}
  assert ".task.goal_logits" in paths and ".task.layout" in paths


def test_navtask_annotations_are_types_not_strings():
  import dataclasses
  for f in dataclasses.fields(NavTask):
    assert not isinstance(f.type, str), (f.name, f.type)
  assert {f.name: f.type for f in dataclasses.fields(NavTask)}["world"] is WorldParams
  assert {f.name: f.type for f in dataclasses.fields(NavTask)}["bank"] is LayoutBank
