#include "sim_core/adaptive_sampling.h"

#include <algorithm>
#include <stdexcept>
#include <utility>
#include <vector>

#include "sim_core/low_discrepancy.h"

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

// A rectangle of a tile's samples: [x0, x1) x [y0, y1).
struct SampleSpan {
  int x0, y0, x1, y1;
};

// The samples of one tile (its tile buffer) and the schedule that fills them. The schedule may be limited
// to a part of the tile (`part`, in the tile's samples): each of those samples comes out as in the whole
// tile, and only they are written to the frame.
class TileSampler {
 public:
  TileSampler(TileContext& ctx, int x0, int y0, int w, int h, int k)
      : ctx_(ctx), x0_(x0), y0_(y0), w_(w), h_(h), k_(k), nx_(w * k), ny_(h * k),
        inv_k_(1.f / static_cast<float>(k)),
        samples_(static_cast<std::size_t>(nx_) * ny_), state_(samples_.size(), 0) {}

  SampleSpan whole() const { return {0, 0, nx_, ny_}; }
  // Full rate: every sample of `part` traced, row by row.
  void trace_all(const SampleSpan& part) {
    for (int j = part.y0; j < part.y1; ++j)
      for (int i = part.x0; i < part.x1; ++i) trace_at(i, j);
  }
  // Reference samples every `spacing` (and the last row/column), then the runs between them along X on
  // the reference rows, then along Y on every column. A sample depends only on the reference cell it lies
  // in (its four corner references and the X runs on the cell's two reference rows), so for `part` the
  // schedule runs over the cells that hold its samples (for the whole tile, in the whole tile's order).
  void trace_adaptive(int spacing, const SampleSpan& part);
  // With a sample buffer: traces the guard sub-samples of the pixel filter just outside the frame that
  // lie beyond `part`'s edges where they are the frame's edges.
  void trace_guard(FrameBuffers& fb, const SampleSpan& part);
  // Flushes `part` (whole pixels) into the frame buffer: pixels (their samples' box mean, final without
  // a resolve pass), geometry and sample kinds, and its samples into the sample buffer when there is one.
  void flush(FrameBuffers& fb, const SampleSpan& part);
  // Folds the schedule's statistics into the tile's counters and `stat`.
  void finish(int spacing, TileStat* stat) const;

 private:
  enum : std::uint8_t { kPending = 0, kTraced = 1, kInterpolated = 2 };
  TileContext& ctx_;
  const int x0_, y0_, w_, h_, k_, nx_, ny_;
  const float inv_k_;
  std::vector<SampleResult> samples_;
  std::vector<std::uint8_t> state_;
  std::uint64_t checks_ = 0, passed_ = 0, traced_ = 0, interpolated_ = 0;

  std::size_t at(int i, int j) const { return static_cast<std::size_t>(j) * nx_ + i; }
  void trace_at(int i, int j);
  // Traces the sample at frame sub-sample coordinates (sx, sy) (negative or past the frame: a guard sample).
  SampleResult trace_subsample(int sx, int sy);
  // The run of `count` samples strictly between known samples ia and ib along a line: interpolated when
  // the two are similar, traced otherwise. index_of(m) / trace_of(m) address its m-th sample (1-based).
  template <class IndexOf, class TraceOf>
  void resolve_run(std::size_t ia, std::size_t ib, int count, IndexOf index_of, TraceOf trace_of);
};

SampleResult TileSampler::trace_subsample(int sx, int sy) {
  // Position and seeds by place in the whole frame: a window of it (Camera::crop_x/y) samples like the
  // whole, to the bit (the position computed from the frame's sub-sample index, not the window's).
  const int fx = ctx_.camera.crop_x * k_ + sx, fy = ctx_.camera.crop_y * k_ + sy;
  const std::uint32_t key =
      sample_key(static_cast<std::uint32_t>(fx), static_cast<std::uint32_t>(fy), static_cast<std::uint32_t>(k_));
  ++traced_;
  ++ctx_.counters.tile_buffer_writes;
  return trace_frame_sample(ctx_, (static_cast<float>(fx) + 0.5f) * inv_k_, (static_cast<float>(fy) + 0.5f) * inv_k_,
                            key);
}

