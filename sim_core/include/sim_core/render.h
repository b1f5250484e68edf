// The tile-based ray tracer's frame driver: it hands tiles to threads, each tile with its own context
// (counters, cache model, comparator histogram), and sums them in tile order. Shading of one sample lives
// in shader.h, the sampling schedule inside a tile (1 spp, FSAA, adaptive under/supersampling, multi-rate)
// in sampling.h, stereo reprojection in stereo.h.
#pragma once
#include <cstdint>
#include <vector>

#include "sim_core/cache.h"
#include "sim_core/camera.h"
#include "sim_core/comparator.h"
#include "sim_core/counters.h"
#include "sim_core/scene.h"
#include "sim_core/settings.h"
#include "sim_core/shader.h"

namespace sim_core {

// Statistics of one tile.
struct TileStat {
  int x0 = 0, y0 = 0, width = 0, height = 0;  // pixels (render resolution)
  int block = 1;                              // reference spacing used (1 = every sample traced)
  std::uint64_t samples_traced = 0, samples_interpolated = 0, samples_reused = 0;
  std::uint64_t similarity_checks = 0, similarity_passed = 0;
  float similarity_ratio = 0.f;  // passed / checks (0 when no check ran)
  std::uint64_t rays_total = 0, bvh_node_visits = 0, triangle_tests = 0, cache_misses = 0;
};

// Multi-rate state carried from one frame to the next (explicit, never global).
struct MultirateState {
  int tiles_x = 0, tiles_y = 0, tile_size = 0, width = 0, height = 0;
  std::vector<std::int32_t> block;   // block size each tile used
  std::vector<float> ratio;          // similarity ratio each tile measured
  std::vector<std::uint64_t> checks; // similarity checks each tile ran (ratio is meaningless at 0)
  bool matches(int tx, int ty, int ts, int w, int h) const {
    return tiles_x == tx && tiles_y == ty && tile_size == ts && width == w && height == h &&
           block.size() == static_cast<std::size_t>(tx) * ty;
  }
};

struct FrameBuffers {
  int width = 0, height = 0;
  std::vector<float> color;         // H*W*3 linear RGB
  std::vector<float> depth;         // H*W camera-space depth, inf on miss
  std::vector<float> normal;        // H*W*3 shading normal, 0 on miss
  std::vector<float> position;      // H*W*3 primary hit point (world), 0 on miss
  std::vector<std::int32_t> object; // H*W, -1 on miss
  std::vector<std::uint8_t> kind;   // H*W: 0 traced, 1 interpolated, 2 reused
  void allocate(int w, int h);
};

struct RenderOutput {
  FrameBuffers fb;
  Counters counters;
  std::vector<TileStat> tiles;
  ComparatorHistogram histogram{};
  MultirateState multirate;
};

// Renders `camera` (already at render resolution) with `settings`. `previous` may be null.
RenderOutput render_frame(const Scene& scene, const Camera& camera, const RenderSettings& settings, int threads,
                          const MultirateState* previous, const CacheConfig& cache);

}  // namespace sim_core
