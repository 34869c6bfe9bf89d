"""Which branches of the keepout fast paths a fleet takes, for the harness's keepout figures.

Same frame: the robots whose slice test or window clip the float32 bracket left open
(the batch then runs that part exactly), and the robots whose mask cells are read as
one slice. Other frame: the robots with a cell the CPU kernel's checked floor left
undecided (settled exactly).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from jaxfilters import geometry
from jaxfilters.keepout import common, other_frame, prologue, reference
from jaxfilters import mask_lookup
from jaxfilters.types import Costmap, FilterMask


def path_report(costmap: Costmap, mask: FilterMask, transform=None, mask_index=None) -> dict:
  """How many robots each fast-path branch takes on these inputs (counts, a dict)."""
  b, h, w = costmap.cost.shape
  idx, ok, _, en, win, tf = common.batched_inputs(costmap, mask, jnp.zeros((b, 3)), mask_index, None, None,
                                                  transform, "path_report")
  hm, wm = mask.data.shape[1:]
  geo = common.robot_geometry(costmap, mask)
  geo_axes = tuple(None if g is None else 0 for g in geo)

  @jax.jit
  def same_frame(origin, origin_lo, res, res_lo, i, ok, win, en):
    def one(origin, origin_lo, res, res_lo, i, ok, win, en):
      o, r = geometry.origin_terms(origin, origin_lo), geometry.resolution_terms(res, res_lo)
      mo, mr = mask_lookup.mask_origin_terms(mask, i), mask.resolution[i]
      overlap, box, wknown = prologue.box_one((hm, wm), o, r, mo, mr, win)
      exact_overlap, exact_box, _ = prologue.box_one((hm, wm), o, r, mo, mr, win, exact=True)
      overlap, box = jax.tree.map(lambda e, f: jnp.where(wknown, f, e), (exact_overlap, exact_box), (overlap, box))
      run = en & overlap & ok
      box = tuple(jnp.where(run, c, 0) for c in box)
      _, _, sliced, known = prologue.slice_test_one((h, w), o, r, mo, mr, (hm, wm), box)
      exact_sliced = prologue.slice_test_one((h, w), o, r, mo, mr, (hm, wm), box, exact=True)[2]
      return known, wknown, jnp.where(known, sliced, exact_sliced)
    return jax.vmap(one, in_axes=(*geo_axes, 0, 0, 0, 0))(origin, origin_lo, res, res_lo, i, ok, win, en)

  @jax.jit
  def other(origin, origin_lo, res, res_lo, i, win, tf):
    def one(origin, origin_lo, res, res_lo, i, win, tf):
      axes = reference.se2_axes_one(geometry.origin_terms(origin, origin_lo), geometry.resolution_terms(res, res_lo),
                                    tf, h, w)
      code = other_frame.codes_one(axes, i, mask_lookup.mask_origin_terms(mask, i), mask.resolution[i], (hm, wm), win,
                                   True)
      return jnp.any(code == -2)
    return jax.vmap(one, in_axes=(*geo_axes, 0, 0, 0))(origin, origin_lo, res, res_lo, i, win, tf)

  if tf is None:
    known, wknown, sliced = same_frame(*geo, idx, ok, win, en)
    return dict(robots=b, exact_slice_test=int(jnp.sum(~known)), exact_window=int(jnp.sum(~wknown)),
                sliced=int(jnp.sum(sliced)))
  undecided = other(*geo, idx, win, tf)
  return dict(robots=b, robots_with_undecided_cells=int(jnp.sum(undecided)))
