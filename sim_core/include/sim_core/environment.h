// What a ray that leaves the scene sees: a constant colour or an equirectangular map in the world frame
// (Z up, Blender's convention, same mapping as env_filter.h), optionally turned about +Z (Blender's Mapping
// node rotation: the map is read at R_z(rotation) * direction). Glossy lookups can go through the
// summed-area-table filter of env_filter.h (box or Bartlett), built lazily per filter order.
//
// A map's light reaches surfaces two ways. Its compact, very bright parts (a sun: texels far above the
// map's mean that carry a sizeable share of its power) become environment lights, which the shader
// treats as sun lights with shadow rays, so they cast sharp, correctly occluded shadows as Cycles'
// importance-sampled world does. The rest, smooth by comparison, lights surfaces as the ambient term
// (order-2 spherical harmonics, occluded by ambient-occlusion rays). Rays that see the map (camera,
// reflections) still see all of it.
#pragma once
#include <memory>
#include <mutex>
#include <vector>

#include "sim_core/env_filter.h"
#include "sim_core/math.h"

namespace sim_core {

// A compact bright part of an environment map, lighting the scene like a sun lamp.
struct EnvironmentLight {
  Vec3 direction;        // unit, world frame, from the scene towards the light
  Vec3 irradiance;       // W/m^2 on a surface facing it (its radiance over the map's background, integrated)
  float angular_radius;  // radians: the spread of its power around `direction` (soft shadows)
};

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
  // Radiance in `direction` (any length > 0): the nearest texel, or bilinearly interpolated between the
  // four nearest (4 texel reads; Cycles' linear interpolation of an Environment Texture).
  Vec3 radiance(Vec3 direction, bool bilinear = false) const;
  // Mean radiance over the whole sphere (solid-angle weighted).
  Vec3 mean() const { return mean_; }
  // The map's suns (at most kMaxSuns, brightest first); none for a constant colour.
  const std::vector<EnvironmentLight>& lights() const { return lights_; }
  // A texel is part of a sun when its luminance exceeds kSunThreshold x the map's mean luminance, within
  // kSunRadius of the brightest such texel; the region counts when it carries at least kSunMinPower of
  // the map's power. At most kMaxSuns.
  static constexpr float kSunThreshold = 50.f;
  static constexpr float kSunRadius = 0.1745329f;  // 10 degrees
  static constexpr float kSunMinPower = 0.02f;
  static constexpr int kMaxSuns = 4;
  // Irradiance / pi on a surface with unit normal n, unoccluded, from the map without its suns: what a
  // white Lambertian surface reflects of the ambient light. A map's is the order-2 spherical-harmonic
  // irradiance (Ramamoorthi & Hanrahan 2001, 9 coefficients per channel, under 3 % error for smooth
  // lighting), so a bright sky lights upward faces more than downward ones; a constant colour's is the
  // colour itself.
  Vec3 diffuse_radiance(Vec3 n) const;
  // The sun-less map's radiance band-limited to the same 9 SH coefficients (a smooth version of the
  // ambient light): what an ambient-occlusion ray towards `direction` weighs its visibility by.
  Vec3 smooth_radiance(Vec3 direction) const;
  // Cone-filtered radiance (glossy reflection); order 1 box, 2 Bartlett. Requires the SAT filter.
  Vec3 filtered(Vec3 direction, float cone_half_angle, int order) const;

 private:
  Vec3 constant_{0.f, 0.f, 0.f};
  Vec3 mean_{0.f, 0.f, 0.f};
  Vec3 sh_[9];  // radiance without the suns projected on the real SH basis up to order 2 (map frame)
  std::vector<EnvironmentLight> lights_;
  Vec3 sh_evaluate(const Vec3* coefficients, Vec3 direction) const;
  int width_ = 0, height_ = 0;
  float cos_rot_ = 1.f, sin_rot_ = 0.f;
  std::vector<float> rgb_;
  Vec3 to_map(Vec3 d) const { return Vec3(cos_rot_ * d.x - sin_rot_ * d.y, sin_rot_ * d.x + cos_rot_ * d.y, d.z); }
  Vec3 from_map(Vec3 d) const { return Vec3(cos_rot_ * d.x + sin_rot_ * d.y, -sin_rot_ * d.x + cos_rot_ * d.y, d.z); }
  // Finds the suns of `residual` (the map), moves them into lights_ and leaves the map's background there.
  void extract_suns(std::vector<float>* residual);
  mutable std::mutex filter_mutex_;
  mutable std::unique_ptr<EnvironmentFilter> filters_[2];
  const EnvironmentFilter* filter(int order) const;
};

}  // namespace sim_core
