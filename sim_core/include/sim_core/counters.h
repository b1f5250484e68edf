// Activity counters of one render, the events the energy model prices (names fixed in ARCHITECTURE.md).
// Every tile owns a Counters and the frame sums them in tile order, so totals are independent of threads.
// Shading-feature counters (all 0 when a scene lacks the feature): rays_alpha = continuation rays past
// alpha cut-outs (a ray kind, part of rays_total), alpha_tests = alpha evaluations at hits of cut-out
// materials, area_light_evals = unshadowed area-light evaluations (emitter polygon + representative
// point), texture_fetches = filtered texture lookups, texel_reads = texels they read through the texture
// cache, texture_cache_misses / texture_dram_bytes = that cache's misses and the line bytes they fetch,
// env_sh_evals = spherical-harmonic evaluations of an environment map (ambient light: one per diffuse hit,
// one per AO ray, one per rough-specular ambient term; 0 for a constant-colour world). The resolve pass
// (resolve.h; none for 1 spp or undersampling without AO): resolve_bytes = bytes of the frame's sample
// buffer, written by the tiles and read back once; resolve_taps = the pixel filter's RGB multiply-adds;
// ambient_filter_taps = neighbours the ambient denoiser weighs.
#pragma once
#include <cstdint>

namespace sim_core {

#define SIM_CORE_COUNTERS(X)                                                                            \
  X(rays_primary) X(rays_shadow) X(rays_reflection) X(rays_refraction) X(rays_ao) X(rays_glossy)         \
  X(rays_total) X(bvh_node_visits) X(triangle_tests) X(shading_evals) X(raygen_evals)                    \
  X(similarity_checks) X(interpolations) X(reprojections) X(tile_buffer_reads) X(tile_buffer_writes)     \
  X(framebuffer_bytes) X(gbuffer_prefetch_bytes) X(cache_accesses) X(cache_misses) X(dram_bytes_read)    \
  X(closest_hit_comparisons) X(env_lookups) X(env_filtered_lookups) X(samples_traced)                    \
  X(samples_interpolated) X(samples_reused) X(pixels) X(rays_alpha) X(alpha_tests) X(area_light_evals)  \
  X(texture_fetches) X(texel_reads) X(texture_cache_misses) X(texture_dram_bytes) X(env_sh_evals)       \
  X(resolve_taps) X(resolve_bytes) X(ambient_filter_taps)

struct Counters {
#define SIM_CORE_DECLARE(name) std::uint64_t name = 0;
  SIM_CORE_COUNTERS(SIM_CORE_DECLARE)
#undef SIM_CORE_DECLARE

  Counters& operator+=(const Counters& o) {
#define SIM_CORE_ADD(name) name += o.name;
    SIM_CORE_COUNTERS(SIM_CORE_ADD)
#undef SIM_CORE_ADD
    return *this;
  }
  // Calls fn(name, value) for every counter, in the order above.
  template <class Fn>
  void for_each(Fn&& fn) const {
#define SIM_CORE_VISIT(name) fn(#name, name);
    SIM_CORE_COUNTERS(SIM_CORE_VISIT)
#undef SIM_CORE_VISIT
  }
};

// Bytes of one tile-buffer record (colour + geometry of a sample) and of one G-buffer texel (stereo).
inline constexpr std::uint64_t kTileRecordBytes = 32;
inline constexpr std::uint64_t kGBufferTexelBytes = 32;
// Frame-buffer flush: RGBA8 per pixel.
inline constexpr std::uint64_t kFramebufferPixelBytes = 4;

}  // namespace sim_core