void TileSampler::trace_at(int i, int j) {
  samples_[at(i, j)] = trace_subsample(x0_ * k_ + i, y0_ * k_ + j);
  state_[at(i, j)] = kTraced;
}

void TileSampler::trace_guard(FrameBuffers& fb, const SampleSpan& part) {
  SampleBuffer& sb = fb.samples;
  if (sb.empty()) return;
  const int g = sb.guard;
  const int ix0 = x0_ * k_ + part.x0, iy0 = y0_ * k_ + part.y0, ix1 = x0_ * k_ + part.x1, iy1 = y0_ * k_ + part.y1;
  // Only on the whole frame's edges (a window's inner edges read its neighbours' samples, render.h).
  const Camera& cam = ctx_.camera;
  const int fx0 = cam.crop_x + x0_, fy0 = cam.crop_y + y0_;
  const int ex0 = fx0 == 0 && part.x0 == 0 ? ix0 - g : ix0;
  const int ex1 = fx0 + w_ == cam.frame_width() && part.x1 == nx_ ? ix1 + g : ix1;
  const int ey0 = fy0 == 0 && part.y0 == 0 ? iy0 - g : iy0;
  const int ey1 = fy0 + h_ == cam.frame_height() && part.y1 == ny_ ? iy1 + g : iy1;
  for (int sy = ey0; sy < ey1; ++sy)
    for (int sx = ex0; sx < ex1; ++sx) {
      if (sx >= ix0 && sx < ix1 && sy >= iy0 && sy < iy1) continue;  // the tile's own samples
      const SampleResult r = trace_subsample(sx, sy);
      sb.set(sx, sy, r.color, r.ambient, r.geom.object, r.geom.normal, r.geom.position);
    }
}

template <class IndexOf, class TraceOf>
void TileSampler::resolve_run(std::size_t ia, std::size_t ib, int count, IndexOf index_of, TraceOf trace_of) {
  if (count <= 0) return;
  Counters& c = ctx_.counters;
  ++checks_;
  c.tile_buffer_reads += 2;
  if (!similar(samples_[ia].geom, samples_[ib].geom, ctx_.cos_threshold)) {
    for (int m = 1; m <= count; ++m) trace_of(m);
    return;
  }
  ++passed_;
  for (int m = 1; m <= count; ++m) {
    const float f = static_cast<float>(m) / static_cast<float>(count + 1);
    SampleResult& s = samples_[index_of(m)];
    s.color = lerp(samples_[ia].color, samples_[ib].color, f);
    s.geom = interpolate_geometry(samples_[ia].geom, samples_[ib].geom, f);
    const AmbientSample &a = samples_[ia].ambient, &b = samples_[ib].ambient;
    s.ambient = {lerp(a.unoccluded, b.unoccluded, f), lerp(a.seen, b.seen, f), lerp(a.all, b.all, f)};
    state_[index_of(m)] = kInterpolated;
    ++interpolated_;
    c.tile_buffer_reads += 2;
    ++c.tile_buffer_writes;
  }
}

void TileSampler::trace_adaptive(int spacing, const SampleSpan& part) {
  std::vector<int> rx, ry;  // reference columns / rows: every `spacing`, plus the last one
  for (int i = 0; i < nx_; ++i) if (i % spacing == 0 || i == nx_ - 1) rx.push_back(i);
  for (int j = 0; j < ny_; ++j) if (j % spacing == 0 || j == ny_ - 1) ry.push_back(j);
  // The references bounding `part`'s cells: the last at or before its first sample, the first at or
  // after its last one (the whole tile: all of them).
  auto bounds = [](const std::vector<int>& refs, int lo, int hi) {
    std::size_t a = 0, b = refs.size() - 1;
    while (a + 1 < refs.size() && refs[a + 1] <= lo) ++a;
    while (b > 0 && refs[b - 1] >= hi - 1) --b;
    return std::pair<std::size_t, std::size_t>(a, b);
  };
  const auto [ax, bx] = bounds(rx, part.x0, part.x1);
  const auto [ay, by] = bounds(ry, part.y0, part.y1);
  for (std::size_t r = ay; r <= by; ++r)
    for (std::size_t c = ax; c <= bx; ++c) trace_at(rx[c], ry[r]);
  // X: along reference rows, between adjacent reference samples.
  for (std::size_t q = ay; q <= by; ++q) {
    const int j = ry[q];
    for (std::size_t r = ax; r < bx; ++r) {
      const int i0 = rx[r], i1 = rx[r + 1];
      resolve_run(at(i0, j), at(i1, j), i1 - i0 - 1, [&](int m) { return at(i0 + m, j); },
                  [&](int m) { trace_at(i0 + m, j); });
    }
  }
  // Y: along every column, between the (now known) samples of adjacent reference rows.
  for (int i = rx[ax]; i <= rx[bx]; ++i) {
    for (std::size_t r = ay; r < by; ++r) {
      const int j0 = ry[r], j1 = ry[r + 1];
      resolve_run(at(i, j0), at(i, j1), j1 - j0 - 1, [&](int m) { return at(i, j0 + m); },
                  [&](int m) { trace_at(i, j0 + m); });
    }
  }
}

