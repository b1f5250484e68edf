#include "sim_core/sampling.h"

#include <algorithm>
#include <vector>

#include "sim_core/sampler.h"

namespace sim_core {

bool similar(const SampleGeometry& a, const SampleGeometry& b, float cos_threshold) {
  if (cos_threshold > 1.f) return false;  // a negative angle threshold: nothing is similar
  if (a.object != b.object) return false;
  if (a.object >= 0) {
    if (dot(a.normal, b.normal) < cos_threshold) return false;
    if (a.shadow_bits != b.shadow_bits) return false;
  }
  // Secondary rays follow the same scheme: their first hits must agree too.
  for (int s = 0; s < 2; ++s) {
    if (a.sec_object[s] != b.sec_object[s]) return false;
    if (a.sec_object[s] >= 0 && dot(a.sec_normal[s], b.sec_normal[s]) < cos_threshold) return false;
  }
  return a.sec_shadow_bits == b.sec_shadow_bits;
}

int multirate_block(int previous_block, float previous_ratio, std::uint64_t previous_checks,
                    const RenderSettings& settings) {
  int b = std::min(4, std::max(2, previous_block));
  if (previous_checks == 0) return b;
  if (previous_ratio >= settings.multirate_high) return std::min(4, b + 1);
  if (previous_ratio < settings.multirate_low) return std::max(2, b - 1);
  return b;
}

namespace {

SampleGeometry interpolate_geometry(const SampleGeometry& a, const SampleGeometry& b, float f) {
  SampleGeometry g = a;  // object, shadow bits and secondary hits agree (similarity passed)
  g.normal = normalize(lerp(a.normal, b.normal, f));
  g.position = lerp(a.position, b.position, f);
  g.depth = a.object >= 0 ? a.depth + (b.depth - a.depth) * f : kInf;
  return g;
}

}  // namespace

void render_tile(TileContext& ctx, FrameBuffers& fb, int x0, int y0, int w, int h, int k, int spacing,
                 TileStat* stat) {
  const int nx = w * k, ny = h * k;
  std::vector<SampleResult> samples(static_cast<std::size_t>(nx) * ny);
  std::vector<std::uint8_t> state(samples.size(), 0);  // 0 pending, 1 traced, 2 interpolated
  Counters& c = ctx.counters;
  const float inv_k = 1.f / static_cast<float>(k);
  std::uint64_t checks = 0, passed = 0, traced = 0, interpolated = 0;

  auto at = [&](int i, int j) -> std::size_t { return static_cast<std::size_t>(j) * nx + i; };
  auto trace_at = [&](int i, int j) {
    // Seeds by position in the full frame: a window of it (Camera::crop_x/y) samples like the whole.
    const std::uint32_t sx = static_cast<std::uint32_t>((ctx.camera.crop_x + x0) * k + i),
                        sy = static_cast<std::uint32_t>((ctx.camera.crop_y + y0) * k + j);
    const std::uint32_t key = hash_combine(hash_combine(hash_u32(sx), sy), static_cast<std::uint32_t>(k));
    const float px = static_cast<float>(x0) + (static_cast<float>(i) + 0.5f) * inv_k;
    const float py = static_cast<float>(y0) + (static_cast<float>(j) + 0.5f) * inv_k;
    samples[at(i, j)] = trace_sample(ctx, px, py, key);
    state[at(i, j)] = 1;
    ++traced;
    ++c.tile_buffer_writes;
  };
  // Handles the run of samples strictly between a and b (indices along a line): interpolate or trace.
  auto resolve_run = [&](std::size_t ia, std::size_t ib, int count, auto index_of, auto trace_of) {
    if (count <= 0) return;
    ++checks;
    c.tile_buffer_reads += 2;
    if (similar(samples[ia].geom, samples[ib].geom, ctx.cos_threshold)) {
      ++passed;
      for (int m = 1; m <= count; ++m) {
        const float f = static_cast<float>(m) / static_cast<float>(count + 1);
        SampleResult& s = samples[index_of(m)];
        s.color = lerp(samples[ia].color, samples[ib].color, f);
        s.geom = interpolate_geometry(samples[ia].geom, samples[ib].geom, f);
        state[index_of(m)] = 2;
        ++interpolated;
        c.tile_buffer_reads += 2;
        ++c.tile_buffer_writes;
      }
    } else {
      for (int m = 1; m <= count; ++m) trace_of(m);
    }
  };

  if (spacing <= 1) {
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) trace_at(i, j);
  } else {
    std::vector<int> rx, ry;  // reference columns / rows: every `spacing`, plus the last one
    for (int i = 0; i < nx; ++i) if (i % spacing == 0 || i == nx - 1) rx.push_back(i);
    for (int j = 0; j < ny; ++j) if (j % spacing == 0 || j == ny - 1) ry.push_back(j);
    for (int j : ry)
      for (int i : rx) trace_at(i, j);
    // X: along reference rows, between adjacent reference samples.
    for (int j : ry) {
      for (std::size_t r = 0; r + 1 < rx.size(); ++r) {
        const int i0 = rx[r], i1 = rx[r + 1];
        resolve_run(at(i0, j), at(i1, j), i1 - i0 - 1, [&](int m) { return at(i0 + m, j); },
                    [&](int m) { trace_at(i0 + m, j); });
      }
    }
    // Y: along every column, between the (now known) samples of adjacent reference rows.
    for (int i = 0; i < nx; ++i) {
      for (std::size_t r = 0; r + 1 < ry.size(); ++r) {
        const int j0 = ry[r], j1 = ry[r + 1];
        resolve_run(at(i, j0), at(i, j1), j1 - j0 - 1, [&](int m) { return at(i, j0 + m); },
                    [&](int m) { trace_at(i, j0 + m); });
      }
    }
  }

