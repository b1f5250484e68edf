#include "sim_core/resolve.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "sim_core/parallel.h"

namespace sim_core {

float blackman_harris(float offset) {
  if (!(std::fabs(offset) < kPixelFilterRadius)) return 0.f;
  // Cycles' filter_func_blackman_harris over its table's width (2 x filter_width).
  const double v = 2.0 * 3.14159265358979323846 * (static_cast<double>(offset) / (2.0 * kPixelFilterRadius) + 0.5);
  const double w = 0.35875 - 0.48829 * std::cos(v) + 0.14128 * std::cos(2.0 * v) - 0.01168 * std::cos(3.0 * v);
  return static_cast<float>(std::max(0.0, w));
}

PixelFilter::PixelFilter(int k_) : k(k_) {
  if (k < 1) throw std::invalid_argument("PixelFilter: the sub-sample grid must be at least 1x1");
  if (k == 1) {  // one sample per pixel: the pixel itself
    weights = {1.f};
    return;
  }
  // Sub-sample j (0 = the pixel's first) sits at (j + 0.5) / k - 0.5 px from the pixel centre.
  auto offset = [&](int j) { return (static_cast<float>(j) + 0.5f) / static_cast<float>(k) - 0.5f; };
  while (blackman_harris(offset(-guard - 1)) > 0.f) ++guard;
  double sum = 0.0;
  for (int j = -guard; j < k + guard; ++j) {
    weights.push_back(blackman_harris(offset(j)));
    sum += weights.back();
  }
  for (float& w : weights) w = static_cast<float>(w / sum);
}

int ambient_reach(int k) { return static_cast<int>(std::ceil(kAmbientRadius * static_cast<float>(k))); }

int resolve_reach(int k, bool ambient) {
  if (k < 1) throw std::invalid_argument("resolve_reach: the sub-sample grid must be at least 1x1");
  return (k > 1 ? PixelFilter(k).guard : 0) + (ambient ? ambient_reach(k) : 0);
}

int resolve_reach_pixels(int k, bool ambient) { return (resolve_reach(k, ambient) + k - 1) / k; }

void SampleBuffer::allocate(int pixel_width, int pixel_height, int k_, bool ambient_) {
  k = k_;
  guard = PixelFilter(k).guard;
  width = pixel_width * k + 2 * guard;
  height = pixel_height * k + 2 * guard;
  ambient = ambient_;
  const std::size_t n = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  color.assign(n * 3, 0.f);
  ambient_samples.assign(ambient ? n : 0, AmbientSample{});
  normal.assign(ambient ? n : 0, Vec3());
  position.assign(ambient ? n : 0, Vec3());
  object.assign(ambient ? n : 0, -1);
}

void SampleBuffer::set(int sx, int sy, Vec3 c, const AmbientSample& a, std::int32_t obj, Vec3 n, Vec3 p) {
  const std::size_t i = index(sx, sy);
  color[3 * i] = c.x; color[3 * i + 1] = c.y; color[3 * i + 2] = c.z;
  if (!ambient) return;
  ambient_samples[i] = a;
  object[i] = obj;
  normal[i] = n;
  position[i] = p;
}

namespace {

bool has_ambient(const AmbientSample& a) { return max_component(a.all) > 0.f; }

// Step 1: each sample's visible share of the ambient light from its pool of same-surface neighbours.
// `taps` gets each sample's neighbour count.
void denoise_ambient(SampleBuffer& b, Vec3 eye, std::vector<std::uint16_t>* taps, int threads) {
  const int reach = ambient_reach(b.k);
  const float sigma = static_cast<float>(b.k);  // 1 px
  std::vector<float> spatial(static_cast<std::size_t>((2 * reach + 1) * (2 * reach + 1)));
  for (int dy = -reach; dy <= reach; ++dy)
    for (int dx = -reach; dx <= reach; ++dx) {
      const float d2 = static_cast<float>(dx * dx + dy * dy);
      spatial[static_cast<std::size_t>((dy + reach) * (2 * reach + 1) + dx + reach)] =
          d2 <= static_cast<float>(reach * reach) ? std::exp(-d2 / (2.f * sigma * sigma)) : 0.f;
    }
  std::vector<float> out(b.color);
  taps->assign(b.color.size() / 3, 0);
  parallel_chunks(static_cast<std::size_t>(b.height), threads, 8, [&](std::size_t begin, std::size_t end) {
    for (std::size_t y = begin; y < end; ++y) {
      const int yi = static_cast<int>(y);
      for (int x = 0; x < b.width; ++x) {
        const std::size_t i = y * static_cast<std::size_t>(b.width) + static_cast<std::size_t>(x);
        const AmbientSample& a = b.ambient_samples[i];
        if (b.object[i] < 0 || !has_ambient(a)) continue;
        std::uint16_t n_taps = 0;
        const Vec3 n = b.normal[i], p = b.position[i];
        const float tolerance = kAmbientPlaneTolerance * length(p - eye);
        Vec3 seen, all;
        for (int dy = -reach; dy <= reach; ++dy) {
          const int yj = yi + dy;
          if (yj < 0 || yj >= b.height) continue;
          for (int dx = -reach; dx <= reach; ++dx) {
            const int xj = x + dx;
            const float g = spatial[static_cast<std::size_t>((dy + reach) * (2 * reach + 1) + dx + reach)];
            if (xj < 0 || xj >= b.width || !(g > 0.f)) continue;
            ++n_taps;
            const std::size_t j = static_cast<std::size_t>(yj) * static_cast<std::size_t>(b.width) +
                                  static_cast<std::size_t>(xj);
            const AmbientSample& q = b.ambient_samples[j];
            if (b.object[j] != b.object[i] || !has_ambient(q)) continue;
            if (dot(n, b.normal[j]) < kAmbientNormalCos) continue;
            if (std::fabs(dot(n, b.position[j] - p)) > tolerance) continue;
            seen += q.seen * g;
            all += q.all * g;
          }
        }
        (*taps)[i] = n_taps;
        // The sample's colour holds unoccluded x (seen / all) of its own rays; it takes the pool's share.
        for (int c = 0; c < 3; ++c) {
          const float own = a.all[c] > 0.f ? a.seen[c] / a.all[c] : 0.f;
          const float pooled = all[c] > 0.f ? seen[c] / all[c] : own;
          out[3 * i + static_cast<std::size_t>(c)] =
              std::max(0.f, b.color[3 * i + static_cast<std::size_t>(c)] + a.unoccluded[c] * (pooled - own));
        }
      }
    }
  });
  b.color.swap(out);
}

// Step 2: the separable pixel filter (k > 1).
void filter_pixels(const SampleBuffer& b, int pixel_width, int pixel_height, float* pixels, int threads) {
  const PixelFilter filter(b.k);
  const int k = b.k, taps = static_cast<int>(filter.weights.size());
  // Horizontal pass over every sample row: one value per pixel column. The guard makes every pixel's
  // footprint complete, so the normalised weights hold everywhere.
  std::vector<float> rows(static_cast<std::size_t>(b.height) * static_cast<std::size_t>(pixel_width) * 3);
  parallel_chunks(static_cast<std::size_t>(b.height), threads, 16, [&](std::size_t begin, std::size_t end) {
    for (std::size_t r = begin; r < end; ++r) {
      const float* src = &b.color[r * static_cast<std::size_t>(b.width) * 3];
      float* dst = &rows[r * static_cast<std::size_t>(pixel_width) * 3];
      for (int x = 0; x < pixel_width; ++x) {
        double acc[3] = {0.0, 0.0, 0.0};
        const float* s = src + static_cast<std::size_t>(x) * static_cast<std::size_t>(k) * 3;  // tap 0
        for (int t = 0; t < taps; ++t)
          for (int c = 0; c < 3; ++c) acc[c] += static_cast<double>(filter.weights[t]) * s[3 * t + c];
        for (int c = 0; c < 3; ++c) dst[3 * x + c] = static_cast<float>(acc[c]);
      }
    }
  });
  // Vertical pass: each pixel from the rows of its footprint.
  parallel_chunks(static_cast<std::size_t>(pixel_height), threads, 16, [&](std::size_t begin, std::size_t end) {
    for (std::size_t y = begin; y < end; ++y)
      for (int x = 0; x < pixel_width; ++x) {
        double acc[3] = {0.0, 0.0, 0.0};
        for (int t = 0; t < taps; ++t) {
          const float* s = &rows[((y * static_cast<std::size_t>(k) + static_cast<std::size_t>(t)) *
                                      static_cast<std::size_t>(pixel_width) + static_cast<std::size_t>(x)) * 3];
          for (int c = 0; c < 3; ++c) acc[c] += static_cast<double>(filter.weights[t]) * s[c];
        }
        float* p = &pixels[(y * static_cast<std::size_t>(pixel_width) + static_cast<std::size_t>(x)) * 3];
        for (int c = 0; c < 3; ++c) p[c] = static_cast<float>(acc[c]);
      }
  });
}

}  // namespace

ResolveWork resolve_pixels(SampleBuffer& samples, int pixel_width, int pixel_height, Vec3 eye, float* pixels,
                           int threads) {
  const int guard = PixelFilter(samples.k).guard;
  if (samples.guard != guard || samples.width != pixel_width * samples.k + 2 * guard ||
      samples.height != pixel_height * samples.k + 2 * guard)
    throw std::invalid_argument("resolve_pixels: sample buffer does not match the frame");
  ResolveWork work;
  if (samples.ambient) denoise_ambient(samples, eye, &work.ambient_taps, threads);
  if (samples.k > 1) {
    filter_pixels(samples, pixel_width, pixel_height, pixels, threads);
  } else {
    std::copy(samples.color.begin(), samples.color.end(), pixels);
  }
  return work;
}

Counters resolve_counters(const SampleBuffer& samples, const ResolveWork& work, int pixel_width, int pixel_height,
                          PixelRect rect) {
  if (rect.width <= 0) rect = {0, 0, pixel_width, pixel_height};
  if (rect.x0 < 0 || rect.y0 < 0 || rect.height <= 0 || rect.x0 + rect.width > pixel_width ||
      rect.y0 + rect.height > pixel_height)
    throw std::invalid_argument("resolve_counters: the rectangle is outside the frame");
  // The rectangle's samples, with the guard ring where it reaches the buffer's edge.
  const int k = samples.k, g = samples.guard;
  const int x0 = rect.x0 == 0 ? 0 : rect.x0 * k + g, y0 = rect.y0 == 0 ? 0 : rect.y0 * k + g;
  const int x1 = rect.x0 + rect.width == pixel_width ? samples.width : (rect.x0 + rect.width) * k + g;
  const int y1 = rect.y0 + rect.height == pixel_height ? samples.height : (rect.y0 + rect.height) * k + g;
  const auto columns = static_cast<std::uint64_t>(x1 - x0), rows = static_cast<std::uint64_t>(y1 - y0);
  Counters c;
  if (!work.ambient_taps.empty())
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x)
        c.ambient_filter_taps +=
            work.ambient_taps[static_cast<std::size_t>(y) * static_cast<std::size_t>(samples.width) +
                              static_cast<std::size_t>(x)];
  if (k > 1) {  // horizontal pass: every sample row of the pixels' footprint; vertical: every pixel
    const auto taps = static_cast<std::uint64_t>(PixelFilter(k).weights.size());
    c.resolve_taps = taps * static_cast<std::uint64_t>(rect.width) * (rows + static_cast<std::uint64_t>(rect.height));
  }
  c.resolve_bytes = columns * rows * (kResolveColorBytes + (samples.ambient ? kResolveAmbientBytes : 0));
  return c;
}

}  // namespace sim_core
