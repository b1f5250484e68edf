// The resolve pass: a frame's samples into pixels, after every tile is traced. Tiles write their samples
// to a frame-level sample buffer (in DRAM on the modelled GPU) and the resolve reads it back once:
//
// 1. Ambient denoising (when AO rays are traced): each sample's ambient-occlusion estimate is pooled with
//    its neighbours' on the same surface (same object, normals within kAmbientNormalCos, on its tangent
//    plane), Gaussian-weighted over +-kAmbientRadius pixels: the visible share of the ambient light is
//    the open rays' radiance over all rays' radiance of the pool, where one sample's is noisy. Like the
//    denoisers real-time ray tracers run on their few-ray AO (and the denoised Cycles renders the
//    simulator is measured against), it removes noise without shifting the mean of a smooth surface.
// 2. The pixel filter of the sub-sample modes (FSAA, supersampling): Cycles' default, a Blackman-Harris
//    window of width 1.5 px (Cycles' "filter_width"; support +-1.5 px around the pixel centre),
//    separable in x and y. A pixel is the filter-weighted mean of every sub-sample within its support,
//    its neighbours' included, so edges and textures get Cycles' softness instead of a 1-pixel box's.
//    Tiles on the frame's edges also trace a guard ring of sub-samples just outside it, where Cycles'
//    filtered rays land too. One sample per pixel (1 spp, undersampling) is the pixel itself.
//
// The energy model prices the pass: the buffer's bytes written and read back (resolve_bytes), the pixel
// filter's multiply-adds (resolve_taps) and the ambient filter's weighted taps (ambient_filter_taps).
// Frames with one sample per pixel and no AO rays need no resolve pass (pixels go straight out).
#pragma once
#include <cstdint>
#include <vector>

#include "sim_core/counters.h"
#include "sim_core/math.h"

namespace sim_core {

inline constexpr float kPixelFilterRadius = 1.5f;  // px: Blackman-Harris window of width 3 px
inline constexpr float kAmbientRadius = 2.f;       // px: the ambient filter's window (+-), Gaussian sigma 1 px
inline constexpr float kAmbientNormalCos = 0.9f;   // normals within ~25 degrees pool their AO
inline constexpr float kAmbientPlaneTolerance = 0.02f;  // off the tangent plane by at most 2 % of the depth
// Bytes of one sample in the buffer: its colour as RGBA16F; with AO, also its ambient record (unoccluded
// ambient, open and all rays' radiance at RGBA16F, an octahedral normal and a depth: 32 bytes).
inline constexpr std::uint64_t kResolveColorBytes = 8;
inline constexpr std::uint64_t kResolveAmbientBytes = 32;

// How far the resolve pass reads, in sub-samples along each axis, on a k x k sub-sample grid:
// - ambient_reach: the ambient filter's pool around a sample (ceil(kAmbientRadius * k): 2 px);
// - resolve_reach: around a pixel's own sub-samples, what its resolved value depends on: the pixel filter's
//   guard (PixelFilter(k).guard = k sub-samples, 1 px: the Blackman-Harris support of +-1.5 px around the
//   pixel centre reaches 1 px past the pixel's edge) and, with AO, the ambient pool around each of those
//   samples (their denoised colours). 1 spp without AO: 0.
int ambient_reach(int k);
int resolve_reach(int k, bool ambient);
// resolve_reach in whole pixels (rounded up): 1 (filter), 2 (AO at 1 sample per pixel) or 3 (both).
int resolve_reach_pixels(int k, bool ambient);

// Filter weight at `offset` pixels from the pixel centre (1 at the centre, 0 at and beyond the radius).
float blackman_harris(float offset);

// The 1-D pixel filter of a k x k sub-sample grid: normalised weights of the sub-samples a pixel reads
// along one axis, from `guard` sub-samples before its own first one to `guard` after its last one.
// k = 1: the pixel's own sample (no guard).
struct PixelFilter {
  int k = 1;
  int guard = 0;
  std::vector<float> weights;  // k + 2 * guard taps, summing to 1
  explicit PixelFilter(int k);
};

// The ambient light of a sample's primary hit, apart from its colour so the resolve can denoise it: the
// unoccluded diffuse ambient (albedo x irradiance / pi) and the (smooth) radiance its AO rays carried,
// all of them and the open ones. All zero where no AO rays were traced (a miss, no diffuse layer).
struct AmbientSample {
  Vec3 unoccluded;
  Vec3 seen;
  Vec3 all;
};

// A frame's samples (k x k per pixel, plus the pixel filter's guard ring), row-major.
struct SampleBuffer {
  int k = 1, guard = 0;
  int width = 0, height = 0;  // in samples, guard included
  bool ambient = false;       // AO rays were traced: the ambient records are kept
  std::vector<float> color;   // 3 per sample
  // With `ambient`: the primary hit's record and what the ambient filter compares (object -1 = no hit).
  std::vector<AmbientSample> ambient_samples;
  std::vector<Vec3> normal, position;
  std::vector<std::int32_t> object;
  void allocate(int pixel_width, int pixel_height, int k, bool ambient);
  bool empty() const { return color.empty(); }
  // Sample (sx, sy) in frame sample coordinates (-guard .. pixel_width * k + guard - 1).
  std::size_t index(int sx, int sy) const {
    return static_cast<std::size_t>(sy + guard) * static_cast<std::size_t>(width) + static_cast<std::size_t>(sx + guard);
  }
  void set(int sx, int sy, Vec3 c, const AmbientSample& a, std::int32_t obj, Vec3 n, Vec3 p);
};

// A rectangle of a frame's pixels (width 0 = the whole frame).
struct PixelRect {
  int x0 = 0, y0 = 0, width = 0, height = 0;
};

// What a resolve pass did per sample, for pricing any part of the frame: the ambient denoiser's
// neighbour taps of each sample of the buffer (empty without AO).
struct ResolveWork {
  std::vector<std::uint16_t> ambient_taps;
};

// Resolves `samples` into `pixels` (pixel_width * pixel_height * 3, row-major): ambient denoising with
// AO (the samples' colours are updated), then the pixel filter (or a copy at one sample per pixel). `eye`
// is the camera position (the ambient filter's plane tolerance grows with a hit's distance from it).
// `threads` share the work; the result does not depend on them.
ResolveWork resolve_pixels(SampleBuffer& samples, int pixel_width, int pixel_height, Vec3 eye, float* pixels,
                           int threads);

// The resolve pass's counters (resolve_bytes, resolve_taps, ambient_filter_taps) for the pixels of `rect`:
// their samples, with the guard ring where `rect` reaches the buffer's edge (there it reaches the frame's
// edge). Additive: rectangles that tile the frame sum to the whole frame's counts.
Counters resolve_counters(const SampleBuffer& samples, const ResolveWork& work, int pixel_width, int pixel_height,
                          PixelRect rect = {});

}  // namespace sim_core
