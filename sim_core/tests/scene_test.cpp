// The scene's per-triangle data in BVH leaf order: interpolated UVs equal the vertex UVs at the corners
// (whatever order the BVH put the triangles in), the texture level-of-detail term is half the log2 of
// UV area over world area, and bad material, light or UV input is rejected with std::invalid_argument.
#include <cmath>
#include <stdexcept>
#include <vector>

#include "sim_core/scene.h"

#include "check.h"

using namespace sim_core;

namespace {

constexpr float kMat[kMaterialFields] = {0.8f, 0.8f, 0.8f, 0.f, 0.5f, 0.f, 1.5f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.5f, -1.f};

// A 4x4 grid of quads on z = 0, spanning 4 m; UV = (x / 2 + 0.1 y, y / 8): distinct at every vertex.
void grid(std::vector<float>* pos, std::vector<float>* uv, std::vector<std::uint32_t>* tri) {
  for (int j = 0; j <= 4; ++j)
    for (int i = 0; i <= 4; ++i) {
      pos->insert(pos->end(), {float(i), float(j), 0.f});
      uv->insert(uv->end(), {0.5f * i + 0.1f * j, 0.125f * j});
    }
  for (int j = 0; j < 4; ++j)
    for (int i = 0; i < 4; ++i) {
      const std::uint32_t a = static_cast<std::uint32_t>(j * 5 + i);
      tri->insert(tri->end(), {a, a + 1, a + 6, a, a + 6, a + 5});
    }
}

bool throws(const std::vector<float>& mat, const std::vector<float>& light) {
  std::vector<float> pos, uv;
  std::vector<std::uint32_t> tri;
  grid(&pos, &uv, &tri);
  try {
    Scene s(pos.data(), pos.size() / 3, tri.data(), tri.size() / 3, nullptr, nullptr, nullptr, nullptr, mat.data(), 1,
            light.empty() ? nullptr : light.data(), light.empty() ? 0 : 1, Environment(Vec3(0.f, 0.f, 0.f)), uv.data());
  } catch (const std::invalid_argument&) {
    return true;
  }
  return false;
}

void check_uvs_at_vertices() {
  std::vector<float> pos, uv;
  std::vector<std::uint32_t> tri;
  grid(&pos, &uv, &tri);
  const std::size_t nt = tri.size() / 3;
  const Scene s(pos.data(), pos.size() / 3, tri.data(), nt, nullptr, nullptr, nullptr, nullptr, kMat, 1, nullptr, 0,
                Environment(Vec3(0.f, 0.f, 0.f)), uv.data());
  for (std::uint32_t i = 0; i < nt; ++i) {
    const std::uint32_t src = s.tri(i).prim;  // the caller's triangle (leaf order differs)
    CHECK(s.texcoord(i) != nullptr);
    const float bary[3][3] = {{1.f, 0.f, 0.f}, {0.f, 1.f, 0.f}, {0.f, 0.f, 1.f}};
    for (int k = 0; k < 3; ++k) {
      float u, v;
      s.uv_at(i, bary[k][0], bary[k][1], bary[k][2], &u, &v);
      const std::uint32_t vi = tri[3 * src + k];
      CHECK(u == uv[2 * vi] && v == uv[2 * vi + 1]);
    }
    // Centroid: the mean of the corners' UVs.
    float u, v;
    s.uv_at(i, 1.f / 3, 1.f / 3, 1.f / 3, &u, &v);
    const float mu = (uv[2 * tri[3 * src]] + uv[2 * tri[3 * src + 1]] + uv[2 * tri[3 * src + 2]]) / 3.f;
    CHECK(std::fabs(u - mu) < 1e-6f);
    // Each 1 m^2 quad half covers 0.5 * 0.125 * 0.5 of UV area over 0.5 m^2 of world.
    CHECK(std::fabs(s.texcoord(i)->lod_bias - 0.5f * std::log2(0.0625f)) < 1e-5f);
  }
  // Without UVs: no texcoords, (0, 0) everywhere.
  const Scene bare(pos.data(), pos.size() / 3, tri.data(), nt, nullptr, nullptr, nullptr, nullptr, kMat, 1, nullptr, 0,
                   Environment(Vec3(0.f, 0.f, 0.f)));
  float u = 1.f, v = 1.f;
  bare.uv_at(0, 0.2f, 0.3f, 0.5f, &u, &v);
  CHECK(bare.texcoord(0) == nullptr && u == 0.f && v == 0.f);
}

void check_bad_input() {
  const std::vector<float> ok(kMat, kMat + kMaterialFields);
  CHECK(!throws(ok, {}));
  std::vector<float> bad = ok;
  bad[13] = 0.f;  // texture 0 of none
  CHECK(throws(bad, {}));
  bad = ok;
  bad[11] = 3.f;  // alpha mode
  CHECK(throws(bad, {}));
  bad = ok;
  bad[10] = 1.5f;  // alpha
  CHECK(throws(bad, {}));
  std::vector<float> light = {3.f, 0.f, 0.f, 2.f, 0.f, 0.f, -1.f, 1.f, 1.f, 1.f, 5.f, 0.f, 0.f, 0.f, 0.f, 1.f, 1.f, 1.f, 0.f, 0.f};
  CHECK(!throws(ok, light));
  std::vector<float> l = light;
  l[15] = 0.f;  // zero-size area light
  CHECK(throws(ok, l));
  l = light;
  l[17] = 0.f; l[19] = 1.f;  // axis_u parallel to the direction
  CHECK(throws(ok, l));
  l = light;
  l[0] = 4.f;  // unknown kind
  CHECK(throws(ok, l));
  l = light;
  l[10] = -1.f;  // negative intensity
  CHECK(throws(ok, l));
}

}  // namespace

int main() {
  check_uvs_at_vertices();
  check_bad_input();
  return check_exit_code();
}
