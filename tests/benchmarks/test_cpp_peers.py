"""The C++ keepout peers the benchmarks compare against compute the JAX keepout's integers.

benchmarks/nav2_peer.py builds both peers (the line-by-line copy and the lean loop) with
the same compiler and flags as the harness and checks them against jaxfilters and
reference/nav2.py before any ratio is reported; here the same checks run on small
inputs, in the same frame (aligned and another mask resolution, windows partly off the
mask) and in another frame. Skipped where no C++ compiler exists.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

import jaxfilters as jf
from benchmarks import nav2_peer
from benchmarks import run as bench_run


@pytest.mark.parametrize("source", [nav2_peer.SOURCE, nav2_peer.LEAN_SOURCE], ids=["nav2_copy", "lean"])
@pytest.mark.parametrize("mask_res, transform", [(0.05, False), (0.1, False), (0.05, True)],
                         ids=["aligned", "other_res", "other_frame"])
def test_peer_equals_jax_and_reference(source, mask_res, transform):
  fn, desc = nav2_peer.build(source)
  if fn is None:
    pytest.skip(f"C++ peer unavailable: {desc}")
  cm, mask, tf = bench_run.keepout_inputs(3, 12, 40, 120, mask_res, transform)
  b = cm.num_robots
  out, _ = jf.keepout_filter(cm, mask, jnp.zeros((b, 3), jnp.float32), jf.KeepoutState.create(b), transform=tf)
  inp = nav2_peer.host_inputs(cm, mask, transform=tf)
  note = nav2_peer.check(fn, inp, np.asarray(out.cost))
  assert "equal to JAX on all 12 robots" in note and "reference/nav2.py" in note
  got, _ = nav2_peer.run(fn, inp)
  assert not np.array_equal(got, inp["cost"])         # the peer wrote cells (not an empty loop)


def test_check_rejects_a_peer_result_that_differs():
  fn, desc = nav2_peer.build(nav2_peer.LEAN_SOURCE)
  if fn is None:
    pytest.skip(f"C++ peer unavailable: {desc}")
  cm, mask, _ = bench_run.keepout_inputs(4, 4, 40, 120, 0.05, False)
  inp = nav2_peer.host_inputs(cm, mask)
  want, _ = nav2_peer.run(fn, inp)
  want[1, 5, 7] ^= 1
  with pytest.raises(AssertionError, match="differ at 1 cells"):
    nav2_peer.check(fn, inp, want)
