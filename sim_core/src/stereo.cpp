#include "sim_core/stereo.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "sim_core/low_discrepancy.h"

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

namespace {

// Phase 1: where every left-eye sample lands in the right eye.
struct Reprojection {
  std::vector<std::int64_t> src;         // per right pixel: left pixel feeding it, -1 = hole
  std::vector<float> zbuf;               // per right pixel: right-eye depth of that source
  std::vector<float> proj_x, proj_y, proj_z;  // per left pixel: right-eye pixel coordinates and depth
  std::vector<std::int32_t> proj_row;    // per left pixel: right-eye row, -1 when it lands outside
};

// Phase 2: the right eye's colour and depth from the reprojected samples.
struct Resampled {
  std::vector<float> color, depth;
  std::vector<std::uint8_t> filled;
};

// The depth range of the left samples that land in the right frame (G-buffer prefetch, stereo.h).
struct LandedDepths {
  float zmin = kInf, zmax = 0.f;
  bool any_env = false;
  bool any_hit() const { return zmin <= zmax; }
};

bool same_surface(const FrameBuffers& L, const Reprojection& rp, std::size_t a, std::size_t b) {
  if (L.object[a] < 0 || L.object[a] != L.object[b]) return false;
  const float za = rp.proj_z[a], zb = rp.proj_z[b];
  return !(std::fabs(za - zb) > kDepthTolerance * std::min(za, zb));
}

// 1. Reprojects every left-eye sample (hit point, or direction of a miss) into the right eye; a z-buffer
//    keeps the nearest. Counts one reprojection per left sample.
Reprojection reproject_left(const FrameBuffers& L, const Camera& right, Counters* rc) {
  const int W = L.width, H = L.height;
  const std::size_t n = static_cast<std::size_t>(W) * H;
  Reprojection rp{std::vector<std::int64_t>(n, -1), std::vector<float>(n, kInf), std::vector<float>(n, -1.f),
                  std::vector<float>(n, -1.f), std::vector<float>(n, kInf), std::vector<std::int32_t>(n, -1)};
  for (std::size_t i = 0; i < n; ++i) {
    ++rc->reprojections;
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
    rp.proj_x[i] = u;
    rp.proj_y[i] = v;
    rp.proj_z[i] = z;
    rp.proj_row[i] = y;
    const std::size_t j = static_cast<std::size_t>(y) * W + x;
    if (rp.src[j] < 0 || z < rp.zbuf[j]) { rp.src[j] = static_cast<std::int64_t>(i); rp.zbuf[j] = z; }
  }
  return rp;
}

// 2. Sub-pixel resampling along reprojected spans: two horizontally adjacent left samples on one
//    continuous surface (same object, depths within tolerance, same target row) bound a span of right
//    pixels; each right pixel centre inside it takes the linear interpolation of the two samples, unless
//    a nearer surface landed there. Gaps a magnified surface leaves in the splat are filled the same way.
//    What remains without a source is a hole (disocclusion or out of frame). Updates rp.src.
Resampled resample_spans(const FrameBuffers& L, Reprojection* rp) {
  const int W = L.width, H = L.height;
  const std::size_t n = static_cast<std::size_t>(W) * H;
  std::vector<std::int64_t>& src = rp->src;
  Resampled rs{std::vector<float>(3 * n, 0.f), std::vector<float>(n, kInf), std::vector<std::uint8_t>(n, 0)};
  for (std::size_t j = 0; j < n; ++j) {
    if (src[j] < 0) continue;
    const std::size_t i = static_cast<std::size_t>(src[j]);
    for (int ch = 0; ch < 3; ++ch) rs.color[3 * j + ch] = L.color[3 * i + ch];
    rs.depth[j] = rp->zbuf[j];
    rs.filled[j] = 1;
  }
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x + 1 < W; ++x) {
      const std::size_t a = static_cast<std::size_t>(y) * W + x, b = a + 1;
      if (rp->proj_row[a] < 0 || rp->proj_row[a] != rp->proj_row[b] || !same_surface(L, *rp, a, b)) continue;
      const float za = rp->proj_z[a], zb = rp->proj_z[b];
      const float ua = rp->proj_x[a], ub = rp->proj_x[b];
      if (!(ub > ua) || ub - ua > static_cast<float>(kMaxSpan)) continue;  // fold-over or torn span
      const int first = std::max(0, static_cast<int>(std::ceil(ua - 0.5f)));
      const int last = std::min(W - 1, static_cast<int>(std::ceil(ub - 0.5f)) - 1);
      const std::size_t row = static_cast<std::size_t>(rp->proj_row[a]) * W;
      for (int xx = first; xx <= last; ++xx) {
        const float f = (static_cast<float>(xx) + 0.5f - ua) / (ub - ua);
        const float z = za + (zb - za) * f;
        const std::size_t j = row + xx;
        if (rs.filled[j] && rp->zbuf[j] < z * (1.f - kDepthTolerance)) continue;  // a nearer surface is in front
        if (rs.filled[j] && src[j] >= 0 && L.object[static_cast<std::size_t>(src[j])] == L.object[a] &&
            std::fabs(rp->proj_x[static_cast<std::size_t>(src[j])] - (static_cast<float>(xx) + 0.5f)) < kExactPx)
          continue;  // a sample of this surface landed on the pixel centre: nothing to resample
        for (int ch = 0; ch < 3; ++ch)
          rs.color[3 * j + ch] = L.color[3 * a + ch] + (L.color[3 * b + ch] - L.color[3 * a + ch]) * f;
        rs.depth[j] = z;
        if (!rs.filled[j] || rp->zbuf[j] > z * (1.f + kDepthTolerance)) src[j] = static_cast<std::int64_t>(a);
        rs.filled[j] = 1;
      }
    }
  }
  return rs;
}

