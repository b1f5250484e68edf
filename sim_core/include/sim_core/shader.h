// Shading of one sample: the Whitted ray tree of a primary ray, traced and shaded in named phases
// (shader.cpp): primary hit (past alpha cut-outs) -> surface point, texture and material terms ->
// emission -> direct light (point, spot, sun, area) with shadow rays -> ambient light with
// ambient-occlusion rays -> mirror/glossy reflection and Fresnel refraction (recursively) -> environment
// for rays that leave the scene. Every ray, node and triangle fetch, closest-hit comparison, texel read and
// environment lookup is counted into the tile's context.
#pragma once
#include <cstdint>
#include <vector>

#include "sim_core/cache.h"
#include "sim_core/camera.h"
#include "sim_core/comparator.h"
#include "sim_core/counters.h"
#include "sim_core/resolve.h"
#include "sim_core/scene.h"
#include "sim_core/settings.h"

namespace sim_core {

// What the similarity test needs to know about a sample besides its colour (seed sec. 3: object id,
// normal, position, shadow bits), for the primary hit and for the first reflection/refraction hits.
struct SampleGeometry {
  std::int32_t object = -1;  // primary hit object, -1 on a miss
  Vec3 normal;               // shading normal at the primary hit
  Vec3 position;             // primary hit point (world)
  float depth = kInf;        // camera-space depth of the primary hit
  std::uint32_t shadow_bits = 0;  // bit l: light l is occluded at the primary hit
  std::int32_t sec_object[2] = {-2, -2};  // reflection / refraction hit object (-1 environment, -2 no ray)
  Vec3 sec_normal[2];
  std::uint32_t sec_shadow_bits = 0;
};

struct SampleResult {
  Vec3 color;
  SampleGeometry geom;
  AmbientSample ambient;  // the primary hit's ambient light (part of `color`), for the resolve's denoiser
};

// Texture cache of the shading cores when no hardware profile provides one (16 KiB, 64-byte lines, 4 ways).
inline constexpr CacheConfig kDefaultTextureCache{16384, 64, 4};

// Kinds of traced rays, as a ray log records them (the order of the rays_* counters).
enum class TracedKind : std::uint8_t { kPrimary, kShadow, kReflection, kRefraction, kAo, kGlossy };

// One ray as a tile traced it: shadow and ambient-occlusion rays are any-hit queries, the others closest-hit.
struct TracedRay {
  Ray ray;
  TracedKind kind;
};

// How tiles trace their rays; the defaults are what the energy model prices.
struct TraceOptions {
  // 4: the 4-wide BVH; 2: the binary walk, the slow reference that gives the same images (its counters
  // count 32-byte binary nodes).
  int bvh_width = 4;
  bool log_rays = false;  // keep every traced ray (benchmarks replay a render's rays through other tracers)
  void validate() const;  // throws std::invalid_argument
};

// Per-tile state of the T&I unit model: counters, node/triangle cache, texture cache, comparator histogram,
// and how the tile's rays are traced.
struct TileContext {
  const Scene& scene;
  const RenderSettings& settings;
  const Camera& camera;
  CacheModel cache;
  CacheModel texture_cache;  // texel reads of base-colour textures (untouched by scenes without textures)
  Counters counters;
  ComparatorHistogram histogram{};
  TraceOptions trace;
  std::vector<TracedRay> ray_log;  // with trace.log_rays: every ray, in tracing order
  float cos_threshold;  // cos(normal_threshold); > 1 when nothing may pass
  float ao_distance;
  float pixel_spread;   // angle between neighbouring samples (the primary ray cone's spread, radians)

  TileContext(const Scene& s, const RenderSettings& st, const Camera& c, const CacheConfig& cc,
              const TraceOptions& trace = {}, const CacheConfig& texture_cc = kDefaultTextureCache);
  void finish();  // folds cache statistics into the counters
};

// Traces and shades the primary sample through continuous pixel coordinates (px, py) of the camera.
// `key` identifies the sample (its global sample-grid coordinates) and seeds all its random numbers.
SampleResult trace_sample(TileContext& ctx, float px, float py, std::uint32_t key);
// The same through continuous coordinates of the whole frame (Camera::primary_frame): what the tile
// sampler uses, so that a window's samples are the frame's to the bit wherever the window lies.
SampleResult trace_frame_sample(TileContext& ctx, float fx, float fy, std::uint32_t key);

}  // namespace sim_core
