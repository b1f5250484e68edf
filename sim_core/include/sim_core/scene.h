// The native scene: triangles in BVH leaf order, per-triangle shading data, materials, lights and the
// environment. Built once from validated flat arrays (the Python side checks them first); immutable
// afterwards, so any number of threads may trace it concurrently.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

#include "sim_core/bvh.h"
#include "sim_core/environment.h"
#include "sim_core/intersect.h"
#include "sim_core/math.h"
#include "sim_core/parallel.h"

namespace sim_core {

struct Material {
  Vec3 base_color{0.8f, 0.8f, 0.8f};
  float metallic = 0.f;
  float roughness = 0.5f;
  float transmission = 0.f;
  float ior = 1.5f;
  Vec3 emission{0.f, 0.f, 0.f};
  // A material traces reflection rays when it is metallic or smoother than this roughness.
  static constexpr float kReflectRoughness = 0.5f;
  bool reflects() const { return metallic > 0.f || roughness < kReflectRoughness; }
  bool refracts() const { return transmission > 0.f; }
};
inline constexpr int kMaterialFields = 10;  // base rgb, metallic, roughness, transmission, ior, emission rgb

enum class LightKind : int { kPoint = 0, kSpot = 1, kSun = 2 };
struct Light {
  LightKind kind = LightKind::kPoint;
  Vec3 position;
  Vec3 direction{0.f, 0.f, -1.f};  // where the light shines (spot, sun)
  Vec3 color{1.f, 1.f, 1.f};
  float intensity = 1.f;
  float radius = 0.f;              // sphere radius (point/spot) or angular radius in radians (sun)
  float spot_angle = 0.7853982f;   // half angle of the spot cone
};
inline constexpr int kLightFields = 13;  // kind, position xyz, direction xyz, color rgb, intensity, radius, spot
inline constexpr int kMaxLights = 32;    // one shadow bit per light

struct TriShading {
  Vec3 n[3];  // shading normal at v0, v1, v2 (the geometric normal when none were given)
  Vec3 ng;    // unit geometric normal (winding order)
};

class Scene {
 public:
  // positions: V*3 floats; triangles: T*3 indices (< V, non-degenerate); prim_ids: caller's original index
  // of each triangle; normals: V*3 or null; material_ids, object_ids: T each or null;
  // materials: M * kMaterialFields; lights: L * kLightFields. Throws std::invalid_argument on bad input.
  Scene(const float* positions, std::size_t vertex_count, const std::uint32_t* triangles,
        std::size_t triangle_count, const std::int64_t* prim_ids, const float* normals,
        const std::uint32_t* material_ids, const std::uint32_t* object_ids, const float* materials,
        std::size_t material_count, const float* lights, std::size_t light_count, Environment env);

  // Closest hit and any hit (shadow and ambient-occlusion rays) over the 4-wide BVH: what the renderer and
  // the host-side queries walk. The recorder sees 128-byte node fetches and 48-byte triangle fetches.
  Hit closest(const Ray& r) const {
    NullRecorder rec;
    return closest(r, rec);
  }
  template <class Rec>
  Hit closest(const Ray& r, Rec& rec) const {
    return intersect_closest4(bvh4_.nodes.data(), bvh4_.blocks.data(), tris_.data(), r, rec);
  }
  template <class Rec>
  bool occluded(const Ray& r, Rec& rec) const {
    return intersect_any4(bvh4_.nodes.data(), bvh4_.blocks.data(), tris_.data(), r, rec);
  }
  // The binary walk: the slow reference the wide walk is checked against (same hit/miss, t and
  // occlusion); its recorder sees 32-byte node fetches.
  Hit closest_binary(const Ray& r) const {
    NullRecorder rec;
    return closest_binary(r, rec);
  }
  template <class Rec>
  Hit closest_binary(const Ray& r, Rec& rec) const { return intersect_closest(bvh_.nodes.data(), tris_.data(), r, rec); }
  template <class Rec>
  bool occluded_binary(const Ray& r, Rec& rec) const { return intersect_any(bvh_.nodes.data(), tris_.data(), r, rec); }

  // N rays (origins, directions: N*3 floats; tmax: N floats or null for +inf) -> t (inf on miss), original
  // prim id (-1 on miss); multithreaded over chunks of rays. bvh_width 4 (default) walks the BVH4, 2 the
  // binary BVH (the reference; benchmarks).
  void intersect_many(const float* origins, const float* directions, std::size_t n, float* t_out,
                      std::int64_t* prim_out, int threads, int bvh_width = 4, const float* tmax = nullptr) const;
  // Any-hit queries of N rays within (0, tmax[i]) (null tmax: +inf): occluded_out[i] = 1 when something is hit.
  void occluded_many(const float* origins, const float* directions, const float* tmax, std::size_t n,
                     std::uint8_t* occluded_out, int threads, int bvh_width = 4) const;

  const TriRecord& tri(std::uint32_t i) const { return tris_[i]; }
  const TriShading& shading(std::uint32_t i) const { return shading_[i]; }
  Vec3 geometric_normal(std::uint32_t i) const;  // unit, from the winding (v1 - v0) x (v2 - v0)
  const std::vector<Material>& materials() const { return materials_; }
  const std::vector<Light>& lights() const { return lights_; }
  const Environment& environment() const { return env_; }
  const Bvh& bvh() const { return bvh_; }
  const Bvh4& bvh4() const { return bvh4_; }
  std::size_t triangle_count() const { return tris_.size(); }
  Vec3 bounds_lo() const { return lo_; }
  Vec3 bounds_hi() const { return hi_; }
  float diagonal() const { return length(hi_ - lo_); }
  bool has_refraction() const { return has_refraction_; }
  bool has_reflection() const { return has_reflection_; }
  bool has_emission() const { return has_emission_; }

 private:
  std::vector<TriRecord> tris_;
  std::vector<TriShading> shading_;
  std::vector<Material> materials_;
  std::vector<Light> lights_;
  Environment env_;
  Bvh bvh_;
  Bvh4 bvh4_;
  Vec3 lo_, hi_;
  bool has_refraction_ = false, has_reflection_ = false, has_emission_ = false;
};



}  // namespace sim_core

