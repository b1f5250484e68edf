// What a ray that leaves the scene sees: a constant colour or an equirectangular map in the world frame
// (Z up, Blender's convention, same mapping as env_filter.h), optionally turned about +Z (Blender's Mapping
// node rotation: the map is read at R_z(rotation) * direction). Glossy lookups can go through the
// summed-area-table filter of env_filter.h (box or Bartlett), built lazily per filter order.
#pragma once
#include <memory>
#include <mutex>
#include <vector>

#include "sim_core/env_filter.h"
#include "sim_core/math.h"

namespace sim_core {

class Environment {
 public:
  Environment() = default;
  explicit Environment(Vec3 constant) : constant_(constant), mean_(constant) {}
  // rgb: (height, width, 3) float32 linear, row 0 at the top; copied. rotation_z in radians.
  Environment(const float* rgb, int width, int height, float rotation_z = 0.f);
  ~Environment();
  Environment(Environment&&) noexcept;
  Environment& operator=(Environment&&) noexcept;

  bool is_map() const { return width_ > 0; }
  // Nearest-texel radiance in `direction` (any length > 0).
  Vec3 radiance(Vec3 direction) const;
  // Mean radiance over the whole sphere (solid-angle weighted).
  Vec3 mean() const { return mean_; }
  // Irradiance / pi on a surface with unit normal n, unoccluded: what a white Lambertian surface reflects
  // of the environment (the ambient term). A map's is the order-2 spherical-harmonic irradiance
  // (Ramamoorthi & Hanrahan 2001, 9 coefficients per channel, under 3 % error for any lighting), so a bright
  // sky lights upward faces more than downward ones; a constant colour's is the colour itself.
  Vec3 diffuse_radiance(Vec3 n) const;
  // The map's radiance band-limited to the same 9 SH coefficients (a smooth version of the environment):
  // averaged over cosine-distributed unoccluded directions it estimates the occluded ambient term.
  Vec3 smooth_radiance(Vec3 direction) const;
  // Cone-filtered radiance (glossy reflection); order 1 box, 2 Bartlett. Requires the SAT filter.
  Vec3 filtered(Vec3 direction, float cone_half_angle, int order) const;

 private:
  Vec3 constant_{0.f, 0.f, 0.f};
  Vec3 mean_{0.f, 0.f, 0.f};
  Vec3 sh_[9];  // radiance projected on the real SH basis up to order 2 (map frame)
  Vec3 sh_evaluate(const Vec3* coefficients, Vec3 direction) const;
  int width_ = 0, height_ = 0;
  float cos_rot_ = 1.f, sin_rot_ = 0.f;
  std::vector<float> rgb_;
  Vec3 to_map(Vec3 d) const { return Vec3(cos_rot_ * d.x - sin_rot_ * d.y, sin_rot_ * d.x + cos_rot_ * d.y, d.z); }
  mutable std::mutex filter_mutex_;
  mutable std::unique_ptr<EnvironmentFilter> filters_[2];
  const EnvironmentFilter* filter(int order) const;
};

}  // namespace sim_core
