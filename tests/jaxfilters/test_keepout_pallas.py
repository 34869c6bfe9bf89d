"""The Pallas keepout kernel (jaxfilters.keepout.pallas) gives the XLA aligned path's integers.

On CPU the kernel runs in the Pallas interpreter (`PallasTuning(interpret=True)`):
the same kernel program, discharged to XLA, so its indexing, masks and write rule
are checked here (the compiled Triton kernel runs on a GPU only). References: a NumPy
loop over robots written from Nav2's rule (mask costs from reference/nav2.py, no shared
code), the XLA aligned kernels (`same_frame.aligned_one`, `same_frame.aligned_packed_one`),
the exact per-cell path and the float64 reference `reference.keepout_process`.
"""

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from jaxfilters import keepout as ko
from jaxfilters.keepout import common, packed, same_frame
from benchmarks.keepout_paths import path_report
from jaxfilters.keepout import pallas as kp
from jaxfilters.grid import OccupancyGrid
from jaxfilters.keepout import PallasTuning
from jaxfilters.types import Costmap, FilterInfo, FilterMask
from reference import nav2 as reference
from tests.compile_count import count_compiles

INT8 = np.arange(-128, 128)
LUT = np.asarray([reference.mask_cost(v) for v in INT8])      # mask cost of int8 d at LUT[d + 128]


# ----------------------------------------------------------------------------- the kernel alone


