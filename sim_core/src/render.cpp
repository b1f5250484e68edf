#include "sim_core/render.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
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

namespace {

// Edges of a grid of `ts`-pixel cells over [0, n) with origin `o` (in (-ts, 0]) and the extra `cuts` that
// fall inside: 0 first, n last, ascending.
std::vector<int> grid_edges(int n, int ts, int o, const std::vector<int>& cuts) {
  std::vector<int> e{0};
  for (int x = o + ts; x < n; x += ts) e.push_back(x);
  for (const int c : cuts)
    if (c > 0 && c < n) e.push_back(c);
  e.push_back(n);
  std::sort(e.begin(), e.end());
  e.erase(std::unique(e.begin(), e.end()), e.end());
  return e;
}

}  // namespace

TileGrid::TileGrid(int w, int h, int ts, int ox, int oy, const std::vector<int>& cuts_x,
                   const std::vector<int>& cuts_y)
    : width(w), height(h), tile_size(ts), origin_x(ox), origin_y(oy), tiles_x(0), tiles_y(0),
      xs_(grid_edges(w, ts, ox, cuts_x)), ys_(grid_edges(h, ts, oy, cuts_y)) {
  tiles_x = static_cast<int>(xs_.size()) - 1;
  tiles_y = static_cast<int>(ys_.size()) - 1;
}

TileStat TileGrid::tile(std::size_t t) const {
  TileStat s;
  const std::size_t cx = t % static_cast<std::size_t>(tiles_x), cy = t / static_cast<std::size_t>(tiles_x);
  s.x0 = xs_[cx];
  s.y0 = ys_[cy];
  s.width = xs_[cx + 1] - s.x0;
  s.height = ys_[cy + 1] - s.y0;
  return s;
}

void render_tiles(const Scene& scene, const Camera& camera, const RenderSettings& settings, const CacheConfig& cache,
                  const TileGrid& grid, int threads, const TraceOptions& trace, RenderOutput* out,
                  const TileRenderer& render, const CacheConfig& texture_cache, const std::vector<char>* counted) {
  trace.validate();
  const std::size_t ntiles = static_cast<std::size_t>(grid.count());
  out->tiles.resize(ntiles);
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
      stat.counters = ctx.counters;
      stat.histogram = ctx.histogram;
      if (trace.log_rays) tile_rays[t] = std::move(ctx.ray_log);
    }
  });
  for (std::size_t t = 0; t < ntiles; ++t) {
    if (counted && !(*counted)[t]) continue;
    if (trace.log_rays) out->rays.insert(out->rays.end(), tile_rays[t].begin(), tile_rays[t].end());
    out->counters += out->tiles[t].counters;
    for (std::size_t i = 0; i < out->histogram.size(); ++i) out->histogram[i] += out->tiles[t].histogram[i];
  }
}

namespace {

// Copies the w x h window at (x0, y0) of `src`'s pixel buffers (no sample buffer).
FrameBuffers crop_pixels(const FrameBuffers& src, int x0, int y0, int w, int h) {
  FrameBuffers dst;
  dst.allocate(w, h);
  for (int y = 0; y < h; ++y) {
    const std::size_t from = static_cast<std::size_t>(y0 + y) * src.width + x0, to = static_cast<std::size_t>(y) * w;
    auto copy = [&](const auto& s, auto& d, std::size_t n) {
      std::copy(s.begin() + from * n, s.begin() + (from + w) * n, d.begin() + to * n);
    };
    copy(src.color, dst.color, 3);
    copy(src.depth, dst.depth, 1);
    copy(src.normal, dst.normal, 3);
    copy(src.position, dst.position, 3);
    copy(src.object, dst.object, 1);
    copy(src.kind, dst.kind, 1);
  }
  return dst;
}

}  // namespace

