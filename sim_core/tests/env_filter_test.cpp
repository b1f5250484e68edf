// The glossy environment filter: a constant map filters to the constant for any cone and either order; the
// equirectangular mapping and its inverse agree.
#include <cmath>
#include <vector>

#include "sim_core/env_filter.h"

#include "check.h"

int main() {
  {  // A constant map filters to the constant for any cone and either order.
    std::vector<float> env(16 * 32 * 3, 0.25f);
    for (int order = 1; order <= 2; ++order) {
      sim_core::EnvironmentFilter f(env.data(), 32, 16, order);
      for (float cone : {0.f, 0.05f, 0.4f, 1.5f}) {
        const sim_core::Vec3 v = f.lookup(sim_core::Vec3(0.3f, -0.5f, 0.8f), cone);
        CHECK(std::fabs(v.x - 0.25f) < 1e-5f && std::fabs(v.z - 0.25f) < 1e-5f);
      }
    }
  }
  for (float row : {0.5f, 3.25f, 8.f, 15.5f})
    for (float col : {0.25f, 7.5f, 16.f, 31.75f}) {
      float c, r;
      sim_core::equirect_pixel(sim_core::equirect_direction(col, row, 32, 16), 32, 16, &c, &r);
      CHECK(std::fabs(c - col) < 1e-3f && std::fabs(r - row) < 1e-3f);
    }
  return check_exit_code();
}
