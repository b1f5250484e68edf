// Summed-area tables: box and Bartlett sums against direct summation (float64 tables, with and without
// offset).
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "sim_core/sat.h"

#include "check.h"


int main() {
  const int w = 29, h = 23, c = 2;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> val(0.f, 5.f);
  std::vector<float> img(static_cast<std::size_t>(w) * h * c);
  for (float& v : img) v = val(rng);
  auto at = [&](int x, int y, int k) { return static_cast<double>(img[(static_cast<std::size_t>(y) * w + x) * c + k]); };
  for (int offset = 0; offset < 2; ++offset) {
    sim_core::SummedAreaTable<double> t1(img.data(), w, h, c, 1, offset != 0);
    sim_core::SummedAreaTable<double> t2(img.data(), w, h, c, 2, offset != 0);
    for (int trial = 0; trial < 200; ++trial) {
      int x0 = static_cast<int>(rng() % (w + 1)), x1 = static_cast<int>(rng() % (w + 1));
      int y0 = static_cast<int>(rng() % (h + 1)), y1 = static_cast<int>(rng() % (h + 1));
      if (x0 > x1) std::swap(x0, x1);
      if (y0 > y1) std::swap(y0, y1);
      double got[c];
      t1.box_sum(x0, y0, x1, y1, got);
      for (int k = 0; k < c; ++k) {
        double ref = 0.0;
        for (int y = y0; y < y1; ++y)
          for (int x = x0; x < x1; ++x) ref += at(x, y, k);
        CHECK(std::fabs(got[k] - ref) <= 1e-9 * (1.0 + std::fabs(ref)));
      }
      const int rx = 1 + static_cast<int>(rng() % 6), ry = 1 + static_cast<int>(rng() % 6);
      const int cx = rx - 1 + static_cast<int>(rng() % (w - 2 * rx + 2));
      const int cy = ry - 1 + static_cast<int>(rng() % (h - 2 * ry + 2));
      t2.bartlett_sum(cx, cy, rx, ry, got);
      for (int k = 0; k < c; ++k) {
        double ref = 0.0;
        for (int y = 0; y < h; ++y)
          for (int x = 0; x < w; ++x)
            ref += std::max(0, rx - std::abs(x - cx)) * std::max(0, ry - std::abs(y - cy)) * at(x, y, k);
        CHECK(std::fabs(got[k] - ref) <= 1e-9 * (1.0 + std::fabs(ref)));
      }
    }
  }
  return check_exit_code();
}
