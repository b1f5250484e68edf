#include "sim_core/stereo.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "sim_core/sampler.h"
#include "sim_core/sampling.h"

namespace sim_core {
namespace {

constexpr float kDepthTolerance = 0.05f;  // relative depth difference that separates surfaces
constexpr int kMaxSpan = 16;              // widest gap between two reprojected neighbours checked for leaks

}  // namespace

StereoOutput render_stereo(const Scene& scene, const Camera& left, const Camera& right,
                           const RenderSettings& settings, int threads, const MultirateState* previous,
                           const CacheConfig& cache) {
  right.validate();
  if (left.width != right.width || left.height != right.height)
    throw std::invalid_argument("stereo eyes must have the same resolution");
  StereoOutput out;
  out.left = render_frame(scene, left, settings, threads, previous, cache);
  const FrameBuffers& L = out.left.fb;
  const int W = L.width, H = L.height;
  const std::size_t n = static_cast<std::size_t>(W) * H;

  // 1. Reproject every left-eye sample (hit point, or direction of a miss) into the right eye; a
  //    z-buffer keeps the nearest. src = left pixel index feeding each right pixel, or -1 (hole).
  std::vector<std::int64_t> src(n, -1);
  std::vector<float> zbuf(n, kInf);
  std::vector<float> proj_x(n, -1.f), proj_z(n, kInf);
  std::vector<std::int32_t> proj_row(n, -1);
  Counters rc;
  for (std::size_t i = 0; i < n; ++i) {
    ++rc.reprojections;
    const Vec3 p(L.position[3 * i], L.position[3 * i + 1], L.position[3 * i + 2]);
    float u, v, z = kInf;
    bool ok;
    if (L.object[i] >= 0) {
      ok = right.project(p, &u, &v, &z);
    } else {
      ok = right.project_direction(p, &u, &v);
    }
    if (!ok || !(u >= 0.f && u < static_cast<float>(W) && v >= 0.f && v < static_cast<float>(H))) continue;
    const int x = std::min(W - 1, static_cast<int>(u)), y = std::min(H - 1, static_cast<int>(v));
    proj_x[i] = u;
    proj_z[i] = z;
    proj_row[i] = y;
    const std::size_t j = static_cast<std::size_t>(y) * W + x;
    if (src[j] < 0 || z < zbuf[j]) { src[j] = static_cast<std::int64_t>(i); zbuf[j] = z; }
  }
  // 2. Bad pixels: holes, and farther samples showing through the gap between two reprojected
  //    neighbours of one continuous nearer surface (a magnified surface in the right eye).
  std::vector<std::uint8_t> bad(n, 0);
  for (std::size_t j = 0; j < n; ++j) if (src[j] < 0) { bad[j] = 1; ++out.holes; }
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x + 1 < W; ++x) {
      const std::size_t a = static_cast<std::size_t>(y) * W + x, b = a + 1;
      if (L.object[a] < 0 || L.object[a] != L.object[b] || proj_row[a] < 0 || proj_row[b] < 0) continue;
      const float za = proj_z[a], zb = proj_z[b];
      if (std::fabs(za - zb) > kDepthTolerance * std::min(za, zb)) continue;
      const int ua = static_cast<int>(proj_x[a]), ub = static_cast<int>(proj_x[b]);
      const int lo = std::min(ua, ub), hi = std::max(ua, ub);
      if (hi - lo < 2 || hi - lo > kMaxSpan) continue;
      const int row = proj_row[a];
      const float zmax = std::max(za, zb) * (1.f + kDepthTolerance);
      for (int xx = lo + 1; xx < hi; ++xx) {
        const std::size_t j = static_cast<std::size_t>(row) * W + xx;
        if (!bad[j] && zbuf[j] > zmax) { bad[j] = 1; ++out.depth_mismatches; }
      }
    }
  }
  // G-buffer reads of the error detection: the left rows each right tile's pixels reproject from.
  // 3. Right eye, tile by tile: reuse valid pixels, trace bad ones (every sub-pixel of the grid).
  RenderOutput& R = out.right;
  R.fb.allocate(W, H);
  const int ts = settings.tile_size;
  const int tx = (W + ts - 1) / ts, ty = (H + ts - 1) / ts;
  const int ntiles = tx * ty;
  R.tiles.resize(ntiles);
  std::vector<Counters> tile_counters(ntiles);
  std::vector<ComparatorHistogram> tile_hist(ntiles);
  const int k = settings.subgrid();
  const float inv_k = 1.f / static_cast<float>(k);
  parallel_chunks(static_cast<std::size_t>(ntiles), threads, 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t t = begin; t < end; ++t) {
      const int x0 = static_cast<int>(t % tx) * ts, y0 = static_cast<int>(t / tx) * ts;
      const int w = std::min(ts, W - x0), h = std::min(ts, H - y0);
      TileContext ctx(scene, settings, right, cache);
      TileStat& stat = R.tiles[t];
      stat.x0 = x0; stat.y0 = y0; stat.width = w; stat.height = h; stat.block = 1;
      Counters& c = ctx.counters;
      c.gbuffer_prefetch_bytes += static_cast<std::uint64_t>(h) * W * kGBufferTexelBytes;
      for (int yy = y0; yy < y0 + h; ++yy) {
        for (int xx = x0; xx < x0 + w; ++xx) {
          const std::size_t j = static_cast<std::size_t>(yy) * W + xx;
          c.tile_buffer_reads += 1;  // error-detection result
          if (!bad[j]) {
            const std::size_t i = static_cast<std::size_t>(src[j]);
            for (int ch = 0; ch < 3; ++ch) {
              R.fb.color[3 * j + ch] = L.color[3 * i + ch];
              R.fb.normal[3 * j + ch] = L.normal[3 * i + ch];
              R.fb.position[3 * j + ch] = L.position[3 * i + ch];
            }
            R.fb.object[j] = L.object[i];
            R.fb.depth[j] = L.object[i] >= 0 ? zbuf[j] : kInf;
            R.fb.kind[j] = 2;
            ++stat.samples_reused;
            ++c.samples_reused;
            ++c.tile_buffer_writes;
            continue;
          }
          Vec3 sum;
          SampleGeometry centre;
          for (int b = 0; b < k; ++b)
            for (int a = 0; a < k; ++a) {
              const std::uint32_t sx = static_cast<std::uint32_t>(xx * k + a), sy = static_cast<std::uint32_t>(yy * k + b);
              const std::uint32_t key = hash_combine(hash_combine(hash_u32(sx), sy), static_cast<std::uint32_t>(k) | 0x100u);
              const SampleResult s = trace_sample(ctx, static_cast<float>(xx) + (a + 0.5f) * inv_k,
                                                  static_cast<float>(yy) + (b + 0.5f) * inv_k, key);
              sum += s.color;
              if (a == k / 2 && b == k / 2) centre = s.geom;
              ++stat.samples_traced;
              ++c.samples_traced;
              ++c.tile_buffer_writes;
            }
          const Vec3 col = k > 1 ? sum * (1.f / static_cast<float>(k * k)) : sum;
          R.fb.color[3 * j] = col.x; R.fb.color[3 * j + 1] = col.y; R.fb.color[3 * j + 2] = col.z;
          R.fb.object[j] = centre.object;
          R.fb.depth[j] = centre.depth;
          if (centre.object >= 0) {
            R.fb.normal[3 * j] = centre.normal.x; R.fb.normal[3 * j + 1] = centre.normal.y;
            R.fb.normal[3 * j + 2] = centre.normal.z;
          }
          R.fb.position[3 * j] = centre.position.x; R.fb.position[3 * j + 1] = centre.position.y;
          R.fb.position[3 * j + 2] = centre.position.z;
          R.fb.kind[j] = 0;
        }
      }
      c.pixels += static_cast<std::uint64_t>(w) * h;
      c.framebuffer_bytes += static_cast<std::uint64_t>(w) * h * kFramebufferPixelBytes;
      ctx.finish();
      stat.rays_total = c.rays_total;
      stat.bvh_node_visits = c.bvh_node_visits;
      stat.triangle_tests = c.triangle_tests;
      stat.cache_misses = c.cache_misses;
      tile_counters[t] = c;
      tile_hist[t] = ctx.histogram;
    }
  });
  R.counters = rc;
  for (int t = 0; t < ntiles; ++t) {
    R.counters += tile_counters[t];
    for (std::size_t i = 0; i < R.histogram.size(); ++i) R.histogram[i] += tile_hist[t][i];
  }
  R.multirate = out.left.multirate;
  out.reuse_ratio = n ? static_cast<double>(R.counters.samples_reused) / static_cast<double>(n) : 0.0;
  return out;
}

}  // namespace sim_core