def _kernel_case(seed, b, h, w, m=2, hm=23, wm=31):
  """Random kernel inputs: every cost byte, every int8 mask value, windows on, across and off the mask."""
  rng = np.random.default_rng(seed)
  cost = rng.integers(0, 256, (b, h, w), dtype=np.uint8)
  cost[:, ::3, ::5] = 255                                       # plenty of unknown old cells
  data = rng.choice(np.concatenate([INT8, np.arange(0, 101)]), (m, hm, wm)).astype(np.int8)
  idx = rng.integers(0, m, b)
  # Window starts over the whole padded table: wholly off, across the edge, inside.
  sx = rng.integers(0, wm + w + 1, b)
  sy = rng.integers(0, hm + h + 1, b)
  sx[0], sy[0] = w, h                                           # robot 0 starts at mask cell (0, 0)
  x = np.sort(rng.integers(-2, w + 3, (2, b)), axis=0)
  y = np.sort(rng.integers(-2, h + 3, (2, b)), axis=0)
  x[:, 0], y[:, 0] = (0, w), (0, h)                             # robot 0: the whole map
  x[:, 1] = (w // 2, w // 2)                                    # robot 1: an empty window
  x[:, 2], y[:, 2] = (w // 4, 3 * w // 4), (h // 3, h - 2)      # robot 2: inside the map on all sides
  sx[2], sy[2] = w - w // 4 + 5, h - h // 3 + 5                 # ... its low corner on the mask
  take = rng.random(b) < 0.8
  take[0] = take[2] = True
  lethal = rng.random(b) < 0.5
  return cost, data, idx, sx, sy, np.clip(x, 0, w), np.clip(y, 0, h), take, lethal


def _numpy_kernel(cost, data, idx, sx, sy, x, y, take, lethal, *, escape, lethal_cost):
  """Nav2's rule cell by cell (vectorised per robot) on the window's mask cells, from int8 data."""
  b, h, w = cost.shape
  _, hm, wm = data.shape
  out = cost.astype(np.int64)
  for r in range(b):
    if not take[r]:
      continue
    jj, kk = np.meshgrid(np.arange(h), np.arange(w), indexing="ij")
    my, mx = sy[r] + jj - h, sx[r] + kk - w                     # the table is the mask padded by (H, W)
    on = (my >= 0) & (my < hm) & (mx >= 0) & (mx < wm)
    mc = np.where(on, LUT[data[idx[r], np.clip(my, 0, hm - 1), np.clip(mx, 0, wm - 1)].astype(np.int64) + 128], 255)
    visit = (kk >= x[0, r]) & (kk < x[1, r]) & (jj >= y[0, r]) & (jj < y[1, r])
    old = out[r]
    write = visit & (mc != 255) & ((mc > old) | ((old == 255) & (mc >= 253)))   # Nav2 main (PR #6329)
    out[r] = np.where(write, lethal_cost if (escape and lethal[r]) else mc, old)
  return out.astype(np.uint8)


def _flags(x, y, h, w):
  cols, rows = np.arange(w), np.arange(h)
  return (jnp.asarray((cols >= x[0][:, None]) & (cols < x[1][:, None])),
          jnp.asarray((rows >= y[0][:, None]) & (rows < y[1][:, None])))


@functools.lru_cache(maxsize=None)
def _jitted_write(escape, lethal_cost, tuning):
  return jax.jit(functools.partial(kp.aligned_write, escape=escape, lethal_cost=lethal_cost, tuning=tuning))


TUNINGS = [PallasTuning(layout="flat", interpret=True),                           # flat, several rows per program
           PallasTuning(layout="flat", block_cells=64, in_place=True, interpret=True),  # flat, one row (or part)
           PallasTuning(layout="rows", block_cells=256, interpret=True),
           PallasTuning(layout="rows", block_cells=2048, in_place=True, interpret=True)]


@pytest.mark.parametrize("shape", [(4, 37, 53), (3, 200, 200)], ids=["37x53", "200x200"])
@pytest.mark.parametrize("t", range(len(TUNINGS)), ids=lambda t: f"{TUNINGS[t].layout}{TUNINGS[t].block_cells}"
                         + ("_in_place" if TUNINGS[t].in_place else ""))
def test_kernel_equals_numpy_and_xla_aligned_path(shape, t):
  b, h, w = shape
  tuning = TUNINGS[t]
  escape = bool((t + h) % 2)           # escape mode on for half of the cases, off for the others
  lethal_cost = 77
  cost, data, idx, sx, sy, x, y, take, lethal = _kernel_case(10 * t + h, b, h, w)
  table = common.cost_plus_one_table(jnp.asarray(data), h, w)
  col_ok, row_ok = _flags(x, y, h, w)
  params = kp.slice_params(jnp.asarray(idx), jnp.asarray(sx), jnp.asarray(sy), col_ok, row_ok, jnp.asarray(take),
                           jnp.asarray(lethal))
  got = np.asarray(_jitted_write(escape, lethal_cost, tuning)(jnp.asarray(cost), table, params))

  want = _numpy_kernel(cost, data, idx, sx, sy, x, y, take, lethal, escape=escape, lethal_cost=lethal_cost)
  np.testing.assert_array_equal(got, want)
  assert np.count_nonzero(want != cost) > 20, "the case must exercise the write rule"

  config = ko.KeepoutConfig(override_lethal_cost=escape, lethal_override_cost=lethal_cost)
  state = dataclasses.replace(ko.KeepoutState.create(b), is_pose_lethal=jnp.asarray(lethal))
  rows_taken = row_ok & jnp.asarray(take)[:, None]
  xla = jax.vmap(lambda c, i, a, s, co, ro, st: same_frame.aligned_one(c, table, i, a, s, co, ro, st, config=config))(
      jnp.asarray(cost), jnp.asarray(idx), jnp.asarray(sx), jnp.asarray(sy), col_ok, rows_taken, state)
  np.testing.assert_array_equal(got, np.asarray(xla))
  if w % 4 == 0:    # the packed (uint32 SWAR) XLA kernel, the GPU's XLA choice
    words = packed.shifted_words(table)
    by_words = jax.vmap(lambda c, i, a, s, co, ro, st: same_frame.aligned_packed_one(c, words, i, a, s, co, ro, st,
                                                                                    config=config))(
        jnp.asarray(cost), jnp.asarray(idx), jnp.asarray(sx), jnp.asarray(sy), col_ok, rows_taken, state)
    np.testing.assert_array_equal(got, np.asarray(by_words))


def test_slice_params_are_the_window_bounds():
  x = np.asarray([[0, 3, 5, 2], [7, 3, 9, 2]])        # robot 1: empty columns; robot 3: empty (x0 == x1)
  y = np.asarray([[1, 0, 0, 4], [4, 6, 6, 6]])
  col_ok, row_ok = _flags(x, y, 6, 9)
  take = jnp.asarray([True, True, False, True])
  p = np.asarray(kp.slice_params(jnp.arange(4), jnp.arange(4) + 10, jnp.arange(4) + 20, col_ok, row_ok, take,
                                 jnp.asarray([True, False, True, False])))
  np.testing.assert_array_equal(p, [[0, 10, 20, 0, 7, 1, 4, 1],
                                    [1, 11, 21, 0, 0, 0, 0, 0],     # nothing to write: y0 == y1 == 0
                                    [2, 12, 22, 5, 9, 0, 0, 1],     # not taken
                                    [3, 13, 23, 0, 0, 0, 0, 0]])


def test_large_batches_run_in_chunks(monkeypatch):
  b, h, w = 5, 9, 13
  cost, data, idx, sx, sy, x, y, take, lethal = _kernel_case(7, b, h, w)
  table = common.cost_plus_one_table(jnp.asarray(data), h, w)
  col_ok, row_ok = _flags(x, y, h, w)
  params = kp.slice_params(jnp.asarray(idx), jnp.asarray(sx), jnp.asarray(sy), col_ok, row_ok, jnp.asarray(take),
                           jnp.asarray(lethal))
  # Pretend 2 robots' costmaps reach the 32-bit offset limit: 3 calls (2, 2, 1 robots).
  monkeypatch.setattr(kp, "_MAX_COST_BYTES", 2 * h * w + 1)
  run = functools.partial(kp.aligned_write, escape=False, lethal_cost=0, tuning=PallasTuning(interpret=True))
  text = str(jax.make_jaxpr(run)(jnp.asarray(cost), table, params))
  assert text.count("pallas_call") == 3
  got = np.asarray(run(jnp.asarray(cost), table, params))
  want = _numpy_kernel(cost, data, idx, sx, sy, x, y, take, lethal, escape=False, lethal_cost=0)
  np.testing.assert_array_equal(got, want)


def test_kernel_refuses_bad_operands():
  cost, table, params = jnp.zeros((2, 4, 5), jnp.uint8), jnp.zeros((1, 8, 10), jnp.uint8), jnp.zeros((2, 8), jnp.int32)
  run = functools.partial(kp.aligned_write, escape=False, lethal_cost=0, tuning=PallasTuning(interpret=True))
  with pytest.raises(ValueError, match="cost must be uint8"):
    run(cost.astype(jnp.int8), table, params)
  with pytest.raises(ValueError, match=r"table must be uint8 \[M, Hm \+ 2H, Wm \+ 2W\]"):
    run(cost, table[:, :7], params)
  with pytest.raises(ValueError, match=r"params must be int32 \[2, 8\]"):
    run(cost, table, params[:1])
  with pytest.raises(ValueError, match=r"lethal_cost must be a cost in \[0, 255\]"):
    kp.aligned_write(cost, table, params, escape=True, lethal_cost=256, tuning=PallasTuning(interpret=True))


@pytest.mark.parametrize("layout", kp.LAYOUTS)
def test_kernel_lowers_to_triton_for_cuda(layout):
  """The kernel is a valid Triton program (power-of-two blocks, supported ops), lowered here without a GPU."""
  cost = jax.ShapeDtypeStruct((8, 200, 200), jnp.uint8)
  table = jax.ShapeDtypeStruct((1, 2400, 2400), jnp.uint8)
  params = jax.ShapeDtypeStruct((8, kp.NUM_PARAMS), jnp.int32)
  run = functools.partial(kp.aligned_write, escape=True, lethal_cost=200,
                          tuning=PallasTuning(layout=layout, in_place=True))
  text = jax.jit(run, donate_argnums=0).trace(cost, table, params).lower(lowering_platforms=("cuda",)).as_text()
  assert "triton" in text
  assert "output_operand_alias" in text or "operand_output_alias" in text or "tf.aliasing_output" in text


# ----------------------------------------------------------------------------- through keepout_filter


def _fleet(seed, b=6, h=21, w=44, hm=30, wm=40, *, other_res=()):
  """A same-frame fleet on one or two masks; robots listed in `other_res` use twice the mask's resolution."""
  rng = np.random.default_rng(seed)
  res = 0.05
  data = rng.choice(np.concatenate([INT8, np.arange(0, 101), np.arange(0, 101)]), (2, hm, wm)).astype(np.int8)
  grids = [OccupancyGrid.create(np.clip(d, -1, 100), res, (1.0, -2.0)) for d in data]
  mask = FilterMask.create(grids, FilterInfo.create(0)).with_data(data)
  k = rng.integers(-w - 3, wm + 3, (b, 2))
  k[0] = (2, 3)                                                       # robot 0 over the mask
  # float32 geometry, so the float64 reference sees exactly the device's values (2 * res puts
  # cell centres exactly on mask-cell edges).
  origin = (np.asarray([1.0, -2.0]) + k * res).astype(np.float32)
  resolution = np.full(b, res, np.float32)
  resolution[list(other_res)] = np.float32(2 * res)
  cost = rng.integers(0, 256, (b, h, w), dtype=np.uint8)
  cm = Costmap.create(cost, origin, resolution)
  x0, y0 = rng.integers(-2, w // 2, b), rng.integers(-2, h // 2, b)
  window = np.stack([x0, y0, x0 + rng.integers(1, w + 3, b), y0 + rng.integers(1, h + 3, b)], 1).astype(np.int32)
  window[0] = (0, 0, w, h)
  state = dataclasses.replace(ko.KeepoutState.create(b), is_pose_lethal=jnp.asarray(rng.random(b) < 0.5))
  enabled = rng.random(b) < 0.8
  enabled[0] = True
  return cm, mask, state, window, rng.integers(0, 2, b).astype(np.int32), jnp.asarray(enabled)


@functools.lru_cache(maxsize=None)
def _filter(config):
  @jax.jit
  def run(cm, mask, state, window, mask_index, enabled):
    out, st = ko.keepout_filter(cm, mask, jnp.zeros((cm.num_robots, 3)), state, mask_index=mask_index,
                                enabled=enabled, window=window, config=config)
    return out.cost, st
  return run


def _reference_fleet(cm, mask, state, window, mask_index, enabled, config):
  """reference.keepout_process robot by robot (a mask_index out of range: untouched)."""
  out = []
  for r in range(cm.num_robots):
    i = int(mask_index[r])
    if not 0 <= i < mask.data.shape[0]:
      out.append(np.asarray(cm.cost[r]))
      continue
    want, _ = reference.keepout_process(np.asarray(cm.cost[r]), np.asarray(cm.origin[r]),
                                        np.asarray(cm.resolution[r]), np.asarray(mask.data[i]),
                                        np.asarray(mask.origin[i]), np.asarray(mask.resolution[i]),
                                        np.clip(window[r], 0, [cm.cost.shape[2], cm.cost.shape[1]] * 2),
                                        is_pose_lethal=bool(state.is_pose_lethal[r]),
                                        override=config.override_lethal_cost,
                                        override_cost=config.lethal_override_cost, enabled=bool(enabled[r]))
    out.append(want)
  return np.stack(out)


FLEETS = [dict(), dict(other_res=(1, 4)), dict(other_res=tuple(range(6)))]   # all sliced, some, none


@pytest.mark.parametrize("config", [
    ko.KeepoutConfig(override_lethal_cost=True, lethal_override_cost=120, kernel="pallas",
                     pallas=PallasTuning(interpret=True)),
    ko.KeepoutConfig(kernel="pallas", pallas=PallasTuning(layout="rows", in_place=True, interpret=True))],
    ids=["flat_escape", "rows_in_place"])
def test_filter_with_pallas_equals_float64_reference(config):
  """Through `keepout_filter` (one compiled program per config for all fleets): the kernel takes
  the sliced robots, the gather the others (robots at another resolution); disabled robots and a
  traced mask_index out of range are left untouched, the latter flagged."""
  run = _filter(config)
  changed = recompiles = 0
  for seed, kwargs in enumerate(FLEETS):
    cm, mask, state, window, mask_index, enabled = _fleet(seed, **kwargs)
    mask_index[3] = 2                                                   # M = 2: out of range
    with count_compiles() as compiles:
      got, st = run(cm, mask, state, window, mask_index, enabled)
    recompiles += compiles() if seed else 0                             # the first fleet compiles
    want = _reference_fleet(cm, mask, state, window, mask_index, enabled, config)
    np.testing.assert_array_equal(np.asarray(got), want, err_msg=f"fleet {kwargs}")
    np.testing.assert_array_equal(np.asarray(st.error), np.arange(6) == 3)
    sliced = path_report(cm, mask, mask_index=np.where(mask_index < 2, mask_index, 0))["sliced"]
    # Robots at another resolution are gathered, unless their window reads no mask cell
    # (wholly off the mask: then the slice reads only padding, and is taken).
    other = len(kwargs.get("other_res", ()))
    assert 6 - other <= sliced < 6 if other else sliced == 6, "the fleet must take the intended paths"
    changed += int(np.count_nonzero(want != np.asarray(cm.cost)))
  assert changed > 200
  assert recompiles == 0, "new fleets of the same shapes must not recompile"


# ----------------------------------------------------------------------------- selection and options


def test_kernel_option_is_validated():
  with pytest.raises(ValueError, match=r"kernel must be one of \('auto', 'xla', 'pallas'\); got 'triton'"):
    ko.KeepoutConfig(kernel="triton")
  with pytest.raises(ValueError, match=r"kernel must be one of \('auto', 'xla', 'pallas'\); got 'cuda'"):
    ko.KeepoutConfig(frame_kernel="cuda")
  with pytest.raises(ValueError, match="pallas must be a keepout.pallas.PallasTuning; got dict"):
    ko.KeepoutConfig(pallas={"layout": "flat"})
  for kwargs, message in [(dict(layout="tiles"), r"layout must be one of \('flat', 'rows'\); got 'tiles'"),
                          (dict(block_cells=1000), r"block_cells must be a power of two in \[16, 65536\]; got 1000"),
                          (dict(block_cells=True), "block_cells must be a power of two"),
                          (dict(frame_block_cells=100), r"frame_block_cells must be a power of two in \[16, 65536\]; got 100"),
                          (dict(num_warps=3), "num_warps must be one of 1, 2, 4, 8, 16, 32; got 3"),
                          (dict(frame_num_warps=64), "frame_num_warps must be one of 1, 2, 4, 8, 16, 32; got 64"),
                          (dict(num_stages=0), r"num_stages must be an int in \[1, 8\]; got 0"),
                          (dict(in_place=1), "in_place must be a bool; got 1"),
                          (dict(interpret="yes"), "interpret must be a bool; got 'yes'")]:
    with pytest.raises(ValueError, match=message):
      PallasTuning(**kwargs)
  assert hash(ko.KeepoutConfig(kernel="pallas")) == hash(ko.KeepoutConfig(kernel="pallas"))


def test_selection_by_backend():
  tuning, interp = PallasTuning(), PallasTuning(interpret=True)
  assert not kp.use_pallas("xla", tuning, backend="gpu")
  assert kp.use_pallas("auto", tuning, backend="gpu")
  assert not kp.use_pallas("auto", tuning, backend="cpu")
  assert not kp.use_pallas("auto", interp, backend="cpu")            # auto never picks the interpreter
  assert not kp.use_pallas("auto", tuning, table_bytes=1 << 31, backend="gpu")
  assert kp.use_pallas("pallas", tuning, backend="gpu")
  assert kp.use_pallas("pallas", interp, backend="cpu")
  with pytest.raises(ValueError, match="needs a GPU backend.*the default backend is 'cpu'.*interpret=True"):
    kp.use_pallas("pallas", tuning, backend="cpu")
  with pytest.raises(ValueError, match="must be < 2 GiB; got 2147483648 bytes"):
    kp.use_pallas("pallas", tuning, table_bytes=1 << 31, backend="gpu")


@pytest.mark.parametrize("kernel", ["pallas", "auto"])
def test_other_frame_interpreter_on_a_gpu_is_refused(kernel):
  """On an H200 the interpreter of the other-frame kernel gave other cells than the compiled kernel, the
  XLA loop and the exact path (which agree): a wrong result with no error, so it is refused."""
  interp = PallasTuning(interpret=True)
  with pytest.raises(ValueError, match=r"interpret=True\) with the other-frame Pallas kernel on a GPU backend"):
    kp.use_pallas(kernel, interp, backend="gpu", field="frame_kernel")
  assert kp.use_pallas("pallas", interp, backend="cpu", field="frame_kernel")       # the CPU's interpreter is exact
  assert kp.use_pallas(kernel, PallasTuning(), backend="gpu", field="frame_kernel")  # the compiled kernel


def test_filter_entry_point_picks_the_kernel():
  cm, mask, state, window, mask_index, enabled = _fleet(3, b=2, h=5, w=6)
  jaxpr = lambda config: str(jax.make_jaxpr(lambda c: ko.keepout_filter(
      c, mask, jnp.zeros((2, 3)), state, mask_index=mask_index, config=config)[0].cost)(cm))
  assert "pallas_call" in jaxpr(ko.KeepoutConfig(kernel="pallas", pallas=PallasTuning(interpret=True)))
  assert "pallas_call" not in jaxpr(ko.KeepoutConfig())
  on_gpu = jax.default_backend() == "gpu"
  assert ("pallas_call" in jaxpr(ko.KeepoutConfig(kernel="auto"))) == on_gpu
  if on_gpu:
    assert "pallas_call" in jaxpr(ko.KeepoutConfig(kernel="pallas"))
  else:   # no silent slow path: the compiled kernel needs a GPU
    with pytest.raises(ValueError, match="kernel='pallas'.*needs a GPU backend"):
      ko.keepout_filter(cm, mask, jnp.zeros((2, 3)), state, config=ko.KeepoutConfig(kernel="pallas"),
                        mask_index=mask_index)
