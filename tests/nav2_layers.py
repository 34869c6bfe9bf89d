"""A local costmap's inflation layers from a Nav2 params file written for a test (Scenario.layers)."""

from pathlib import Path

import jaxfilters as jf

_HEADER = """\
local_costmap:
  local_costmap:
    ros__parameters:
      resolution: 0.05
      robot_radius: 0.22
      plugins: [{plugins}]
"""


def local_layers(folder: Path, plugins, blocks: str):
  """`load_params(...).local_costmap.layers` of a params file in `folder` whose local costmap (0.05 m,
  robot radius 0.22 m) lists `plugins`, with `blocks` the layers' YAML at six spaces' indent."""
  path = Path(folder) / f"{'_'.join(plugins)}.yaml"
  path.write_text(_HEADER.format(plugins=", ".join(f'"{p}"' for p in plugins)) + blocks)
  return jf.load_params(path, costmaps=("local_costmap",)).local_costmap.layers
