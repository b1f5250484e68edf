// The tile-based ray tracer's frame driver: it hands tiles to threads, each tile with its own context
// (counters, cache model, comparator histogram), and sums them in tile order. Shading of one sample lives
// in shader.h, the sampling schedule inside a tile (1 spp, FSAA, adaptive under/supersampling, multi-rate)
// in adaptive_sampling.h, stereo reprojection in stereo.h.
#pragma once
#include <cstdint>
#include <functional>
#include <vector>

#include "sim_core/cache.h"
#include "sim_core/camera.h"
#include "sim_core/comparator.h"
#include "sim_core/counters.h"
#include "sim_core/resolve.h"
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
  Counters counters;                 // every activity counter of this tile (they sum to the frame's)
  ComparatorHistogram histogram{};   // this tile's closest-hit comparisons (sum to the frame's)
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

// How a pixel's value came about (the sample_kind AOV).
enum SampleKind : std::uint8_t { kSampleTraced = 0, kSampleInterpolated = 1, kSampleReused = 2 };

struct FrameBuffers {
  int width = 0, height = 0;
  std::vector<float> color;         // H*W*3 linear RGB
  std::vector<float> depth;         // H*W camera-space depth, inf on miss
  std::vector<float> normal;        // H*W*3 shading normal, 0 on miss
  std::vector<float> position;      // H*W*3 primary hit point (world), 0 on miss
  std::vector<std::int32_t> object; // H*W, -1 on miss
  std::vector<std::uint8_t> kind;   // H*W SampleKind
  SampleBuffer samples;             // what the resolve pass reads (empty: pixels are final as stored)
  // With k > 1 sub-samples per pixel edge or AO (`ambient`), also the sample buffer the resolve reads.
  void allocate(int w, int h, int k = 1, bool ambient = false);
  // Writes pixel p: its colour and the geometry of its (centre) sample; the normal stays 0 on a miss.
  void store(std::size_t p, Vec3 color, const SampleGeometry& g, SampleKind sample_kind);
};

// The tiles of a frame, row-major: tile t covers [x0, x0 + width) x [y0, y0 + height), clipped to the frame.
// Tile edges lie at origin + n * tile_size; an origin in (-tile_size, 0] makes the first row/column partial
// (a window's apron keeps the frame's tile grid, its outer tiles cut off by it). Extra cuts (`cuts_x`,
// `cuts_y`: a window's edges inside its apron, off the grid) split the tiles they cross into parts.
struct TileGrid {
  int width, height, tile_size, origin_x, origin_y, tiles_x, tiles_y;
  TileGrid(int w, int h, int ts, int ox = 0, int oy = 0, const std::vector<int>& cuts_x = {},
           const std::vector<int>& cuts_y = {});
  int count() const { return tiles_x * tiles_y; }
  TileStat tile(std::size_t t) const;  // rect set, statistics zero

 private:
  std::vector<int> xs_, ys_;  // column / row edges: 0 first, width / height last
};

struct RenderOutput {
  FrameBuffers fb;
  Counters counters;
  std::vector<TileStat> tiles;
  ComparatorHistogram histogram{};
  MultirateState multirate;
  std::uint64_t apron_rays = 0;  // rays a window traced for its apron (real work, in no counter)
  std::vector<TracedRay> rays;  // with TraceOptions::log_rays: every traced ray, tile by tile in tile order
};

// Renders every tile of `grid` on `threads` threads. Each tile gets its own TileContext (cold cache, rays
// traced as `trace` says) and its
// TileStat with the rect set; render(ctx, stat, t) traces the tile and writes its pixels. The driver then
// folds the tile's pixels, frame-buffer flush and cache statistics into its counters and adds every tile's
// counters and comparator histogram to `out` in tile order (the same totals for any thread count).
// With `counted`, only tiles t with counted[t] add to the counters, histogram and ray log (the others are
// traced for the resolve pass of a window and counted by the window they belong to).
using TileRenderer = std::function<void(TileContext& ctx, TileStat& stat, std::size_t tile)>;
void render_tiles(const Scene& scene, const Camera& camera, const RenderSettings& settings, const CacheConfig& cache,
                  const TileGrid& grid, int threads, const TraceOptions& trace, RenderOutput* out,
                  const TileRenderer& render, const CacheConfig& texture_cache = kDefaultTextureCache,
                  const std::vector<char>* counted = nullptr);

// Renders `camera` (already at render resolution) with `settings`. `previous` may be null. `cache` is the
// T&I unit's node/triangle cache, `texture_cache` the shading cores' texture cache. Sub-samples and AO go
// through the resolve pass (resolve.h). A window of a larger frame (Camera::crop_*) that needs the resolve
// pass also traces an apron around it: the resolve_reach_pixels(k, AO) pixels its pixels' filters read
// (1 to 3), as the whole frame has them (the apron's tiles are the frame's, cut off at the apron's edge;
// an adaptive one traces the reference cells that hold the apron's samples), uncounted: windows that
// tile the frame on its tile grid sum to the whole frame's image and counters.
RenderOutput render_frame(const Scene& scene, const Camera& camera, const RenderSettings& settings, int threads,
                          const MultirateState* previous, const CacheConfig& cache,
                          const TraceOptions& trace = {}, const CacheConfig& texture_cache = kDefaultTextureCache);

// How far beyond each edge a window of a frame rendered with `settings` traces samples (`ambient`: AO
// rays are traced, i.e. ao_samples > 0 under a world that gives light): 0 without a resolve pass, else
// resolve_reach_pixels, plus in the adaptive modes the rest of the reference cells that hold them (at most
// block - 1 samples, ceil((block - 1) / k) pixels, more; some of them interpolated). For pricing windows.
int window_apron_pixels(const RenderSettings& settings, bool ambient);

}  // namespace sim_core
