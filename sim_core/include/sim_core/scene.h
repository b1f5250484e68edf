// The native scene: triangles in BVH leaf order, per-triangle shading data, materials, lights and the
// environment. Built once from validated flat arrays (the Python side checks them first); immutable
// afterwards, so any number of threads may trace it concurrently.
#pragma once
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "sim_core/bvh.h"
#include "sim_core/environment.h"
#include "sim_core/intersect.h"
#include "sim_core/math.h"
#include "sim_core/parallel.h"
#include "sim_core/texture.h"

namespace sim_core {

// How a material's alpha acts (Blender's Principled alpha, glTF's alphaMode): ignored (opaque), a hard
// cut-out below `alpha_cutoff` (clip), or a stochastic cut-out per sample (hashed: a surface of alpha a
// stops a fraction a of the samples, which average to a blend, as Cycles renders alpha).
enum class AlphaMode : int { kOpaque = 0, kClip = 1, kHashed = 2 };

struct Material {
  Vec3 base_color{0.8f, 0.8f, 0.8f};  // linear; multiplied by the base-colour texture when there is one
  float metallic = 0.f;
  float roughness = 0.5f;
  float transmission = 0.f;
  float ior = 1.5f;
  Vec3 emission{0.f, 0.f, 0.f};
  float alpha = 1.f;                   // multiplied by the texture's alpha
  AlphaMode alpha_mode = AlphaMode::kOpaque;
  float alpha_cutoff = 0.5f;           // clip threshold
  std::int32_t base_color_texture = -1;  // index into the scene's textures, -1 none
  bool cuts_out = false;               // set by the scene: some hit of this material can be cut out
  // A material traces reflection rays when it is metallic or smoother than this roughness.
  static constexpr float kReflectRoughness = 0.5f;
  bool reflects() const { return metallic > 0.f || roughness < kReflectRoughness; }
  bool refracts() const { return transmission > 0.f; }
};
// base rgb, metallic, roughness, transmission, ior, emission rgb, alpha, alpha mode, alpha cutoff, texture
inline constexpr int kMaterialFields = 14;

// Light kinds. Intensity is what the shader multiplies: radiant intensity (W/sr) of a point or spot
// light, irradiance (W/m^2) of a sun, radiance (W/(m^2 sr)) of an area light's emitting face (sim_core's
// Python Light.from_blender converts Blender's watts).
enum class LightKind : int { kPoint = 0, kSpot = 1, kSun = 2, kArea = 3 };
enum class AreaShape : int { kRectangle = 0, kEllipse = 1 };  // square / disk are the equal-sided cases
struct Light {
  LightKind kind = LightKind::kPoint;
  Vec3 position;
  Vec3 direction{0.f, 0.f, -1.f};  // where the light shines (spot, sun, area: the emitting side)
  Vec3 color{1.f, 1.f, 1.f};
  float intensity = 1.f;
  float radius = 0.f;              // sphere radius (point/spot) or angular radius in radians (sun)
  float spot_angle = 0.7853982f;   // half angle of the spot cone
  float spot_blend = 0.15f;        // Blender's spot_blend: smooth edge over this fraction of the cone
  AreaShape shape = AreaShape::kRectangle;
  float size_u = 0.f, size_v = 0.f;  // area light extents (m) along axis_u and axis_v (ellipse: diameters)
  Vec3 axis_u{1.f, 0.f, 0.f};      // unit, orthogonal to direction (the light's local X)
  Vec3 axis_v{0.f, 1.f, 0.f};      // unit, axis_u x direction (the light's local Y)
  // A sun of the environment map (Environment::lights), added by the scene after its own lights: rays
  // that leave the scene also see it, so reflection rays carry its mirror-like share of the highlight.
  bool environment = false;
  float area() const {
    return kind == LightKind::kArea ? size_u * size_v * (shape == AreaShape::kEllipse ? 0.25f * kPi : 1.f) : 0.f;
  }
};
// kind, position xyz, direction xyz, color rgb, intensity, radius, spot angle, spot blend, shape, size u,
// size v, axis u xyz
inline constexpr int kLightFields = 20;
inline constexpr int kMaxLights = 32;    // one shadow bit per light

struct TriShading {
  Vec3 n[3];  // shading normal at v0, v1, v2 (the geometric normal when none were given)
  Vec3 ng;    // unit geometric normal (winding order)
};

// Texture coordinates of a triangle's vertices and its texture level-of-detail term.
struct TriTexcoord {
  float uv[6];     // (u, v) at v0, v1, v2 (Blender's convention: v up)
  float lod_bias;  // 0.5 * log2(UV area / world area): texels per metre, before the texture's size
};

class Scene {
 public:
  // positions: V*3 floats; triangles: T*3 indices (< V, non-degenerate); prim_ids: caller's original index
  // of each triangle; normals: V*3 or null; material_ids, object_ids: T each or null;
  // materials: M * kMaterialFields; lights: L * kLightFields; uvs: V*2 or null; textures: what the
  // materials' texture indices refer to. Throws std::invalid_argument on bad input.
  Scene(const float* positions, std::size_t vertex_count, const std::uint32_t* triangles,
        std::size_t triangle_count, const std::int64_t* prim_ids, const float* normals,
        const std::uint32_t* material_ids, const std::uint32_t* object_ids, const float* materials,
        std::size_t material_count, const float* lights, std::size_t light_count, Environment env,
        const float* uvs = nullptr, std::vector<std::shared_ptr<const Texture>> textures = {});

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
  // Texture coordinates of triangle i, or null when the scene has no UVs.
  const TriTexcoord* texcoord(std::uint32_t i) const { return texcoords_.empty() ? nullptr : &texcoords_[i]; }
  // Interpolated (u, v) at barycentrics (b0, b1, b2) of triangle i; (0, 0) without UVs.
  void uv_at(std::uint32_t i, float b0, float b1, float b2, float* u, float* v) const;
  const Texture& texture(std::int32_t i) const { return *textures_[static_cast<std::size_t>(i)]; }
  std::size_t texture_count() const { return textures_.size(); }
  // Start of texture i in the modelled texture address space (textures laid out one after another).
  std::uint64_t texture_base(std::int32_t i) const { return texture_bases_[static_cast<std::size_t>(i)]; }
  Vec3 geometric_normal(std::uint32_t i) const;  // unit, from the winding (v1 - v0) x (v2 - v0)
  const std::vector<Material>& materials() const { return materials_; }
  // The scene's lights, then the environment map's suns (as sun lights, while shadow bits last).
  const std::vector<Light>& lights() const { return lights_; }
  std::size_t environment_light_count() const;
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
  bool has_textures() const { return has_textures_; }   // some material samples a texture
  bool has_cutouts() const { return has_cutouts_; }     // some material can be cut out by its alpha

 private:
  std::vector<TriRecord> tris_;
  std::vector<TriShading> shading_;
  std::vector<TriTexcoord> texcoords_;  // leaf order; empty without UVs
  std::vector<std::shared_ptr<const Texture>> textures_;
  std::vector<std::uint64_t> texture_bases_;
  std::vector<Material> materials_;
  std::vector<Light> lights_;
  Environment env_;
  Bvh bvh_;
  Bvh4 bvh4_;
  Vec3 lo_, hi_;
  bool has_refraction_ = false, has_reflection_ = false, has_emission_ = false;
  bool has_textures_ = false, has_cutouts_ = false;
};

}  // namespace sim_core