RenderOutput render_frame(const Scene& scene, const Camera& camera, const RenderSettings& settings, int threads,
                          const MultirateState* previous, const CacheConfig& cache, const TraceOptions& trace,
                          const CacheConfig& texture_cache) {
  settings.validate();
  camera.validate();
  cache.validate();
  texture_cache.validate();
  const int k = settings.subgrid();
  const int ts = settings.tile_size;
  // AO rays are traced only under a world that gives light.
  const bool ambient = settings.ao_samples > 0 && max_component(scene.environment().mean()) > 0.f;
  // A window that goes through the resolve pass reads samples beyond its edges: those of the pixel
  // filter's support and the ambient filter's pool around each of them (resolve_reach_pixels: 1 to 3
  // px). It traces an apron of just those pixels around itself, up to the frame's edges. The apron's
  // tiles stay those of the window's tile grid, cut off at the apron's edge: in the per-pixel modes a
  // pixel's samples do not depend on its tile, and an adaptive tile traces the reference cells that
  // hold the apron's samples (render_tile's `part`), which stay within a reference spacing of it.
  Camera traced = camera;
  int apron = 0;
  if ((k > 1 || ambient) && (camera.width != camera.frame_width() || camera.height != camera.frame_height())) {
    apron = resolve_reach_pixels(k, ambient);
    traced.crop_x = std::max(0, camera.crop_x - apron);
    traced.crop_y = std::max(0, camera.crop_y - apron);
    traced.width = std::min(camera.frame_width(), camera.crop_x + camera.width + apron) - traced.crop_x;
    traced.height = std::min(camera.frame_height(), camera.crop_y + camera.height + apron) - traced.crop_y;
    traced.full_width = camera.frame_width();
    traced.full_height = camera.frame_height();
  }
  const int wx = camera.crop_x - traced.crop_x, wy = camera.crop_y - traced.crop_y;  // the window in `traced`
  // The frame's tile grid (edges at multiples of ts in the frame's pixels), here over the traced area and
  // cut at the window's edges: a window off that grid keeps it, and a tile its edge crosses is traced as
  // its part in the window (counted) and its part in the apron (not), each as the whole tile has it.
  auto grid_origin = [&](int crop) { return crop % ts == 0 ? 0 : -(crop % ts); };
  const TileGrid grid(traced.width, traced.height, ts, grid_origin(traced.crop_x), grid_origin(traced.crop_y),
                      {wx, wx + camera.width}, {wy, wy + camera.height});
  // The frame's tile holding `r` whole (not cut off by the traced area's or the window's edges; clipped to
  // the frame's), in the traced area's pixels: what an adaptive tile's sampling schedule is laid out over.
  auto whole_tile = [&](const TileStat& r) {
    const int ex = (traced.crop_x + r.x0) / ts * ts - traced.crop_x;
    const int ey = (traced.crop_y + r.y0) / ts * ts - traced.crop_y;
    return PixelRect{ex, ey, std::min(ex + ts, traced.frame_width() - traced.crop_x) - ex,
                     std::min(ey + ts, traced.frame_height() - traced.crop_y) - ey};
  };
  const TileGrid window_grid(camera.width, camera.height, ts, grid_origin(camera.crop_x), grid_origin(camera.crop_y));
  // Tile t of `grid`: its index in the window's grid, or -1 in the apron.
  std::vector<std::ptrdiff_t> window_tile(static_cast<std::size_t>(grid.count()), -1);
  std::vector<char> counted(window_tile.size(), 0);
  for (std::size_t t = 0; t < window_tile.size(); ++t) {
    const TileStat r = grid.tile(t);
    if (r.x0 < wx || r.y0 < wy || r.x0 >= wx + camera.width || r.y0 >= wy + camera.height) continue;
    window_tile[t] = static_cast<std::ptrdiff_t>((r.y0 - wy - window_grid.origin_y) / ts) * window_grid.tiles_x +
                     (r.x0 - wx - window_grid.origin_x) / ts;
    counted[t] = 1;
  }
  RenderOutput out;
  out.fb.allocate(traced.width, traced.height, k, ambient);
  const bool use_prev = settings.multirate && settings.adaptive() && previous &&
                        previous->matches(window_grid.tiles_x, window_grid.tiles_y, ts, camera.width, camera.height);
  render_tiles(scene, traced, settings, cache, grid, threads, trace, &out, [&](TileContext& ctx, TileStat& stat, std::size_t t) {
    int spacing = 1;
    if (settings.adaptive()) {
      spacing = settings.block;
      if (use_prev && window_tile[t] >= 0) {
        const auto p = static_cast<std::size_t>(window_tile[t]);
        spacing = multirate_block(previous->block[p], previous->ratio[p], previous->checks[p], settings);
      }
    }
    const PixelRect tile = whole_tile(stat), part{stat.x0, stat.y0, stat.width, stat.height};
    render_tile(ctx, out.fb, tile.x0, tile.y0, tile.width, tile.height, k, spacing, &stat, &part);
  }, texture_cache, &counted);
  for (std::size_t t = 0; t < out.tiles.size(); ++t)
    if (!counted[t]) out.apron_rays += out.tiles[t].rays_total;
  if (!out.fb.samples.empty()) {
    // Each tile of the window carries its share of the resolve pass (its pixels' filter and samples).
    const ResolveWork work =
        resolve_pixels(out.fb.samples, out.fb.width, out.fb.height, camera.position, out.fb.color.data(), threads);
    for (std::size_t t = 0; t < out.tiles.size(); ++t) {
      if (!counted[t]) continue;
      TileStat& stat = out.tiles[t];
      const Counters c = resolve_counters(out.fb.samples, work, out.fb.width, out.fb.height,
                                          PixelRect{stat.x0, stat.y0, stat.width, stat.height});
      stat.counters += c;
      out.counters += c;
    }
  }
  if (apron > 0) {
    out.fb = crop_pixels(out.fb, wx, wy, camera.width, camera.height);
    std::vector<TileStat> tiles(static_cast<std::size_t>(window_grid.count()));
    for (std::size_t t = 0; t < window_tile.size(); ++t) {
      if (window_tile[t] < 0) continue;
      TileStat stat = out.tiles[t];
      stat.x0 -= wx;
      stat.y0 -= wy;
      tiles[static_cast<std::size_t>(window_tile[t])] = stat;
    }
    out.tiles = std::move(tiles);
  }
  const std::size_t ntiles = out.tiles.size();
  MultirateState& ms = out.multirate;
  ms.tiles_x = window_grid.tiles_x; ms.tiles_y = window_grid.tiles_y; ms.tile_size = ts;
  ms.width = camera.width; ms.height = camera.height;
  ms.block.resize(ntiles); ms.ratio.resize(ntiles); ms.checks.resize(ntiles);
  for (std::size_t t = 0; t < ntiles; ++t) {
    ms.block[t] = out.tiles[t].block;
    ms.ratio[t] = out.tiles[t].similarity_ratio;
    ms.checks[t] = out.tiles[t].similarity_checks;
  }
  return out;
}

int window_apron_pixels(const RenderSettings& settings, bool ambient) {
  settings.validate();
  const int k = settings.subgrid();
  if (k == 1 && !ambient) return 0;
  const int cells = settings.adaptive() ? (settings.block - 1 + k - 1) / k : 0;
  return resolve_reach_pixels(k, ambient) + cells;
}

}  // namespace sim_core
