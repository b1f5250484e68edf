// The resolve pass: Cycles' Blackman-Harris pixel filter (weights, guard, constant and impulse frames) and
// the ambient denoiser (keeps a constant visibility, pools a noisy one on one surface without moving its
// mean, never mixes surfaces).
#include <cmath>
#include <vector>

#include "sim_core/resolve.h"

#include "check.h"

using sim_core::AmbientSample;
using sim_core::SampleBuffer;
using sim_core::Vec3;

namespace {

// Cycles' filter_func_blackman_harris(v, width) with its table's width 2 x filter_width (1.5 px).
double cycles_weight(double offset) {
  const double width = 3.0;
  const double v = 2.0 * 3.14159265358979323846 * (offset / width + 0.5);
  return 0.35875 - 0.48829 * std::cos(v) + 0.14128 * std::cos(2.0 * v) - 0.01168 * std::cos(3.0 * v);
}

// A frame of 12x8 pixels, k x k samples each, every sample on object 0 facing the camera at depth 10.
SampleBuffer frame(int k, bool ambient) {
  SampleBuffer b;
  b.allocate(12, 8, k, ambient);
  return b;
}

}  // namespace

int main() {
  {  // Weights: Cycles' window, 1 at the centre, 0 from +-1.5 px on.
    CHECK(std::fabs(sim_core::blackman_harris(0.f) - 1.f) < 1e-6f);
    CHECK(sim_core::blackman_harris(1.5f) == 0.f && sim_core::blackman_harris(-2.f) == 0.f);
    for (float x : {0.25f, 0.75f, 1.25f})
      CHECK(std::fabs(sim_core::blackman_harris(x) - static_cast<float>(cycles_weight(x))) < 1e-6f);
    // A 2x2 grid reads 2 sub-samples beyond each side of the pixel (offsets +-0.25, +-0.75, +-1.25).
    const sim_core::PixelFilter f(2);
    CHECK(f.guard == 2 && f.weights.size() == 6);
    double sum = 0.0;
    for (float w : f.weights) sum += w;
    CHECK(std::fabs(sum - 1.0) < 1e-6);
    CHECK(std::fabs(f.weights[2] / f.weights[1] - cycles_weight(0.25) / cycles_weight(0.75)) < 1e-5);
    CHECK(std::fabs(f.weights[0] - f.weights[5]) < 1e-7f);
    const sim_core::PixelFilter one(1);  // one sample per pixel: the pixel itself
    CHECK(one.guard == 0 && one.weights.size() == 1 && one.weights[0] == 1.f);
  }
  {  // A constant frame resolves to the constant everywhere, its edge pixels included (the guard ring).
    SampleBuffer b = frame(2, false);
    for (int sy = -b.guard; sy < 8 * 2 + b.guard; ++sy)
      for (int sx = -b.guard; sx < 12 * 2 + b.guard; ++sx) b.set(sx, sy, Vec3(0.3f, 0.5f, 0.7f), {}, -1, {}, {});
    std::vector<float> px(12 * 8 * 3);
    const sim_core::ResolveWork work = sim_core::resolve_pixels(b, 12, 8, Vec3(), px.data(), 2);
    const sim_core::Counters c = sim_core::resolve_counters(b, work, 12, 8);
    for (std::size_t i = 0; i < px.size(); i += 3) CHECK(std::fabs(px[i] - 0.3f) < 1e-6f && std::fabs(px[i + 2] - 0.7f) < 1e-6f);
    CHECK(c.resolve_taps == 6u * 12u * (20u + 8u));  // horizontal over 20 sample rows, vertical per pixel
    CHECK(c.resolve_bytes == 28u * 20u * sim_core::kResolveColorBytes);
    CHECK(c.ambient_filter_taps == 0u);
    sim_core::Counters parts;  // the guard ring goes with the rectangles on the frame's edges
    for (const sim_core::PixelRect r : {sim_core::PixelRect{0, 0, 12, 3}, sim_core::PixelRect{0, 3, 4, 5},
                                        sim_core::PixelRect{4, 3, 8, 5}})
      parts += sim_core::resolve_counters(b, work, 12, 8, r);
    CHECK(parts.resolve_taps == c.resolve_taps && parts.resolve_bytes == c.resolve_bytes);
  }
  {  // An impulse (one bright sub-sample) spreads over the neighbouring pixels as the separable window,
     // and keeps its energy (a sub-sample is a quarter of a pixel's).
    SampleBuffer b = frame(2, false);
    b.set(10, 7, Vec3(1.f, 1.f, 1.f), {}, -1, {}, {});  // pixel (5, 3), its sub-sample (0, 1)
    std::vector<float> px(12 * 8 * 3);
    sim_core::resolve_pixels(b, 12, 8, Vec3(), px.data(), 1);
    const sim_core::PixelFilter f(2);
    double total = 0.0;
    for (std::size_t i = 0; i < px.size(); i += 3) total += px[i];
    CHECK(std::fabs(total - 0.25) < 1e-5);
    // Pixel (5, 3) reads it as its own first column (tap guard) and second row (tap guard + 1).
    CHECK(std::fabs(px[(3 * 12 + 5) * 3] - f.weights[2] * f.weights[3]) < 1e-6f);
    CHECK(px[(3 * 12 + 8) * 3] == 0.f);  // beyond the support
  }
  {  // Ambient denoising on one surface: a noisy visibility (open rays alternating 0 and 16 of 16) pools
     // to its mean; a constant one is kept; another object's samples are never pooled in.
    SampleBuffer b = frame(1, true);
    const Vec3 unoccluded(0.5f, 0.5f, 0.5f), all(16.f, 16.f, 16.f);
    for (int y = 0; y < 8; ++y)
      for (int x = 0; x < 12; ++x) {
        const bool left = x < 6;
        const float open = left ? ((x + y) % 2 ? 16.f : 0.f) : 12.f;
        const Vec3 seen(open, open, open);
        const Vec3 colour = unoccluded * (open / 16.f) + Vec3(0.1f, 0.1f, 0.1f);
        b.set(x, y, colour, AmbientSample{unoccluded, seen, all}, left ? 0 : 1, Vec3(0.f, 0.f, 1.f),
              Vec3(static_cast<float>(x), static_cast<float>(y), 0.f));
      }
    std::vector<float> px(12 * 8 * 3);
    const sim_core::ResolveWork work = sim_core::resolve_pixels(b, 12, 8, Vec3(0.f, 0.f, 10.f), px.data(), 2);
    const sim_core::Counters c = sim_core::resolve_counters(b, work, 12, 8);
    double mean = 0.0, var = 0.0;
    int n = 0;
    for (int y = 2; y < 6; ++y)
      for (int x = 2; x < 4; ++x) { mean += px[(y * 12 + x) * 3]; ++n; }
    mean /= n;
    for (int y = 2; y < 6; ++y)
      for (int x = 2; x < 4; ++x) var += (px[(y * 12 + x) * 3] - mean) * (px[(y * 12 + x) * 3] - mean);
    CHECK(std::fabs(mean - (0.1 + 0.25)) < 0.03);   // half open on average
    CHECK(var / n < 0.02 * 0.25 * 0.25);           // the raw samples' variance is 0.25^2
    for (int y = 0; y < 8; ++y)
      for (int x = 6; x < 12; ++x) CHECK(std::fabs(px[(y * 12 + x) * 3] - (0.1f + 0.5f * 0.75f)) < 1e-5f);
    CHECK(c.ambient_filter_taps > 0u && c.resolve_taps == 0u);
    // Rectangles that tile the frame (the tiles of a render) share its counts exactly.
    sim_core::Counters parts;
    for (const sim_core::PixelRect r : {sim_core::PixelRect{0, 0, 5, 3}, sim_core::PixelRect{5, 0, 7, 3},
                                        sim_core::PixelRect{0, 3, 5, 5}, sim_core::PixelRect{5, 3, 7, 5}})
      parts += sim_core::resolve_counters(b, work, 12, 8, r);
    CHECK(parts.ambient_filter_taps == c.ambient_filter_taps && parts.resolve_bytes == c.resolve_bytes);
    CHECK(c.resolve_bytes == 12u * 8u * (sim_core::kResolveColorBytes + sim_core::kResolveAmbientBytes));
  }
  {  // The resolve's reach (what a window's apron must hold): a pixel's value changes with a sample d
     // sub-samples past its own exactly when d <= resolve_reach: the filter's guard (k sub-samples, 1 px)
     // plus, with AO, the ambient pool around each of them (2k, 2 px). 1 to 3 px whatever k is.
    for (int k = 1; k <= 4; ++k)
      for (bool ambient : {false, true}) {
        const int reach = sim_core::resolve_reach(k, ambient);
        CHECK(reach == (k > 1 ? k : 0) + (ambient ? 2 * k : 0));
        CHECK(sim_core::resolve_reach_pixels(k, ambient) == (k > 1 ? 1 : 0) + (ambient ? 2 : 0));
        if (k == 1 && !ambient) continue;
        const int w = 16, h = 12, px = 6, py = 5;
        auto filled = [&](int perturbed_x) {
          SampleBuffer b;
          b.allocate(w, h, k, ambient);
          const int first = -b.guard, last_x = w * k + b.guard, last_y = h * k + b.guard;
          for (int sy = first; sy < last_y; ++sy)
            for (int sx = first; sx < last_x; ++sx) {
              const bool hit = sx == perturbed_x && sy == py * k;
              const float open = hit ? 16.f : static_cast<float>((sx * 7 + sy * 3) % 9);
              const float c = hit ? 5.f : 0.1f + 0.01f * static_cast<float>((sx + 2 * sy) % 5);
              b.set(sx, sy, Vec3(c, c, c),
                    AmbientSample{Vec3(0.5f, 0.5f, 0.5f), Vec3(open, open, open), Vec3(16.f, 16.f, 16.f)}, 0,
                    Vec3(0.f, 0.f, 1.f), Vec3(static_cast<float>(sx), static_cast<float>(sy), 0.f));
            }
          std::vector<float> out(static_cast<std::size_t>(w * h * 3));
          sim_core::resolve_pixels(b, w, h, Vec3(0.f, 0.f, 10.f), out.data(), 1);
          return out[static_cast<std::size_t>((py * w + px) * 3)];
        };
        const float base = filled(-1000);
        for (int d = 1; d <= reach + 2; ++d) {
          const bool changed = filled((px + 1) * k - 1 + d) != base;
          CHECK(changed == (d <= reach));
        }
      }
  }
  return check_exit_code();
}
