#include "sim_core/render.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "sim_core/sampling.h"

namespace sim_core {

void FrameBuffers::allocate(int w, int h) {
  width = w;
  height = h;
  const std::size_t n = static_cast<std::size_t>(w) * h;
  color.assign(n * 3, 0.f);
  depth.assign(n, kInf);
  normal.assign(n * 3, 0.f);
  position.assign(n * 3, 0.f);
  object.assign(n, -1);
  kind.assign(n, 0);
}

RenderOutput render_frame(const Scene& scene, const Camera& camera, const RenderSettings& settings, int threads,
                          const MultirateState* previous, const CacheConfig& cache) {
  settings.validate();
  camera.validate();
  cache.validate();
  RenderOutput out;
  const int ts = settings.tile_size;
  const int tx = (camera.width + ts - 1) / ts, ty = (camera.height + ts - 1) / ts;
  const int ntiles = tx * ty;
  out.fb.allocate(camera.width, camera.height);
  out.tiles.resize(ntiles);
  std::vector<Counters> tile_counters(ntiles);
  std::vector<ComparatorHistogram> tile_hist(ntiles);
  const bool use_prev = settings.multirate && settings.adaptive() && previous &&
                        previous->matches(tx, ty, ts, camera.width, camera.height);
  const int k = settings.subgrid();

  parallel_chunks(static_cast<std::size_t>(ntiles), threads, 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t t = begin; t < end; ++t) {
      const int x0 = static_cast<int>(t % tx) * ts, y0 = static_cast<int>(t / tx) * ts;
      const int w = std::min(ts, camera.width - x0), h = std::min(ts, camera.height - y0);
      int spacing = 1;
      if (settings.adaptive()) {
        spacing = settings.block;
        if (use_prev) spacing = multirate_block(previous->block[t], previous->ratio[t], previous->checks[t], settings);
      }
      TileContext ctx(scene, settings, camera, cache);
      TileStat& stat = out.tiles[t];
      render_tile(ctx, out.fb, x0, y0, w, h, k, spacing, &stat);
      ctx.counters.pixels += static_cast<std::uint64_t>(w) * h;
      ctx.counters.framebuffer_bytes += static_cast<std::uint64_t>(w) * h * kFramebufferPixelBytes;
      ctx.finish();
      stat.rays_total = ctx.counters.rays_total;
      stat.bvh_node_visits = ctx.counters.bvh_node_visits;
      stat.triangle_tests = ctx.counters.triangle_tests;
      stat.cache_misses = ctx.counters.cache_misses;
      tile_counters[t] = ctx.counters;
      tile_hist[t] = ctx.histogram;
    }
  });
  for (int t = 0; t < ntiles; ++t) {
    out.counters += tile_counters[t];
    for (std::size_t i = 0; i < out.histogram.size(); ++i) out.histogram[i] += tile_hist[t][i];
  }
  MultirateState& ms = out.multirate;
  ms.tiles_x = tx; ms.tiles_y = ty; ms.tile_size = ts; ms.width = camera.width; ms.height = camera.height;
  ms.block.resize(ntiles); ms.ratio.resize(ntiles); ms.checks.resize(ntiles);
  for (int t = 0; t < ntiles; ++t) {
    ms.block[t] = out.tiles[t].block;
    ms.ratio[t] = out.tiles[t].similarity_ratio;
    ms.checks[t] = out.tiles[t].similarity_checks;
  }
  return out;
}

}  // namespace sim_core