// 3a. Holes and silhouettes: a pixel without a source; a pixel whose 4-neighbour was reprojected from
//     another object or from a depth more than the tolerance away (which side of the edge the pixel centre
//     falls on changes between the eyes), unless a left sample lies exactly on its centre.
void mark_holes_and_silhouettes(const FrameBuffers& L, const Reprojection& rp, const Resampled& rs,
                                std::vector<std::uint8_t>* bad, StereoOutput* out) {
  const int W = L.width, H = L.height;
  const std::size_t n = static_cast<std::size_t>(W) * H;
  for (std::size_t j = 0; j < n; ++j) if (!rs.filled[j]) { (*bad)[j] = 1; ++out->holes; }
  auto obj_of = [&](std::size_t j) { return rp.src[j] >= 0 ? L.object[static_cast<std::size_t>(rp.src[j])] : -2; };
  auto edge = [&](std::size_t j, std::size_t k) {
    if (!rs.filled[k]) return false;
    if (obj_of(j) != obj_of(k)) return true;
    if (obj_of(j) < 0) return false;
    return std::fabs(rs.depth[j] - rs.depth[k]) > kDepthTolerance * std::min(rs.depth[j], rs.depth[k]);
  };
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x < W; ++x) {
      const std::size_t j = static_cast<std::size_t>(y) * W + x;
      if ((*bad)[j]) continue;
      if (rp.src[j] >= 0) {
        const std::size_t i = static_cast<std::size_t>(rp.src[j]);
        if (std::fabs(rp.proj_x[i] - (static_cast<float>(x) + 0.5f)) < kExactPx &&
            std::fabs(rp.proj_y[i] - (static_cast<float>(y) + 0.5f)) < kExactPx)
          continue;  // the left sample lies on this pixel's centre: it is the right eye's own sample
      }
      if ((x > 0 && edge(j, j - 1)) || (x + 1 < W && edge(j, j + 1)) || (y > 0 && edge(j, j - W)) ||
          (y + 1 < H && edge(j, j + W))) {
        (*bad)[j] = 1;
        ++out->silhouettes;
      }
    }
  }
}

// 3b. Depth mismatches: farther samples showing through a gap between two reprojected neighbours of one
//     continuous nearer surface that no span covered (a torn or folded surface).
void mark_depth_mismatches(const FrameBuffers& L, const Reprojection& rp, const Resampled& rs,
                           std::vector<std::uint8_t>* bad, StereoOutput* out) {
  const int W = L.width, H = L.height;
  for (int y = 0; y < H; ++y) {
    for (int x = 0; x + 1 < W; ++x) {
      const std::size_t a = static_cast<std::size_t>(y) * W + x, b = a + 1;
      if (rp.proj_row[a] < 0 || rp.proj_row[b] < 0 || !same_surface(L, rp, a, b)) continue;
      const int ua = static_cast<int>(rp.proj_x[a]), ub = static_cast<int>(rp.proj_x[b]);
      const int lo = std::min(ua, ub), hi = std::max(ua, ub);
      if (hi - lo < 2 || hi - lo > kMaxSpan) continue;
      const int row = rp.proj_row[a];
      const float zmax = std::max(rp.proj_z[a], rp.proj_z[b]) * (1.f + kDepthTolerance);
      for (int xx = lo + 1; xx < hi; ++xx) {
        const std::size_t j = static_cast<std::size_t>(row) * W + xx;
        if (!(*bad)[j] && rs.depth[j] > zmax) { (*bad)[j] = 1; ++out->depth_mismatches; }
      }
    }
  }
}

LandedDepths landed_depths(const FrameBuffers& L, const Reprojection& rp) {
  LandedDepths d;
  const std::size_t n = rp.proj_row.size();
  for (std::size_t i = 0; i < n; ++i) {
    if (rp.proj_row[i] < 0) continue;
    if (L.object[i] < 0) {
      d.any_env = true;
    } else {
      d.zmin = std::min(d.zmin, rp.proj_z[i]);
      d.zmax = std::max(d.zmax, rp.proj_z[i]);
    }
  }
  return d;
}

