#include "sim_core/stereo.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "sim_core/sampler.h"
#include "sim_core/sampling.h"

namespace sim_core {
namespace {

constexpr float kDepthTolerance = 0.05f;  // relative depth difference that separates surfaces
constexpr int kMaxSpan = 16;        // widest gap between two reprojected neighbours checked for leaks
constexpr float kExactPx = 1e-3f;  // a reprojected sample this close to a pixel centre is used as is

}  // namespace

std::uint64_t stereo_prefetch_texels(const Camera& left, const Camera& right, int x0, int y0, int w, int h,
                                     bool any_hit, float zmin, float zmax, bool any_env) {
  const int W = left.width, H = left.height;
  if ((!any_hit && !any_env) || w <= 0 || h <= 0) return 0;
  constexpr float kSnap = 1e-3f;  // float round-off of an exactly integer reprojection
  float umin = kInf, umax = -kInf, vmin = kInf, vmax = -kInf;
  bool whole = false;
  auto add = [&](bool ok, float u, float v) {
    if (!ok || !std::isfinite(u) || !std::isfinite(v)) { whole = true; return; }
    umin = std::min(umin, u); umax = std::max(umax, u);
    vmin = std::min(vmin, v); vmax = std::max(vmax, v);
  };
  for (int cy = 0; cy < 2; ++cy)
    for (int cx = 0; cx < 2; ++cx) {
      const Ray r = right.primary(static_cast<float>(x0 + cx * w), static_cast<float>(y0 + cy * h));
      const float cosz = dot(r.dir, right.forward);
      float u, v, z;
      if (any_hit) {
        for (float depth : {zmin, zmax}) {
          const bool ok = cosz > 0.f && left.project(r.origin + r.dir * (depth / cosz), &u, &v, &z);
          add(ok, u, v);
        }
      }
      if (any_env) add(left.project_direction(r.dir, &u, &v), u, v);
    }
  long c0 = 0, c1 = W, r0 = 0, r1 = H;  // half-open pixel ranges
  if (!whole) {
    c0 = std::max(0L, static_cast<long>(std::floor(umin + kSnap)));
    c1 = std::min(static_cast<long>(W), static_cast<long>(std::ceil(umax - kSnap)));
    r0 = std::max(0L, static_cast<long>(std::floor(vmin + kSnap)));
    r1 = std::min(static_cast<long>(H), static_cast<long>(std::ceil(vmax - kSnap)));
  }
  if (c1 <= c0 || r1 <= r0) return 0;
  return static_cast<std::uint64_t>(c1 - c0) * static_cast<std::uint64_t>(r1 - r0);
}

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
  std::vector<float> proj_x(n, -1.f), proj_y(n, -1.f), proj_z(n, kInf);
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
    proj_y[i] = v;
    proj_z[i] = z;
    proj_row[i] = y;
    const std::size_t j = static_cast<std::size_t>(y) * W + x;
    if (src[j] < 0 || z < zbuf[j]) { src[j] = static_cast<std::int64_t>(i); zbuf[j] = z; }
  }
  // 2. Sub-pixel resampling along reprojected spans: two horizontally adjacent left samples on one
  //    continuous surface (same object, depths within tolerance, same target row) bound a span of right
  //    pixels; each right pixel centre inside it takes the linear interpolation of the two samples, unless
  //    a nearer surface landed there. Gaps a magnified surface leaves in the splat are filled the same way.
  //    What remains without a source is a hole (disocclusion or out of frame).
  std::vector<float> rcol(3 * n, 0.f), rdepth(n, kInf);
  std::vector<std::uint8_t> filled(n, 0);
  for (std::size_t j = 0; j < n; ++j) {
    if (src[j] < 0) continue;
    const std::size_t i = static_cast<std::size_t>(src[j]);
    for (int ch = 0; ch < 3; ++ch) rcol[3 * j + ch] = L.color[3 * i + ch];
    rdepth[j] = zbuf[j];
    filled[j] = 1;
  }
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x + 1 < W; ++x) {
      const std::size_t a = static_cast<std::size_t>(y) * W + x, b = a + 1;
      if (L.object[a] < 0 || L.object[a] != L.object[b] || proj_row[a] < 0 || proj_row[a] != proj_row[b]) continue;
      const float za = proj_z[a], zb = proj_z[b];
      if (std::fabs(za - zb) > kDepthTolerance * std::min(za, zb)) continue;
      const float ua = proj_x[a], ub = proj_x[b];
      if (!(ub > ua) || ub - ua > static_cast<float>(kMaxSpan)) continue;  // fold-over or torn span
      const int first = std::max(0, static_cast<int>(std::ceil(ua - 0.5f)));
      const int last = std::min(W - 1, static_cast<int>(std::ceil(ub - 0.5f)) - 1);
      const std::size_t row = static_cast<std::size_t>(proj_row[a]) * W;
      for (int xx = first; xx <= last; ++xx) {
        const float f = (static_cast<float>(xx) + 0.5f - ua) / (ub - ua);
        const float z = za + (zb - za) * f;
        const std::size_t j = row + xx;
        if (filled[j] && zbuf[j] < z * (1.f - kDepthTolerance)) continue;  // a nearer surface is in front
        if (filled[j] && src[j] >= 0 && L.object[static_cast<std::size_t>(src[j])] == L.object[a] &&
            std::fabs(proj_x[static_cast<std::size_t>(src[j])] - (static_cast<float>(xx) + 0.5f)) < kExactPx)
          continue;  // a sample of this surface landed on the pixel centre: nothing to resample
        for (int ch = 0; ch < 3; ++ch) rcol[3 * j + ch] = L.color[3 * a + ch] + (L.color[3 * b + ch] - L.color[3 * a + ch]) * f;
        rdepth[j] = z;
        if (!filled[j] || zbuf[j] > z * (1.f + kDepthTolerance)) src[j] = static_cast<std::int64_t>(a);
        filled[j] = 1;
      }
    }
  }
  // 3. Bad pixels: holes; silhouettes (a 4-neighbour reprojected from another object or from a depth
  //    more than the tolerance away: which side of the edge the pixel centre falls on changes between the
  //    eyes); and farther samples showing through a gap between two reprojected neighbours of one
  //    continuous nearer surface that no span covered (a torn or folded surface).
  std::vector<std::uint8_t> bad(n, 0);
  for (std::size_t j = 0; j < n; ++j) if (!filled[j]) { bad[j] = 1; ++out.holes; }
  auto obj_of = [&](std::size_t j) { return src[j] >= 0 ? L.object[static_cast<std::size_t>(src[j])] : -2; };
  auto edge = [&](std::size_t j, std::size_t k) {
    if (!filled[k]) return false;
    if (obj_of(j) != obj_of(k)) return true;
    if (obj_of(j) < 0) return false;
    return std::fabs(rdepth[j] - rdepth[k]) > kDepthTolerance * std::min(rdepth[j], rdepth[k]);
  };
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x < W; ++x) {
      const std::size_t j = static_cast<std::size_t>(y) * W + x;
      if (bad[j]) continue;
      if (src[j] >= 0) {
        const std::size_t i = static_cast<std::size_t>(src[j]);
        if (std::fabs(proj_x[i] - (static_cast<float>(x) + 0.5f)) < kExactPx &&
            std::fabs(proj_y[i] - (static_cast<float>(y) + 0.5f)) < kExactPx)
          continue;  // the left sample lies on this pixel's centre: it is the right eye's own sample
      }
      if ((x > 0 && edge(j, j - 1)) || (x + 1 < W && edge(j, j + 1)) || (y > 0 && edge(j, j - W)) ||
          (y + 1 < H && edge(j, j + W))) {
        bad[j] = 1;
        ++out.silhouettes;
      }
    }
  }
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
        if (!bad[j] && rdepth[j] > zmax) { bad[j] = 1; ++out.depth_mismatches; }
      }
    }
  }
  // G-buffer reads of the error detection: per right tile, the left-eye pixels its reprojection can reach
  // (see stereo.h). The depth range is that of the left samples that land in the right frame.
  float zmin = kInf, zmax = 0.f;
  bool any_env = false;
  for (std::size_t i = 0; i < n; ++i) {
    if (proj_row[i] < 0) continue;
    if (L.object[i] < 0) {
      any_env = true;
    } else {
      zmin = std::min(zmin, proj_z[i]);
      zmax = std::max(zmax, proj_z[i]);
    }
  }
  const bool any_hit = zmin <= zmax;
  // 4. Right eye, tile by tile: reuse valid pixels, trace bad ones (every sub-pixel of the grid).
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
      c.gbuffer_prefetch_bytes +=
          stereo_prefetch_texels(left, right, x0, y0, w, h, any_hit, zmin, zmax, any_env) * kGBufferTexelBytes;
      for (int yy = y0; yy < y0 + h; ++yy) {
        for (int xx = x0; xx < x0 + w; ++xx) {
          const std::size_t j = static_cast<std::size_t>(yy) * W + xx;
          c.tile_buffer_reads += 1;  // error-detection result
          if (!bad[j]) {
            const std::size_t i = static_cast<std::size_t>(src[j]);
            for (int ch = 0; ch < 3; ++ch) {
              R.fb.color[3 * j + ch] = rcol[3 * j + ch];
              R.fb.normal[3 * j + ch] = L.normal[3 * i + ch];
              R.fb.position[3 * j + ch] = L.position[3 * i + ch];
            }
            R.fb.object[j] = L.object[i];
            R.fb.depth[j] = L.object[i] >= 0 ? rdepth[j] : kInf;
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
