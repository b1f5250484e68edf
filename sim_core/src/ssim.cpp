// SSIM kernel: see sim_core/ssim.h. Work is split into bands of output rows; each band keeps float64
// column sums of the four quantities SSIM needs (x, y, x^2 + y^2, xy; only the sum of the two variances
// enters the formula), then filters each output row horizontally and sums the SSIM map. Band sums are
// added in band order, so the result does not depend on the number of threads.
#include "sim_core/ssim.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "sim_core/parallel.h"

namespace sim_core {
namespace {

constexpr double kK1 = 0.01;
constexpr double kK2 = 0.03;
constexpr int kBoxWin = 7;
constexpr int kGaussRadius = 5;  // int(3.5 * 1.5 + 0.5)
constexpr int kGaussWin = 2 * kGaussRadius + 1;

std::array<double, kGaussWin> make_taps() {
  std::array<double, kGaussWin> k{};
  double sum = 0.0;
  for (int i = 0; i < kGaussWin; ++i) {
    const double t = (i - kGaussRadius) / 1.5;
    k[i] = std::exp(-0.5 * t * t);
    sum += k[i];
  }
  for (double& v : k) v /= sum;
  return k;
}

const std::array<double, kGaussWin> kTaps = make_taps();

// Helpers are forced inline so that the band functions below, compiled once for AVX2 and once for the
// baseline (same operations in the same order, no FMA: identical results), vectorise them.
#if defined(__GNUC__)
#define SSIM_INLINE inline __attribute__((always_inline))
#else
#define SSIM_INLINE inline
#endif
#if defined(__GNUC__) && !defined(__clang__) && defined(__x86_64__) && defined(__linux__)
#define SSIM_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define SSIM_CLONES
#endif

struct Params {
  std::size_t n, no, c;        // row length W * C, output row length (W - win + 1) * C, channels
  double scale, cov, c1, c2;   // window sum -> mean, covariance factor, SSIM constants
};

// SSIM map of one filtered output row into m (window means = sums * scale), then its sum in 4 lanes.
SSIM_INLINE double ssim_row_sum(const double* h0, const double* h1, const double* h2, const double* h3,
                                double* m, const Params& p) {
  const std::size_t no = p.no;
  const double scale = p.scale, cov = p.cov, c1 = p.c1, c2 = p.c2;
  for (std::size_t i = 0; i < no; ++i) {
    const double ux = h0[i] * scale, uy = h1[i] * scale, uss = h2[i] * scale, uxy = h3[i] * scale;
    const double uxuy = ux * uy;
    const double sq = ux * ux + uy * uy;
    const double num = (2.0 * uxuy + c1) * (2.0 * cov * (uxy - uxuy) + c2);
    const double den = (sq + c1) * (cov * (uss - sq) + c2);
    m[i] = num / den;
  }
  double acc[4] = {0.0, 0.0, 0.0, 0.0};
  std::size_t j = 0;
  for (; j + 4 <= no; j += 4) {
    acc[0] += m[j];
    acc[1] += m[j + 1];
    acc[2] += m[j + 2];
    acc[3] += m[j + 3];
  }
  for (; j < no; ++j) acc[0] += m[j];
  return (acc[0] + acc[1]) + (acc[2] + acc[3]);
}

template <typename T>
SSIM_INLINE void add_row(const T* x, const T* y, double* col, std::size_t n) {
  double* s0 = col;
  double* s1 = col + n;
  double* s2 = col + 2 * n;
  double* s3 = col + 3 * n;
  for (std::size_t i = 0; i < n; ++i) {
    const double xv = static_cast<double>(x[i]);
    const double yv = static_cast<double>(y[i]);
    s0[i] += xv;
    s1[i] += yv;
    s2[i] += xv * xv + yv * yv;
    s3[i] += xv * yv;
  }
}

// Slides the column sums one row down: adds the row entering the window, removes the row leaving it.
template <typename T>
SSIM_INLINE void slide_row(const T* xin, const T* yin, const T* xout, const T* yout, double* col, std::size_t n) {
  double* s0 = col;
  double* s1 = col + n;
  double* s2 = col + 2 * n;
  double* s3 = col + 3 * n;
  for (std::size_t i = 0; i < n; ++i) {
    const double xa = static_cast<double>(xin[i]), ya = static_cast<double>(yin[i]);
    const double xb = static_cast<double>(xout[i]), yb = static_cast<double>(yout[i]);
    s0[i] += xa - xb;
    s1[i] += ya - yb;
    s2[i] += (xa * xa + ya * ya) - (xb * xb + yb * yb);
    s3[i] += xa * ya - xb * yb;
  }
}

template <typename T>
SSIM_INLINE void gauss_columns(const T* x, const T* y, std::size_t row, double* col, std::size_t n) {
  double* s0 = col;
  double* s1 = col + n;
  double* s2 = col + 2 * n;
  double* s3 = col + 3 * n;
  {
    const double g = kTaps[kGaussRadius];
    const T* xc = x + (row + kGaussRadius) * n;
    const T* yc = y + (row + kGaussRadius) * n;
    for (std::size_t i = 0; i < n; ++i) {
      const double xv = xc[i], yv = yc[i];
      s0[i] = xv * g;
      s1[i] = yv * g;
      s2[i] = (xv * xv + yv * yv) * g;
      s3[i] = (xv * yv) * g;
    }
  }
  for (int k = 0; k < kGaussRadius; ++k) {
    const double g = kTaps[k];
    const T* xa = x + (row + k) * n;
    const T* ya = y + (row + k) * n;
    const T* xb = x + (row + kGaussWin - 1 - k) * n;
    const T* yb = y + (row + kGaussWin - 1 - k) * n;
    for (std::size_t i = 0; i < n; ++i) {
      const double xav = xa[i], yav = ya[i], xbv = xb[i], ybv = yb[i];
      s0[i] += (xav + xbv) * g;
      s1[i] += (yav + ybv) * g;
      s2[i] += ((xav * xav + yav * yav) + (xbv * xbv + ybv * ybv)) * g;
      s3[i] += (xav * yav + xbv * ybv) * g;
    }
  }
}

SSIM_INLINE void box_horizontal(const double* col, double* hor, std::size_t n, std::size_t no, std::size_t c) {
  for (int q = 0; q < 4; ++q) {
    const double* s = col + q * n;
    double* o = hor + q * no;
    for (std::size_t i = 0; i < no; ++i)
      o[i] = ((s[i] + s[i + c]) + (s[i + 2 * c] + s[i + 3 * c])) + ((s[i + 4 * c] + s[i + 5 * c]) + s[i + 6 * c]);
  }
}

SSIM_INLINE void gauss_horizontal(const double* col, double* hor, std::size_t n, std::size_t no, std::size_t c) {
  for (int q = 0; q < 4; ++q) {
    const double* s = col + q * n;
    double* o = hor + q * no;
    const double g = kTaps[kGaussRadius];
    for (std::size_t i = 0; i < no; ++i) o[i] = s[i + kGaussRadius * c] * g;
    for (int k = 0; k < kGaussRadius; ++k) {
      const double gk = kTaps[k];
      const std::size_t a = k * c, b = (kGaussWin - 1 - k) * c;
      for (std::size_t i = 0; i < no; ++i) o[i] += (s[i + a] + s[i + b]) * gk;
    }
  }
}

// Sum of the SSIM map over output rows [r0, r1); buf holds 9 rows of scratch: 4 x n column values,
// 4 x no horizontal window sums and no map values.
template <typename T>
SSIM_INLINE double band_sum_impl(const T* x, const T* y, std::size_t r0, std::size_t r1, bool gaussian,
                                 const Params& p, double* buf) {
  const std::size_t n = p.n, no = p.no;
  double* col = buf;
  double* hor = buf + 4 * n;
  double* m = hor + 4 * no;
  double total = 0.0;
  if (!gaussian) {
    std::fill(col, col + 4 * n, 0.0);
    for (std::size_t r = r0; r < r0 + kBoxWin; ++r) add_row(x + r * n, y + r * n, col, n);
    for (std::size_t r = r0; r < r1; ++r) {
      if (r > r0) {
        const std::size_t in = r + kBoxWin - 1, out = r - 1;
        slide_row(x + in * n, y + in * n, x + out * n, y + out * n, col, n);
      }
      box_horizontal(col, hor, n, no, p.c);
      total += ssim_row_sum(hor, hor + no, hor + 2 * no, hor + 3 * no, m, p);
    }
  } else {
    for (std::size_t r = r0; r < r1; ++r) {
      gauss_columns(x, y, r, col, n);
      gauss_horizontal(col, hor, n, no, p.c);
      total += ssim_row_sum(hor, hor + no, hor + 2 * no, hor + 3 * no, m, p);
    }
  }
  return total;
}

SSIM_CLONES double band_sum(const float* x, const float* y, std::size_t r0, std::size_t r1, bool gaussian,
                            const Params& p, double* buf) {
  return band_sum_impl(x, y, r0, r1, gaussian, p, buf);
}

SSIM_CLONES double band_sum(const double* x, const double* y, std::size_t r0, std::size_t r1, bool gaussian,
                            const Params& p, double* buf) {
  return band_sum_impl(x, y, r0, r1, gaussian, p, buf);
}

template <typename T>
double ssim_mean_impl(const T* x, const T* y, int h, int w, int c, const SsimOptions& opt) {
  const int win = ssim_window(opt);
  if (h < win || w < win)
    throw std::invalid_argument("images must be at least " + std::to_string(win) + "x" + std::to_string(win) +
                                " pixels for SSIM, got " + std::to_string(h) + "x" + std::to_string(w));
  if (c < 1) throw std::invalid_argument("images need at least one channel");
  if (!(std::isfinite(opt.data_range) && opt.data_range > 0.0))
    throw std::invalid_argument("data_range must be positive and finite");
  if (x == nullptr || y == nullptr) throw std::invalid_argument("null image");

  const std::size_t cc = static_cast<std::size_t>(c);
  const std::size_t n = static_cast<std::size_t>(w) * cc;
  const std::size_t no = static_cast<std::size_t>(w - win + 1) * cc;
  const std::size_t ho = static_cast<std::size_t>(h - win + 1);
  const double c1 = (kK1 * opt.data_range) * (kK1 * opt.data_range);
  const double c2 = (kK2 * opt.data_range) * (kK2 * opt.data_range);
  const double np = static_cast<double>(win) * win;
  const double cov = opt.gaussian ? 1.0 : np / (np - 1.0);
  const double scale = opt.gaussian ? 1.0 : 1.0 / np;

  int threads = opt.threads > 0 ? opt.threads : static_cast<int>(std::thread::hardware_concurrency());
  threads = std::max(threads, 1);
  if (ho * no < 65536) threads = 1;  // thread start-up costs more than it saves on small images
  // Bands depend on the image only (about 16 of them), never on the thread count: the result is the
  // same for any number of threads.
  const std::size_t band = std::max<std::size_t>(16, (ho + 15) / 16);
  const std::size_t bands = (ho + band - 1) / band;
  std::vector<double> band_sums(bands, 0.0);

  Params p{n, no, cc, scale, cov, c1, c2};
  parallel_chunks(bands, threads, 1, [&](std::size_t b0, std::size_t b1) {
    std::vector<double> buf(4 * n + 5 * no);
    for (std::size_t b = b0; b < b1; ++b)
      band_sums[b] = band_sum(x, y, b * band, std::min(ho, (b + 1) * band), opt.gaussian, p, buf.data());
  });
  double total = 0.0;
  for (double s : band_sums) total += s;
  return total / (static_cast<double>(ho) * static_cast<double>(no));
}

}  // namespace

int ssim_window(const SsimOptions& opt) { return opt.gaussian ? kGaussWin : kBoxWin; }

const double* ssim_gaussian_taps() { return kTaps.data(); }

double ssim_mean(const float* x, const float* y, int h, int w, int c, const SsimOptions& opt) {
  return ssim_mean_impl(x, y, h, w, c, opt);
}

double ssim_mean(const double* x, const double* y, int h, int w, int c, const SsimOptions& opt) {
  return ssim_mean_impl(x, y, h, w, c, opt);
}

}  // namespace sim_core
