// A Nav2-style C++ peer for the keepout benchmarks: KeepoutFilter::process as a per-cell
// loop in doubles, one robot after another on one core (docs/nav2_semantics.md §2, §4.3-§4.4).
//
// Written for this project from docs/nav2_semantics.md; it is what one Nav2 costmap thread does per
// cycle, repeated for a fleet of B costmaps:
//   * same frame: the window is clipped to the mask's overlap with worldToMapNoBounds of the
//     mask's corners plus the mask's half cell (an early return leaves the costmap as is);
//     different frames: the whole [min_i, max_i) x [min_j, max_j) window is visited;
//   * per cell, columns outer and rows inner like Nav2: mapToWorld (the cell centre),
//     the transform R(yaw) p + t into the mask frame (different frames only), the bounded
//     worldToMap on the mask, getMaskCost (round(2.54 d), -1 -> 255), and the write rule
//     `data != 255 and (data > old or (old == 255 and data >= 253))` (Nav2 main since PR #6329),
//     writing lethal_override_cost in escape mode.
// Nav2's tf2 rotates with a matrix built from a quaternion; this peer uses cos/sin of the
// yaw like reference/nav2.py, so its integers can be checked against the reference bit for
// bit (the work per cell is the same: 4 multiplies and 4 adds).
//
// Built by benchmarks/run.py with `g++ -O2 -ffp-contract=off -shared -fPIC` (no FMA
// contraction, so every product and sum is rounded like the float64 reference) and called
// through ctypes.

#include <cmath>
#include <cstdint>

namespace {

constexpr unsigned char kNoInformation = 255;
constexpr unsigned char kInscribed = 253;   // INSCRIBED_INFLATED_OBSTACLE

// getMaskCost (docs/nav2_semantics.md §1.4): OccupancyGrid value -> cost; unknown (-1), and values outside
// 0..100 (undefined in Nav2, unknown in jaxfilters), give NO_INFORMATION.
inline unsigned char MaskCost(int8_t d) {
  if (d < 0 || d > 100) return kNoInformation;
  return static_cast<unsigned char>(std::round(static_cast<double>(d) * 254.0 / 100.0));
}

// Costmap2D::worldToMapNoBounds: a signed cast, which truncates toward zero.
inline int WorldToMapNoBounds(double w, double origin, double res) {
  return static_cast<int>((w - origin) / res);
}

// nav2_util::worldToMap on the mask: the half-open box [o, o + size * res). The `!(w >= o)`
// form also rejects NaN, and the quotient is compared before the unsigned cast (Nav2 casts
// first; the results agree wherever the cast is defined).
inline bool WorldToMask(double wx, double wy, double ox, double oy, double res, int w, int h,
                        int* mx, int* my) {
  if (!(wx >= ox) || !(wy >= oy)) return false;
  const double qx = (wx - ox) / res;
  const double qy = (wy - oy) / res;
  if (!(qx < w) || !(qy < h)) return false;
  *mx = static_cast<int>(qx);
  *my = static_cast<int>(qy);
  return true;
}

// KeepoutFilter::process for one costmap. Returns 1 if it ran to the end, 0 on an early return.
int ProcessOne(unsigned char* cost, int h, int w, double ox, double oy, double res,
               const int8_t* mask, int hm, int wm, double mox, double moy, double mres,
               const int32_t* window, const double* transform, bool override_now,
               unsigned char override_cost) {
  int x0 = window[0], y0 = window[1], x1 = window[2], y1 = window[3];
  // LayeredCostmap clips the window to the map before the filters run.
  if (x0 < 0) x0 = 0;
  if (y0 < 0) y0 = 0;
  if (x1 > w) x1 = w;
  if (y1 > h) y1 = h;
  const int min_i = x0, min_j = y0;
  double c = 1.0, s = 0.0, tx = 0.0, ty = 0.0;
  if (transform != nullptr) {
    tx = transform[0];
    ty = transform[1];
    c = std::cos(transform[2]);
    s = std::sin(transform[2]);
  } else {
    const double half = 0.5 * mres;
    int gx0 = WorldToMapNoBounds(mox + half, ox, res);
    int gy0 = WorldToMapNoBounds(moy + half, oy, res);
    if (gx0 >= x1 || gy0 >= y1) return 0;
    if (gx0 > x0) x0 = gx0;
    if (gy0 > y0) y0 = gy0;
    int gx1 = WorldToMapNoBounds(mox + wm * mres + half, ox, res);
    int gy1 = WorldToMapNoBounds(moy + hm * mres + half, oy, res);
    if (gx1 <= min_i || gy1 <= min_j) return 0;
    if (gx1 < x1) x1 = gx1;
    if (gy1 < y1) y1 = gy1;
  }
  for (int i = x0; i < x1; ++i) {
    for (int j = y0; j < y1; ++j) {
      const int index = j * w + i;
      const unsigned char old = cost[index];
      double wx = ox + (i + 0.5) * res;  // Costmap2D::mapToWorld
      double wy = oy + (j + 0.5) * res;
      if (transform != nullptr) {
        const double px = c * wx - s * wy + tx;
        const double py = s * wx + c * wy + ty;
        wx = px;
        wy = py;
      }
      int mx, my;
      if (!WorldToMask(wx, wy, mox, moy, mres, wm, hm, &mx, &my)) continue;
      const unsigned char data = MaskCost(mask[static_cast<int64_t>(my) * wm + mx]);
      if (data == kNoInformation) continue;
      if (data > old || (old == kNoInformation && data >= kInscribed)) {
        cost[index] = override_now ? override_cost : data;
      }
    }
  }
  return 1;
}

}  // namespace

extern "C" {

// Runs KeepoutFilter::process for B robots in turn, in place.
//
// cost: uint8 [B, H, W], modified in place. origin: float64 [B, 2]; res: float64 [B].
// masks: int8 [M, Hm, Wm]; mask_index: int32 [B] (which mask each robot uses);
// mask_origin: float64 [M, 2]; mask_res: float64 [M] (the float32 message value, widened).
// window: int32 [B, 4] (min_i, min_j, max_i, max_j) half-open. transform: float64 [B, 3]
// (x, y, yaw) T_mask_from_global, or null for the same frame. is_pose_lethal: uint8 [B] or
// null. ran: uint8 [B] out (1 if process() reached its loop), or null.
// Returns the number of robots whose process() ran to the end.
int nav2_keepout_batch(int b, int h, int w, unsigned char* cost, const double* origin,
                       const double* res, const int8_t* masks, int hm, int wm,
                       const int32_t* mask_index, const double* mask_origin,
                       const double* mask_res, const int32_t* window, const double* transform,
                       const unsigned char* is_pose_lethal, int override_lethal_cost,
                       int lethal_override_cost, unsigned char* ran) {
  int count = 0;
  for (int r = 0; r < b; ++r) {
    const int m = mask_index[r];
    const bool override_now = override_lethal_cost && is_pose_lethal != nullptr && is_pose_lethal[r];
    const int done = ProcessOne(cost + static_cast<int64_t>(r) * h * w, h, w, origin[2 * r],
                                origin[2 * r + 1], res[r], masks + static_cast<int64_t>(m) * hm * wm,
                                hm, wm, mask_origin[2 * m], mask_origin[2 * m + 1], mask_res[m],
                                window + 4 * r, transform == nullptr ? nullptr : transform + 3 * r,
                                override_now, static_cast<unsigned char>(lethal_override_cost));
    if (ran != nullptr) ran[r] = static_cast<unsigned char>(done);
    count += done;
  }
  return count;
}

}  // extern "C"
