// SSIM kernel against brute force (each window's means and covariances summed directly, scikit-image's
// definition), box and Gaussian, grey and colour, tiny and odd sizes; thread-count invariance; NaN/Inf
// propagate to the result; bad sizes throw.
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>
#include <stdexcept>
#include <vector>

#include "sim_core/ssim.h"

#include "check.h"

// Direct per-window SSIM mean over full windows (the same crop scikit-image applies).
static double brute_ssim(const std::vector<double>& x, const std::vector<double>& y, int h, int w, int c,
                         bool gaussian, double data_range) {
  const int win = gaussian ? 11 : 7;
  std::vector<double> wt(static_cast<std::size_t>(win) * win);
  const double* taps = sim_core::ssim_gaussian_taps();
  for (int i = 0; i < win; ++i)
    for (int j = 0; j < win; ++j) wt[i * win + j] = gaussian ? taps[i] * taps[j] : 1.0 / (win * win);
  const double np = static_cast<double>(win) * win;
  const double cov = gaussian ? 1.0 : np / (np - 1.0);
  const double c1 = (0.01 * data_range) * (0.01 * data_range), c2 = (0.03 * data_range) * (0.03 * data_range);
  double total = 0.0;
  for (int k = 0; k < c; ++k)
    for (int r = 0; r + win <= h; ++r)
      for (int q = 0; q + win <= w; ++q) {
        double ux = 0, uy = 0, uxx = 0, uyy = 0, uxy = 0;
        for (int i = 0; i < win; ++i)
          for (int j = 0; j < win; ++j) {
            const std::size_t at = (static_cast<std::size_t>(r + i) * w + (q + j)) * c + k;
            const double g = wt[i * win + j], a = x[at], b = y[at];
            ux += g * a;
            uy += g * b;
            uxx += g * a * a;
            uyy += g * b * b;
            uxy += g * a * b;
          }
        const double vx = cov * (uxx - ux * ux), vy = cov * (uyy - uy * uy), vxy = cov * (uxy - ux * uy);
        total += (2 * ux * uy + c1) * (2 * vxy + c2) / ((ux * ux + uy * uy + c1) * (vx + vy + c2));
      }
  return total / (static_cast<double>(c) * (h - win + 1) * (w - win + 1));
}

// Small, odd and colour sizes, box and Gaussian, identical and noisy pairs: brute force, thread counts,
// float32 input.
void check_against_brute_force(std::mt19937& rng) {
  std::uniform_real_distribution<double> val(0.0, 1.0);
  std::normal_distribution<double> noise(0.0, 1.0);
  const int sizes[][3] = {{7, 7, 1}, {11, 11, 3}, {12, 9, 2}, {23, 41, 3}, {40, 13, 1}, {70, 37, 4}};
  for (const auto& s : sizes) {
    const int h = s[0], w = s[1], c = s[2];
    const std::size_t n = static_cast<std::size_t>(h) * w * c;
    for (double amp : {0.0, 1e-6, 0.1, 1.0}) {
      std::vector<double> x(n), y(n);
      for (std::size_t i = 0; i < n; ++i) {
        x[i] = val(rng);
        y[i] = x[i] + amp * noise(rng);
      }
      std::vector<float> xf(x.begin(), x.end()), yf(y.begin(), y.end());
      std::vector<double> xd(xf.begin(), xf.end()), yd(yf.begin(), yf.end());
      for (bool gaussian : {false, true}) {
        if (h < 11 && gaussian) continue;
        if (w < 11 && gaussian) continue;
        sim_core::SsimOptions opt;
        opt.gaussian = gaussian;
        opt.data_range = amp == 1.0 ? 2.0 : 1.0;
        const double ref = brute_ssim(x, y, h, w, c, gaussian, opt.data_range);
        opt.threads = 1;
        const double one = sim_core::ssim_mean(x.data(), y.data(), h, w, c, opt);
        CHECK(std::fabs(one - ref) < 1e-12);
        opt.threads = 3;
        CHECK(sim_core::ssim_mean(x.data(), y.data(), h, w, c, opt) == one);
        // float32 input is summed in float64: equal to the float64 kernel on the widened values.
        const double f = sim_core::ssim_mean(xf.data(), yf.data(), h, w, c, opt);
        CHECK(f == sim_core::ssim_mean(xd.data(), yd.data(), h, w, c, opt));
        if (amp == 0.0) CHECK(std::fabs(one - 1.0) < 1e-12);
      }
    }
  }
}

// A larger image over many bands (running column sums drift): brute force and thread counts; NaN/Inf.
void check_large_image(std::mt19937& rng) {
  std::uniform_real_distribution<double> val(0.0, 1.0);
  {
    const int h = 300, w = 200, c = 3;
    std::vector<double> x(static_cast<std::size_t>(h) * w * c), y(x.size());
    for (std::size_t i = 0; i < x.size(); ++i) {
      x[i] = val(rng);
      y[i] = 0.5 * x[i] + 0.5 * val(rng);
    }
    sim_core::SsimOptions opt;
    opt.threads = 1;
    const double one = sim_core::ssim_mean(x.data(), y.data(), h, w, c, opt);
    CHECK(std::fabs(one - brute_ssim(x, y, h, w, c, false, 1.0)) < 1e-12);
    for (int t : {2, 4, 7}) {
      opt.threads = t;
      CHECK(sim_core::ssim_mean(x.data(), y.data(), h, w, c, opt) == one);
    }
    // NaN or Inf anywhere, even in a corner pixel covered by a single window, reaches the mean.
    for (std::size_t at : {std::size_t{0}, x.size() - 1, x.size() / 2}) {
      for (double bad : {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
        std::vector<double> z = y;
        z[at] = bad;
        CHECK(std::isnan(sim_core::ssim_mean(x.data(), z.data(), h, w, c, opt)));
      }
    }
  }
}

// Bad sizes and data range throw.
void check_bad_input() {
  {
    std::vector<double> x(10 * 10, 0.5);
    sim_core::SsimOptions opt;
    bool threw = false;
    try { sim_core::ssim_mean(x.data(), x.data(), 6, 10, 1, opt); } catch (const std::invalid_argument&) { threw = true; }
    CHECK(threw);
    opt.gaussian = true;
    threw = false;
    try { sim_core::ssim_mean(x.data(), x.data(), 10, 10, 1, opt); } catch (const std::invalid_argument&) { threw = true; }
    CHECK(threw);
    opt.gaussian = false;
    opt.data_range = 0.0;
    threw = false;
    try { sim_core::ssim_mean(x.data(), x.data(), 10, 10, 1, opt); } catch (const std::invalid_argument&) { threw = true; }
    CHECK(threw);
  }
}

int main() {
  std::mt19937 rng(11);
  check_against_brute_force(rng);
  check_large_image(rng);
  check_bad_input();
  return check_exit_code();
}