// A valid right-eye pixel j takes its resampled colour and the G-buffer of its left source i.
void reuse_pixel(const FrameBuffers& L, const Resampled& rs, std::size_t i, std::size_t j, FrameBuffers* R) {
  for (int ch = 0; ch < 3; ++ch) {
    R->color[3 * j + ch] = rs.color[3 * j + ch];
    R->normal[3 * j + ch] = L.normal[3 * i + ch];
    R->position[3 * j + ch] = L.position[3 * i + ch];
  }
  R->object[j] = L.object[i];
  R->depth[j] = L.object[i] >= 0 ? rs.depth[j] : kInf;
  R->kind[j] = kSampleReused;
}

// A bad right-eye pixel is traced at every sub-pixel of the k x k grid (its own sample keys).
void trace_pixel(TileContext& ctx, int xx, int yy, int k, TileStat* stat, FrameBuffers* R) {
  const float inv_k = 1.f / static_cast<float>(k);
  Vec3 sum;
  SampleGeometry centre;
  for (int b = 0; b < k; ++b)
    for (int a = 0; a < k; ++a) {
      const std::uint32_t sx = static_cast<std::uint32_t>(xx * k + a), sy = static_cast<std::uint32_t>(yy * k + b);
      const std::uint32_t key = sample_key(sx, sy, static_cast<std::uint32_t>(k) | 0x100u);
      const SampleResult s = trace_sample(ctx, static_cast<float>(xx) + (a + 0.5f) * inv_k,
                                          static_cast<float>(yy) + (b + 0.5f) * inv_k, key);
      sum += s.color;
      if (a == k / 2 && b == k / 2) centre = s.geom;
      ++stat->samples_traced;
      ++ctx.counters.samples_traced;
      ++ctx.counters.tile_buffer_writes;
    }
  const Vec3 col = k > 1 ? sum * (1.f / static_cast<float>(k * k)) : sum;
  R->store(static_cast<std::size_t>(yy) * R->width + xx, col, centre, kSampleTraced);
}

}  // namespace

StereoOutput render_stereo(const Scene& scene, const Camera& left, const Camera& right,
                           const RenderSettings& settings, int threads, const MultirateState* previous,
                           const CacheConfig& cache, const TraceOptions& trace, const CacheConfig& texture_cache) {
  right.validate();
  if (left.width != right.width || left.height != right.height)
    throw std::invalid_argument("stereo eyes must have the same resolution");
  StereoOutput out;
  out.left = render_frame(scene, left, settings, threads, previous, cache, trace, texture_cache);
  const FrameBuffers& L = out.left.fb;
  const int W = L.width, H = L.height;
  const std::size_t n = static_cast<std::size_t>(W) * H;
  RenderOutput& R = out.right;
  // 1-3: reproject, resample, find the bad pixels (see the phase functions above).
  Reprojection rp = reproject_left(L, right, &R.counters);
  const Resampled rs = resample_spans(L, &rp);
  std::vector<std::uint8_t> bad(n, 0);
  mark_holes_and_silhouettes(L, rp, rs, &bad, &out);
  mark_depth_mismatches(L, rp, rs, &bad, &out);
  const LandedDepths landed = landed_depths(L, rp);
  // 4. Right eye, tile by tile: reuse valid pixels, trace bad ones (every sub-pixel of the grid).
  R.fb.allocate(W, H);
  const int k = settings.subgrid();
  render_tiles(scene, right, settings, cache, TileGrid(W, H, settings.tile_size), threads, trace, &R,
               [&](TileContext& ctx, TileStat& stat, std::size_t) {
                 ctx.counters.gbuffer_prefetch_bytes +=
                     stereo_prefetch_texels(left, right, stat.x0, stat.y0, stat.width, stat.height, landed.any_hit(),
                                            landed.zmin, landed.zmax, landed.any_env) * kGBufferTexelBytes;
                 for (int yy = stat.y0; yy < stat.y0 + stat.height; ++yy) {
                   for (int xx = stat.x0; xx < stat.x0 + stat.width; ++xx) {
                     const std::size_t j = static_cast<std::size_t>(yy) * W + xx;
                     ctx.counters.tile_buffer_reads += 1;  // error-detection result
                     if (bad[j]) {
                       trace_pixel(ctx, xx, yy, k, &stat, &R.fb);
                       continue;
                     }
                     reuse_pixel(L, rs, static_cast<std::size_t>(rp.src[j]), j, &R.fb);
                     ++stat.samples_reused;
                     ++ctx.counters.samples_reused;
                     ++ctx.counters.tile_buffer_writes;
                   }
                 }
               },
               texture_cache);
  R.multirate = out.left.multirate;
  out.reuse_ratio = n ? static_cast<double>(R.counters.samples_reused) / static_cast<double>(n) : 0.0;
  return out;
}

}  // namespace sim_core
