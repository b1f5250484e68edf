// Structural similarity (Wang et al. 2004) exactly as scikit-image's structural_similarity computes it:
// K1 = 0.01, K2 = 0.03; a 7x7 uniform window with sample covariance (N / (N - 1)) or an 11-tap Gaussian
// (sigma 1.5, truncate 3.5) with population covariance; the mean over windows lying fully inside the
// image (skimage crops (win - 1) / 2 pixels at each border before averaging), channels averaged.
//
// Window sums are float64 and separable: a running column sum per band of rows (box) or weighted
// column taps (Gaussian), then a direct horizontal window per output row. float32 sums of squares lose
// the variance to cancellation; running float64 sums drift by ~rows * 1e-16 only.
#pragma once
#include <cstddef>

namespace sim_core {

struct SsimOptions {
  double data_range = 1.0;
  bool gaussian = false;  // false: 7x7 box, sample covariance; true: 11-tap Gaussian, population covariance
  int threads = 0;        // 0: hardware concurrency
};

// Window size used for the options (7 or 11); images must be at least this large in both axes.
int ssim_window(const SsimOptions& opt);

// Mean SSIM of two interleaved (H, W, C) images (row-major, C innermost). Throws std::invalid_argument
// on bad sizes or data range. Any NaN or Inf in the input makes the result NaN (every pixel lies in at
// least one full window), so callers can test the result instead of scanning the input twice.
double ssim_mean(const float* x, const float* y, int h, int w, int c, const SsimOptions& opt);
double ssim_mean(const double* x, const double* y, int h, int w, int c, const SsimOptions& opt);

// The 11 normalised Gaussian taps scipy.ndimage.gaussian_filter uses for sigma 1.5, truncate 3.5.
const double* ssim_gaussian_taps();

}  // namespace sim_core
