"""Grid geometry: world -> cell with Nav2's float64 results from float32 arithmetic.

Float32 policy
--------------
Poses, origins and resolutions live on the device as float32. Nav2 computes
`floor((w - o) / res)` in float64; float32 division can round a quotient such as
2.9999999 up to 3.0 and move a point into the next cell (docs/nav2_semantics.md §2.2: 0.3 / 0.1).
jaxfilters never trusts a rounded quotient for a cell index. Each index is the
*exact* floor of the real-number quotient of the float32 inputs:

1. the numerator is kept as a list of float32 terms whose exact sum is the
   numerator (products are split with bit masks into 12-bit halves, so every
   partial product is exact, with or without FMA contraction);
2. a float32 estimate q0 of the quotient is corrected to the exact floor by the
   exact sign of `num - q * res`, evaluated as a Shewchuk expansion with
   error-free two-sums.

For float32 inputs with |quotient| < 2**22 (20 km at 5 mm cells) this equals
float64 arithmetic on the same float32 values, which is what Nav2 computes when
given those values (tests/jaxfilters/test_geometry.py proves it with hypothesis up to
10 km, including points placed exactly on cell boundaries). XLA flushes
subnormal float32 values to zero, so the guarantee holds for inputs that are 0
or at least 1e-30 in magnitude (no error term of the arithmetic is subnormal). Host-side float64
values (YAML origins such as -15.1, a costmap resolution of 0.05) are *not*
rounded: `validate.split_float64` splits each into three float32 parts whose exact sum
is the double (24 + 24 + 5 bits cover its 53), and the exact arithmetic takes
the parts as extra terms. So a floor decided from Nav2's doubles (the costmap
origin and resolution, the mask origin; the mask resolution is float32 in
nav_msgs) is the floor Nav2 computes (docs/nav2_semantics.md §4.3's coarse-mask example: 21 with
the decimal 0.05). Poses stay float32 inputs.

Layout: `exact` (error-free sums and products, expansions, exact signs and
floors), `cells` (world -> cell, cell centres), `fast` (fast paths), `edges`
(edge tables); every name is imported here, so callers write
`geometry.world_to_cell`. Beside the floors: `exact_sign` (signs of long sums of stacked terms, used by
the shape rasteriser), `floor_quotient` (its clipped floor), `exact_sign_affine`
(the filters' `d * multiplier + base` comparisons), fast paths that decide the
same integers with far fewer operations and say where they could not, and edge
tables (exact floors by two float32 comparisons).
"""

from jaxfilters.geometry.exact import (as_terms, exact_product, exact_sign, exact_sign_affine,
                                       expansion, expansion_sign, fixed_point_sign,
                                       floor_div_exact, floor_quotient, split12, stack_terms,
                                       trunc_div_exact, two_sum)
from jaxfilters.geometry.cells import (cell_centre_terms, centres_to_cells_2d, origin_terms,
                                       resolution_terms, transform_points, world_to_cell)
from jaxfilters.geometry.fast import (centre_floor_bracket, floor_bracket, floor_div_checked,
                                      quotient_bracket, rounded_product, world_to_cell_checked,
                                      world_to_index_checked)
from jaxfilters.geometry.edges import (edge_reciprocal, edge_thresholds, float32_key,
                                       floor_by_edges, key_float32)

__all__ = ['as_terms', 'cell_centre_terms', 'centre_floor_bracket', 'centres_to_cells_2d',
           'edge_reciprocal', 'edge_thresholds', 'exact_product', 'exact_sign', 'exact_sign_affine',
           'expansion', 'expansion_sign', 'fixed_point_sign', 'float32_key', 'floor_bracket',
           'floor_by_edges', 'floor_div_checked', 'floor_div_exact', 'floor_quotient',
           'key_float32', 'origin_terms', 'quotient_bracket', 'resolution_terms', 'rounded_product',
           'split12', 'stack_terms', 'transform_points', 'trunc_div_exact', 'two_sum',
           'world_to_cell', 'world_to_cell_checked', 'world_to_index_checked']
