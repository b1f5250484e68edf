// Streaming traversal finds exactly the per-ray closest hits on a random triangle soup, fetches fewer
// nodes, and a one-ray stream costs what a lone ray costs.
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "sim_core/streaming.h"

#include "check.h"


int main() {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  const std::size_t ntri = 400;
  std::vector<float> pos;
  std::vector<std::uint32_t> tris;
  std::vector<std::int64_t> prim;
  for (std::size_t i = 0; i < ntri; ++i) {
    const float cx = u(rng) * 5.f, cy = u(rng) * 5.f, cz = u(rng) * 5.f;
    for (int k = 0; k < 3; ++k) {
      pos.push_back(cx + u(rng) * 0.5f);
      pos.push_back(cy + u(rng) * 0.5f);
      pos.push_back(cz + u(rng) * 0.5f);
      tris.push_back(static_cast<std::uint32_t>(3 * i + k));
    }
    prim.push_back(static_cast<std::int64_t>(i));
  }
  const float material[sim_core::kMaterialFields] = {0.8f, 0.8f, 0.8f, 0.f, 0.5f, 0.f, 1.5f,
                                                     0.f,  0.f,  0.f,  1.f, 0.f, 0.5f, -1.f};
  sim_core::Scene scene(pos.data(), pos.size() / 3, tris.data(), ntri, prim.data(), nullptr, nullptr, nullptr,
                        material, 1, nullptr, 0, sim_core::Environment(sim_core::Vec3(0.f, 0.f, 0.f)));
  std::vector<sim_core::Ray> rays(2000);
  for (auto& r : rays) {
    r.origin = sim_core::Vec3(0.f, 0.f, -12.f);
    r.dir = sim_core::normalize(sim_core::Vec3(u(rng) * 0.5f, u(rng) * 0.5f, 1.f));
  }
  std::vector<sim_core::Hit> a(rays.size()), b(rays.size());
  const auto ta = sim_core::per_ray_traversal(scene, rays.data(), rays.size(), a.data());
  const auto tb = sim_core::streaming_traversal(scene, rays.data(), rays.size(), b.data());
  int hits = 0;
  for (std::size_t i = 0; i < rays.size(); ++i) {
    CHECK(a[i].t == b[i].t || (std::isinf(a[i].t) && std::isinf(b[i].t)));
    if (a[i].hit()) { ++hits; CHECK(b[i].hit()); }
  }
  CHECK(hits > 100);
  CHECK(tb.node_fetches < ta.node_fetches);
  CHECK(tb.triangle_fetches < ta.triangle_fetches);
  for (std::size_t i = 0; i < 50; ++i) {
    sim_core::Hit h1, h2;
    const auto s1 = sim_core::per_ray_traversal(scene, &rays[i], 1, &h1);
    const auto s2 = sim_core::streaming_traversal(scene, &rays[i], 1, &h2);
    CHECK(s1.node_fetches == s2.node_fetches && s1.triangle_fetches == s2.triangle_fetches);
  }
  // Behind a cache, DRAM bytes never exceed the uncached fetch bytes.
  std::vector<sim_core::Hit> c(rays.size());
  const auto tc = sim_core::per_ray_traversal(scene, rays.data(), rays.size(), c.data(),
                                              sim_core::CacheConfig{16384, 64, 4}, 256);
  CHECK(tc.scene_dram_bytes < ta.scene_dram_bytes);
  std::printf("streaming_test: %d hits, nodes %llu per-ray vs %llu streamed\n", hits,
              static_cast<unsigned long long>(ta.node_fetches), static_cast<unsigned long long>(tb.node_fetches));
  return check_exit_code();
}