void TileSampler::flush(FrameBuffers& fb, const SampleSpan& part) {
  const float inv_n = 1.f / static_cast<float>(k_ * k_);
  if (!fb.samples.empty())
    for (int j = part.y0; j < part.y1; ++j)
      for (int i = part.x0; i < part.x1; ++i) {
        const SampleResult& r = samples_[at(i, j)];
        fb.samples.set(x0_ * k_ + i, y0_ * k_ + j, r.color, r.ambient, r.geom.object, r.geom.normal, r.geom.position);
      }
  for (int jj = part.y0 / k_; jj < part.y1 / k_; ++jj) {
    for (int ii = part.x0 / k_; ii < part.x1 / k_; ++ii) {
      Vec3 sum;
      bool any_interp = false;
      for (int b = 0; b < k_; ++b)
        for (int a = 0; a < k_; ++a) {
          const std::size_t idx = at(ii * k_ + a, jj * k_ + b);
          sum += samples_[idx].color;
          any_interp |= state_[idx] == kInterpolated;
        }
      if (k_ > 1) ctx_.counters.tile_buffer_reads += static_cast<std::uint64_t>(k_) * k_;
      const SampleGeometry& g = samples_[at(ii * k_ + k_ / 2, jj * k_ + k_ / 2)].geom;
      const std::size_t p = static_cast<std::size_t>(y0_ + jj) * fb.width + (x0_ + ii);
      fb.store(p, k_ > 1 ? sum * inv_n : sum, g, any_interp ? kSampleInterpolated : kSampleTraced);
    }
  }
}

void TileSampler::finish(int spacing, TileStat* stat) const {
  Counters& c = ctx_.counters;
  c.samples_traced += traced_;
  c.samples_interpolated += interpolated_;
  c.interpolations += interpolated_;
  c.similarity_checks += checks_;
  stat->block = spacing;
  stat->samples_traced = traced_;
  stat->samples_interpolated = interpolated_;
  stat->similarity_checks = checks_;
  stat->similarity_passed = passed_;
  stat->similarity_ratio = checks_ ? static_cast<float>(passed_) / static_cast<float>(checks_) : 0.f;
}

}  // namespace

void render_tile(TileContext& ctx, FrameBuffers& fb, int x0, int y0, int w, int h, int k, int spacing,
                 TileStat* stat, const PixelRect* part) {
  TileSampler sampler(ctx, x0, y0, w, h, k);
  SampleSpan span = sampler.whole();
  if (part) {
    if (part->width < 1 || part->height < 1 || part->x0 < x0 || part->y0 < y0 || part->x0 + part->width > x0 + w ||
        part->y0 + part->height > y0 + h)
      throw std::invalid_argument("render_tile: the part is not inside the tile");
    span = {(part->x0 - x0) * k, (part->y0 - y0) * k, (part->x0 + part->width - x0) * k,
            (part->y0 + part->height - y0) * k};
  }
  if (spacing <= 1) {
    sampler.trace_all(span);
  } else {
    sampler.trace_adaptive(spacing, span);
  }
  sampler.trace_guard(fb, span);
  sampler.flush(fb, span);
  sampler.finish(spacing, stat);
}

}  // namespace sim_core
