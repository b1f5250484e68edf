// The environment's light: its SH irradiance against a brute-force cosine integral of the map, a sun found
// in a map (power, direction, size; rotated with the map) and left out of the ambient term, bilinear
// lookups between texel centres.
#include <cmath>
#include <vector>

#include "sim_core/env_filter.h"
#include "sim_core/environment.h"

#include "check.h"

using sim_core::Environment;
using sim_core::Vec3;

namespace {

constexpr int kW = 256, kH = 128;
constexpr double kPiD = 3.14159265358979323846;

// A sky: a zenith-to-horizon gradient over a darker ground, plus a disc of radiance `sun` and radius
// 1.5 degrees around `sun_dir` (map frame).
std::vector<float> sky(float sun, Vec3 sun_dir) {
  std::vector<float> rgb(static_cast<std::size_t>(kW) * kH * 3);
  for (int row = 0; row < kH; ++row)
    for (int col = 0; col < kW; ++col) {
      const Vec3 d = sim_core::equirect_direction(col + 0.5f, row + 0.5f, kW, kH);
      const float up = std::max(0.f, d.z);
      Vec3 c = d.z >= 0.f ? Vec3(0.7f, 0.8f, 0.9f) * (1.f - up) + Vec3(0.15f, 0.3f, 0.8f) * up
                          : Vec3(0.2f, 0.17f, 0.12f);
      if (sim_core::dot(d, sun_dir) > std::cos(1.5f * 3.14159265f / 180.f)) c = Vec3(sun, sun, sun * 0.9f);
      float* p = &rgb[(static_cast<std::size_t>(row) * kW + col) * 3];
      p[0] = c.x; p[1] = c.y; p[2] = c.z;
    }
  return rgb;
}

// (1 / pi) times the irradiance on a surface of unit normal n from every texel: the ambient term's truth.
Vec3 brute_force(const std::vector<float>& rgb, Vec3 n) {
  double e[3] = {0, 0, 0};
  for (int row = 0; row < kH; ++row) {
    const double solid = std::sin((row + 0.5) / kH * kPiD) * (2 * kPiD / kW) * (kPiD / kH);
    for (int col = 0; col < kW; ++col) {
      const double c = sim_core::dot(sim_core::equirect_direction(col + 0.5f, row + 0.5f, kW, kH), n);
      if (c <= 0.0) continue;
      for (int k = 0; k < 3; ++k) e[k] += rgb[(static_cast<std::size_t>(row) * kW + col) * 3 + k] * c * solid;
    }
  }
  return Vec3(static_cast<float>(e[0] / kPiD), static_cast<float>(e[1] / kPiD), static_cast<float>(e[2] / kPiD));
}

bool near(Vec3 a, Vec3 b, float rel) {
  for (int k = 0; k < 3; ++k)
    if (std::fabs(a[k] - b[k]) > rel * std::max(std::fabs(b[k]), 1e-3f)) return false;
  return true;
}

const Vec3 kNormals[] = {Vec3(0, 0, 1), Vec3(0, 0, -1), Vec3(1, 0, 0), Vec3(0.6f, -0.48f, 0.64f), Vec3(0, 1, 0)};

}  // namespace

int main() {
  {  // A smooth sky (no sun): the order-2 SH irradiance is the cosine integral of the map (normalisation).
    const std::vector<float> map = sky(0.f, Vec3(1, 0, 0));
    const Environment env(map.data(), kW, kH);
    CHECK(env.lights().empty());
    for (const Vec3& n : kNormals) CHECK(near(env.diffuse_radiance(n), brute_force(map, n), 0.05f));
  }
  {  // A sun of radiance 2000 at 20 degrees elevation: one environment light with the disc's power above
     // the sky, in its direction, of about its size; the ambient term is the map without it, so ambient +
     // sun (cosine-weighted) is the whole map's cosine integral.
    const float el = 20.f * 3.14159265f / 180.f;
    const Vec3 dir(std::cos(el) * std::cos(0.7f), std::cos(el) * std::sin(0.7f), std::sin(el));
    const std::vector<float> map = sky(2000.f, dir);
    const Environment env(map.data(), kW, kH);
    CHECK(env.lights().size() == 1);
    if (env.lights().size() == 1) {
      const sim_core::EnvironmentLight& sun = env.lights()[0];
      CHECK(sim_core::dot(sun.direction, dir) > std::cos(1.f * 3.14159265f / 180.f));
      const float disc = static_cast<float>(2 * kPiD * (1 - std::cos(1.5 * kPiD / 180)));  // solid angle
      CHECK(std::fabs(sun.irradiance.x - 2000.f * disc) < 0.15f * 2000.f * disc);  // texels tile the disc roughly
      CHECK(sun.angular_radius > 0.5f * 1.5f * 3.14159265f / 180.f && sun.angular_radius < 3.f * 3.14159265f / 180.f);
      std::vector<float> no_sun = sky(0.f, dir);
      for (const Vec3& n : kNormals) {
        CHECK(near(env.diffuse_radiance(n), brute_force(no_sun, n), 0.05f));
        const float c = std::max(0.f, sim_core::dot(n, sun.direction));
        CHECK(near(env.diffuse_radiance(n) + sun.irradiance * (c / 3.14159265f), brute_force(map, n), 0.05f));
      }
    }
    // Turned by the Mapping rotation: the sun turns with the map (read at R_z(rotation) * direction).
    const float rotation = 1.1f;
    const Environment turned(map.data(), kW, kH, rotation);
    CHECK(turned.lights().size() == 1);
    if (turned.lights().size() == 1) {
      const Vec3 world(std::cos(rotation) * dir.x + std::sin(rotation) * dir.y,
                       -std::sin(rotation) * dir.x + std::cos(rotation) * dir.y, dir.z);
      CHECK(sim_core::dot(turned.lights()[0].direction, world) > std::cos(1.f * 3.14159265f / 180.f));
    }
  }
  {  // A faint glint (one bright texel, little power) is no sun.
    std::vector<float> map = sky(0.f, Vec3(1, 0, 0));
    map[(10 * kW + 20) * 3] = map[(10 * kW + 20) * 3 + 1] = map[(10 * kW + 20) * 3 + 2] = 60.f;
    CHECK(Environment(map.data(), kW, kH).lights().empty());
  }
  {  // Bilinear lookups: a texel centre reads the texel, halfway between two centres their mean; nearest
     // reads stay whole texels.
    std::vector<float> map(static_cast<std::size_t>(kW) * kH * 3);
    for (std::size_t i = 0; i < map.size(); ++i) map[i] = static_cast<float>((i / 3) % 7);
    const Environment env(map.data(), kW, kH);
    const int row = 20, col = 50;
    const float* a = &map[(static_cast<std::size_t>(row) * kW + col) * 3];
    const float* b = &map[(static_cast<std::size_t>(row) * kW + col + 1) * 3];
    const Vec3 centre = sim_core::equirect_direction(col + 0.5f, row + 0.5f, kW, kH);
    const Vec3 between = sim_core::equirect_direction(col + 1.f, row + 0.5f, kW, kH);
    CHECK(std::fabs(env.radiance(centre, true).x - a[0]) < 1e-3f);
    CHECK(std::fabs(env.radiance(between, true).x - 0.5f * (a[0] + b[0])) < 1e-3f);
    const float nearest = env.radiance(between, false).x;
    CHECK(nearest == a[0] || nearest == b[0]);
  }
  return check_exit_code();
}
