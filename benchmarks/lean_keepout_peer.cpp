// A lean C++ keepout loop for the CPU benchmarks: the per-cell work of Nav2's keepout pass
// (docs/nav2_semantics.md §2, §4.3-§4.4) in one tight loop, one robot after another on one
// core. A stricter peer than the line-by-line copy in nav2_keepout_peer.cpp: no helper calls,
// no update window (the benchmarks visit the whole map), only Nav2's same-frame clip to the
// mask's overlap (a few operations per robot, which keep Nav2's integers at the mask's
// border) and the cell loop: the C++ a performance-minded Nav2 user would write.
//
// Per cell, columns outer and rows inner as in Nav2: the cell centre, the transform into the
// mask frame (different frames only), the bounded mask lookup, getMaskCost and the write
// rule `data != 255 and (data > old or (old == 255 and data >= 253))` (Nav2 main since PR
// #6329). The same C signature as
// nav2_keepout_batch, so benchmarks/nav2_peer.py runs and checks both; the window, the
// lethal-override arguments and `ran` are ignored (the benchmarks visit the whole map).
//
// Built by benchmarks/run.py with `g++ -O2 -ffp-contract=off -shared -fPIC`, called through ctypes.

#include <algorithm>
#include <cmath>
#include <cstdint>

extern "C" {

int lean_keepout_batch(int b, int h, int w, unsigned char* cost, const double* origin,
                       const double* res, const int8_t* masks, int hm, int wm,
                       const int32_t* mask_index, const double* mask_origin,
                       const double* mask_res, const int32_t* /*window*/, const double* transform,
                       const unsigned char* /*is_pose_lethal*/, int /*override_lethal_cost*/,
                       int /*lethal_override_cost*/, unsigned char* /*ran*/) {
  for (int r = 0; r < b; ++r) {
    const int m = mask_index[r];
    const int8_t* mask = masks + static_cast<int64_t>(m) * hm * wm;
    unsigned char* c = cost + static_cast<int64_t>(r) * h * w;
    const double ox = origin[2 * r], oy = origin[2 * r + 1], rs = res[r];
    const double mox = mask_origin[2 * m], moy = mask_origin[2 * m + 1], mres = mask_res[m];
    const bool turn = transform != nullptr;
    const double tx = turn ? transform[3 * r] : 0.0, ty = turn ? transform[3 * r + 1] : 0.0;
    const double ct = turn ? std::cos(transform[3 * r + 2]) : 1.0;
    const double st = turn ? std::sin(transform[3 * r + 2]) : 0.0;
    int x0 = 0, y0 = 0, x1 = w, y1 = h;
    if (!turn) {   // Nav2's clip: worldToMapNoBounds of the mask's corners plus half a mask cell
      const double half = 0.5 * mres;
      x0 = std::max(x0, static_cast<int>((mox + half - ox) / rs));
      y0 = std::max(y0, static_cast<int>((moy + half - oy) / rs));
      x1 = std::min(x1, static_cast<int>((mox + wm * mres + half - ox) / rs));
      y1 = std::min(y1, static_cast<int>((moy + hm * mres + half - oy) / rs));
    }
    for (int i = x0; i < x1; ++i) {
      for (int j = y0; j < y1; ++j) {
        double wx = ox + (i + 0.5) * rs, wy = oy + (j + 0.5) * rs;
        if (turn) {
          const double px = ct * wx - st * wy + tx;
          wy = st * wx + ct * wy + ty;
          wx = px;
        }
        if (!(wx >= mox) || !(wy >= moy)) continue;
        const double qx = (wx - mox) / mres, qy = (wy - moy) / mres;
        if (!(qx < wm) || !(qy < hm)) continue;
        const int8_t v = mask[static_cast<int64_t>(qy) * wm + static_cast<int64_t>(qx)];
        if (v < 0 || v > 100) continue;                 // unknown: NO_INFORMATION is never written
        const unsigned char data = static_cast<unsigned char>(std::round(v * 254.0 / 100.0));
        unsigned char& old = c[j * w + i];
        if (data > old || (old == 255 && data >= 253)) old = data;
      }
    }
  }
  return b;
}

}  // extern "C"
