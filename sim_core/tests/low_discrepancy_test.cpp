// Deterministic low-discrepancy sampling: R2 points in [0, 1)^2 that fill the square evenly, keys that
// differ per sample, and warps that land where they promise (hemisphere, cone, unit disk).
#include <cmath>
#include <cstdint>
#include <set>

#include "sim_core/low_discrepancy.h"

#include "check.h"

using namespace sim_core;

int main() {
  const std::uint32_t key = sample_key(12, 34, 2);
  CHECK(key == sample_key(12, 34, 2));
  CHECK(key != sample_key(34, 12, 2) && key != sample_key(12, 34, 3));
  // 256 R2 points: each of the 16 x 16 cells holds between 0 and 3 of them (evenly spread, not clumped).
  int cells[16][16] = {};
  for (std::uint32_t i = 0; i < 256; ++i) {
    const Sample2 s = r2_sample(key, i);
    CHECK(s.u >= 0.f && s.u < 1.f && s.v >= 0.f && s.v < 1.f);
    ++cells[static_cast<int>(s.u * 16.f)][static_cast<int>(s.v * 16.f)];
  }
  int empty = 0;
  for (auto& row : cells)
    for (int c : row) {
      CHECK(c <= 3);
      empty += c == 0;
    }
  CHECK(empty < 64);
  const Vec3 n = normalize(Vec3(0.3f, -0.2f, 0.9f));
  const float half = 0.25f;
  for (std::uint32_t i = 0; i < 200; ++i) {
    const Sample2 s = r2_sample(key, i);
    const Vec3 h = cosine_hemisphere(s, n);
    CHECK(std::fabs(length(h) - 1.f) < 1e-5f && dot(h, n) >= 0.f);
    const Vec3 c = uniform_cone(s, n, half);
    CHECK(std::fabs(length(c) - 1.f) < 1e-5f && dot(c, n) >= std::cos(half) - 1e-5f);
    float x, y;
    concentric_disk(s, &x, &y);
    CHECK(x * x + y * y <= 1.f + 1e-5f);
  }
  return check_exit_code();
}
