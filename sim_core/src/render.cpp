#include "sim_core/render.h"

#include <algorithm>
#include <stdexcept>

#include "sim_core/adaptive_sampling.h"

namespace sim_core {

void FrameBuffers::allocate(int w, int h, int k, bool ambient) {
  width = w;
  height = h;
  const std::size_t n = static_cast<std::size_t>(w) * h;
  color.assign(n * 3, 0.f);
  depth.assign(n, kInf);
  normal.assign(n * 3, 0.f);
  position.assign(n * 3, 0.f);
  object.assign(n, -1);
  kind.assign(n, 0);
  if (k > 1 || ambient) samples.allocate(w, h, k, ambient);
  else samples = SampleBuffer{};
}

void FrameBuffers::store(std::size_t p, Vec3 c, const SampleGeometry& g, SampleKind sample_kind) {
  color[3 * p] = c.x; color[3 * p + 1] = c.y; color[3 * p + 2] = c.z;
  depth[p] = g.depth;
  object[p] = g.object;
  if (g.object >= 0) {
    normal[3 * p] = g.normal.x; normal[3 * p + 1] = g.normal.y; normal[3 * p + 2] = g.normal.z;
  }
  position[3 * p] = g.position.x; position[3 * p + 1] = g.position.y; position[3 * p + 2] = g.position.z;
  kind[p] = sample_kind;
}

TileStat TileGrid::tile(std::size_t t) const {
  TileStat s;
  s.x0 = static_cast<int>(t % static_cast<std::size_t>(tiles_x)) * tile_size;
  s.y0 = static_cast<int>(t / static_cast<std::size_t>(tiles_x)) * tile_size;
  s.width = std::min(tile_size, width - s.x0);
  s.height = std::min(tile_size, height - s.y0);
  return s;
}

void render_tiles(const Scene& scene, const Camera& camera, const RenderSettings& settings, const CacheConfig& cache,
                  const TileGrid& grid, int threads, const TraceOptions& trace, RenderOutput* out,
                  const TileRenderer& render, const CacheConfig& texture_cache) {
  trace.validate();
  const std::size_t ntiles = static_cast<std::size_t>(grid.count());
  out->tiles.resize(ntiles);
  std::vector<Counters> tile_counters(ntiles);
  std::vector<ComparatorHistogram> tile_hist(ntiles);
  std::vector<std::vector<TracedRay>> tile_rays(trace.log_rays ? ntiles : 0);
  parallel_chunks(ntiles, threads, 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t t = begin; t < end; ++t) {
      TileContext ctx(scene, settings, camera, cache, trace, texture_cache);
      TileStat& stat = out->tiles[t];
      stat = grid.tile(t);
      render(ctx, stat, t);
      const std::uint64_t pixels = static_cast<std::uint64_t>(stat.width) * stat.height;
      ctx.counters.pixels += pixels;
      ctx.counters.framebuffer_bytes += pixels * kFramebufferPixelBytes;
      ctx.finish();
      stat.rays_total = ctx.counters.rays_total;
      stat.bvh_node_visits = ctx.counters.bvh_node_visits;
      stat.triangle_tests = ctx.counters.triangle_tests;
      stat.cache_misses = ctx.counters.cache_misses;
      tile_counters[t] = ctx.counters;
      tile_hist[t] = ctx.histogram;
      if (trace.log_rays) tile_rays[t] = std::move(ctx.ray_log);
    }
  });
  for (std::size_t t = 0; t < ntiles; ++t) {
    if (trace.log_rays) out->rays.insert(out->rays.end(), tile_rays[t].begin(), tile_rays[t].end());
    out->counters += tile_counters[t];
    for (std::size_t i = 0; i < out->histogram.size(); ++i) out->histogram[i] += tile_hist[t][i];
  }
}

RenderOutput render_frame(const Scene& scene, const Camera& camera, const RenderSettings& settings, int threads,
                          const MultirateState* previous, const CacheConfig& cache, const TraceOptions& trace,
                          const CacheConfig& texture_cache) {
  settings.validate();
  camera.validate();
  cache.validate();
  texture_cache.validate();
  RenderOutput out;
  const TileGrid grid(camera.width, camera.height, settings.tile_size);
  const int k = settings.subgrid();
  // AO rays are traced only under a world that gives light.
  const bool ambient = settings.ao_samples > 0 && max_component(scene.environment().mean()) > 0.f;
  out.fb.allocate(camera.width, camera.height, k, ambient);
  const bool use_prev = settings.multirate && settings.adaptive() && previous &&
                        previous->matches(grid.tiles_x, grid.tiles_y, grid.tile_size, camera.width, camera.height);
  render_tiles(scene, camera, settings, cache, grid, threads, trace, &out, [&](TileContext& ctx, TileStat& stat, std::size_t t) {
    int spacing = 1;
    if (settings.adaptive()) {
      spacing = settings.block;
      if (use_prev) spacing = multirate_block(previous->block[t], previous->ratio[t], previous->checks[t], settings);
    }
    render_tile(ctx, out.fb, stat.x0, stat.y0, stat.width, stat.height, k, spacing, &stat);
  }, texture_cache);
  if (!out.fb.samples.empty())
    resolve_pixels(out.fb.samples, out.fb.width, out.fb.height, camera.position, out.fb.color.data(), &out.counters,
                   threads);
  const std::size_t ntiles = out.tiles.size();
  MultirateState& ms = out.multirate;
  ms.tiles_x = grid.tiles_x; ms.tiles_y = grid.tiles_y; ms.tile_size = grid.tile_size;
  ms.width = camera.width; ms.height = camera.height;
  ms.block.resize(ntiles); ms.ratio.resize(ntiles); ms.checks.resize(ntiles);
  for (std::size_t t = 0; t < ntiles; ++t) {
    ms.block[t] = out.tiles[t].block;
    ms.ratio[t] = out.tiles[t].similarity_ratio;
    ms.checks[t] = out.tiles[t].similarity_checks;
  }
  return out;
}

}  // namespace sim_core