  // Resolve samples to pixels and flush the tile to the frame buffer.
  const float inv_n = 1.f / static_cast<float>(k * k);
  for (int jj = 0; jj < h; ++jj) {
    for (int ii = 0; ii < w; ++ii) {
      Vec3 sum;
      bool any_interp = false;
      for (int b = 0; b < k; ++b)
        for (int a = 0; a < k; ++a) {
          const std::size_t idx = at(ii * k + a, jj * k + b);
          sum += samples[idx].color;
          any_interp |= state[idx] == 2;
        }
      if (k > 1) c.tile_buffer_reads += static_cast<std::uint64_t>(k) * k;
      const SampleGeometry& g = samples[at(ii * k + k / 2, jj * k + k / 2)].geom;
      const std::size_t p = static_cast<std::size_t>(y0 + jj) * fb.width + (x0 + ii);
      const Vec3 col = k > 1 ? sum * inv_n : sum;
      fb.color[3 * p] = col.x; fb.color[3 * p + 1] = col.y; fb.color[3 * p + 2] = col.z;
      fb.depth[p] = g.depth;
      fb.object[p] = g.object;
      if (g.object >= 0) {
        fb.normal[3 * p] = g.normal.x; fb.normal[3 * p + 1] = g.normal.y; fb.normal[3 * p + 2] = g.normal.z;
      }
      fb.position[3 * p] = g.position.x; fb.position[3 * p + 1] = g.position.y; fb.position[3 * p + 2] = g.position.z;
      fb.kind[p] = any_interp ? 1 : 0;
    }
  }
  c.samples_traced += traced;
  c.samples_interpolated += interpolated;
  c.interpolations += interpolated;
  c.similarity_checks += checks;
  stat->x0 = x0; stat->y0 = y0; stat->width = w; stat->height = h;
  stat->block = spacing;
  stat->samples_traced = traced;
  stat->samples_interpolated = interpolated;
  stat->similarity_checks = checks;
  stat->similarity_passed = passed;
  stat->similarity_ratio = checks ? static_cast<float>(passed) / static_cast<float>(checks) : 0.f;
}

}  // namespace sim_core
