// Render settings as the native core sees them (the Python RenderSettings dataclass validates and
// converts to this). One field per searchable parameter of the render-budget search space.
#pragma once
#include <string>

namespace sim_core {

enum class SamplingMode : int {
  kOneSpp = 0,       // one ray per pixel through its centre
  kFsaa = 1,         // k x k sub-pixel rays per pixel (k = block), averaged
  kUndersample = 2,  // reference samples every `block` pixels, intermediate pixels interpolated or traced
  kSupersample = 3,  // sub-pixel grid k x k (k = block), reference samples every `block` sub-pixels
};

enum class EnvFilter : int { kOff = 0, kBox = 1, kBartlett = 2 };

struct RenderSettings {
  SamplingMode mode = SamplingMode::kOneSpp;
  int block = 2;                      // 2..4: reference spacing (adaptive) or sub-pixel grid (fsaa/supersample)
  float normal_threshold_deg = 20.f;  // similarity: normals within this angle; < 0 means nothing is similar
  int max_depth = 2;                  // 0..4 reflection/refraction bounces after the primary hit
  int shadow_samples = 1;             // 0 = no shadow rays, 1 = hard, N = soft samples on the light's radius
  float resolution_scale = 1.f;       // 0.25..1: render at this fraction of the camera resolution
  EnvFilter env_filter = EnvFilter::kOff;  // glossy environment reflections: point sample, box or Bartlett SAT
                                           // (filtering on: camera and mirror rays read the map bilinearly)
  int ao_samples = 0;                 // ambient-occlusion rays per hit (0 = off)
  float ao_distance = 0.f;            // AO ray length; <= 0: unbounded (the world's visibility, as in Cycles)
  bool multirate = false;             // per-tile block size from the previous frame's similarity ratio
  float multirate_low = 0.5f;         // below: finer blocks next frame
  float multirate_high = 0.85f;       // at or above: coarser blocks next frame (between: keep; hysteresis)
  int tile_size = 16;                 // tile edge in pixels: unit of work and of the on-chip tile buffer

  // Throws std::invalid_argument naming the bad field.
  void validate() const;
  bool adaptive() const { return mode == SamplingMode::kUndersample || mode == SamplingMode::kSupersample; }
  // Sub-pixel grid per pixel edge (1 for 1spp and undersampling).
  int subgrid() const {
    return (mode == SamplingMode::kFsaa || mode == SamplingMode::kSupersample) ? block : 1;
  }
};

}  // namespace sim_core
