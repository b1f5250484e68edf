// A small test scene shared by the tracer's native tests: a bumpy closed sphere (UV-sphere with jittered
// radii, object 0, metallic) on a ground quad (object 1, diffuse) under one point light, a camera that
// sees both, and the settings and cache the tests render it with.
#pragma once
#include <cmath>
#include <random>
#include <vector>

#include "sim_core/cache.h"
#include "sim_core/camera.h"
#include "sim_core/scene.h"
#include "sim_core/settings.h"

namespace sim_core::test {

inline // A bumpy closed sphere (UV-sphere with jittered radii) plus a ground quad: some depth complexity.
void make_mesh(std::vector<float>* pos, std::vector<std::uint32_t>* tri, std::vector<std::uint32_t>* obj) {
  const int nu = 24, nv = 12;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> jitter(0.9f, 1.1f);
  pos->clear(); tri->clear(); obj->clear();
  pos->insert(pos->end(), {0.f, 0.f, 2.f});  // north pole
  for (int v = 1; v < nv; ++v)
    for (int u = 0; u < nu; ++u) {
      const float th = kPi * v / nv, ph = 2 * kPi * u / nu, r = jitter(rng);
      pos->insert(pos->end(), {r * std::sin(th) * std::cos(ph), r * std::sin(th) * std::sin(ph), 1.f + r * std::cos(th)});
    }
  pos->insert(pos->end(), {0.f, 0.f, 0.f});  // south pole
  const std::uint32_t south = static_cast<std::uint32_t>(pos->size() / 3 - 1);
  auto ring = [&](int v, int u) { return static_cast<std::uint32_t>(1 + (v - 1) * nu + (u % nu)); };
  for (int u = 0; u < nu; ++u) tri->insert(tri->end(), {0u, ring(1, u), ring(1, u + 1)});
  for (int v = 1; v + 1 < nv; ++v)
    for (int u = 0; u < nu; ++u) {
      tri->insert(tri->end(), {ring(v, u), ring(v + 1, u), ring(v + 1, u + 1)});
      tri->insert(tri->end(), {ring(v, u), ring(v + 1, u + 1), ring(v, u + 1)});
    }
  for (int u = 0; u < nu; ++u) tri->insert(tri->end(), {ring(nv - 1, u), south, ring(nv - 1, u + 1)});
  obj->assign(tri->size() / 3, 0u);
  const std::uint32_t g = static_cast<std::uint32_t>(pos->size() / 3);
  pos->insert(pos->end(), {-6.f, -6.f, 0.f, 6.f, -6.f, 0.f, 6.f, 6.f, 0.f, -6.f, 6.f, 0.f});
  tri->insert(tri->end(), {g, g + 1, g + 2, g, g + 2, g + 3});
  obj->insert(obj->end(), {1u, 1u});
}

inline Scene make_scene() {
  std::vector<float> pos;
  std::vector<std::uint32_t> tri, obj;
  make_mesh(&pos, &tri, &obj);
  const std::size_t nt = tri.size() / 3;
  std::vector<std::int64_t> ids(nt);
  for (std::size_t i = 0; i < nt; ++i) ids[i] = static_cast<std::int64_t>(i);
  std::vector<std::uint32_t> mats(nt, 0u);
  mats[nt - 1] = mats[nt - 2] = 1u;
  // base rgb, metallic, roughness, transmission, ior, emission rgb, alpha, alpha mode, cutoff, texture
  const float materials[2 * kMaterialFields] = {0.9f, 0.8f, 0.7f, 1.f, 0.2f, 0.f, 1.5f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.5f, -1.f,
                                                0.5f, 0.5f, 0.5f, 0.f, 0.9f, 0.f, 1.5f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.5f, -1.f};
  // kind, position, direction, colour, intensity, radius, spot angle, spot blend (area fields unused)
  const float lights[kLightFields] = {0.f, 3.f, -2.f, 5.f, 0.f, 0.f, -1.f, 1.f, 1.f, 1.f, 40.f, 0.3f, 0.7f, 0.15f};
  return Scene(pos.data(), pos.size() / 3, tri.data(), nt, ids.data(), nullptr, mats.data(), obj.data(),
               materials, 2, lights, 1, Environment(Vec3(0.3f, 0.3f, 0.35f)));
}

inline Camera make_camera(int width = 40, int height = 30) {
  Camera cam;
  cam.position = Vec3(0.f, -6.f, 2.5f);
  cam.forward = normalize(Vec3(0.f, 6.f, -1.5f));
  cam.right = normalize(cross(cam.forward, Vec3(0.f, 0.f, 1.f)));
  cam.up = cross(cam.right, cam.forward);
  cam.vfov = 0.8f;
  cam.width = width;
  cam.height = height;
  return cam;
}

// Settings that exercise soft shadows, ambient occlusion and several 8-pixel tiles, with a small cache.
inline RenderSettings make_settings() {
  RenderSettings st;
  st.shadow_samples = 4;
  st.ao_samples = 2;
  st.tile_size = 8;
  return st;
}
inline constexpr CacheConfig kCache{16384, 64, 4};

}  // namespace sim_core::test
