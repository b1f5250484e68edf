#include "sim_core/sat.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace sim_core {
namespace {

// Exclusive first-order table of `src` ((h, w, c) row-major, type S) into `dst` ((h+1, w+1, c)), summing in T:
// a running row sum added to the entry above, the usual two-pass construction.
template <typename T, typename S>
void integrate(const S* src, int w, int h, int c, const std::vector<double>& offset, std::vector<T>& dst) {
  const std::size_t stride = static_cast<std::size_t>(w + 1) * c;
  dst.assign(stride * (h + 1), T(0));
  std::vector<T> row(static_cast<std::size_t>(c));
  for (int y = 0; y < h; ++y) {
    std::fill(row.begin(), row.end(), T(0));
    const S* in = src + static_cast<std::size_t>(y) * w * c;
    const T* above = &dst[static_cast<std::size_t>(y) * stride];
    T* out = &dst[static_cast<std::size_t>(y + 1) * stride];
    for (int x = 0; x < w; ++x) {
      for (int k = 0; k < c; ++k) {
        row[k] += static_cast<T>(static_cast<T>(in[static_cast<std::size_t>(x) * c + k]) - static_cast<T>(offset[k]));
        out[static_cast<std::size_t>(x + 1) * c + k] = above[static_cast<std::size_t>(x + 1) * c + k] + row[k];
      }
    }
  }
}

}  // namespace

template <typename T>
SummedAreaTable<T>::SummedAreaTable(const float* image, int width, int height, int channels, int order,
                                    bool offset)
    : width_(width), height_(height), channels_(channels), order_(order), offset_(offset),
      mean_(static_cast<std::size_t>(std::max(channels, 0)), 0.0),
      mean1_(static_cast<std::size_t>(std::max(channels, 0)), 0.0),
      stride_((width + order) * channels) {
  if (image == nullptr) throw std::invalid_argument("summed-area table: null image");
  if (width <= 0 || height <= 0 || channels <= 0)
    throw std::invalid_argument("summed-area table: width, height and channels must be positive");
  if (order != 1 && order != 2)
    throw std::invalid_argument("summed-area table: order must be 1 (box) or 2 (Bartlett), got " +
                                std::to_string(order));
  const std::size_t n = static_cast<std::size_t>(width) * height;
  std::vector<double> sum(static_cast<std::size_t>(channels), 0.0);
  for (std::size_t i = 0; i < n; ++i)
    for (int k = 0; k < channels; ++k) {
      const float v = image[i * channels + k];
      if (!std::isfinite(v)) throw std::invalid_argument("summed-area table: image has NaN or Inf");
      sum[k] += v;
    }
  if (offset)
    for (int k = 0; k < channels; ++k) mean_[k] = sum[k] / static_cast<double>(n);

  if (order == 1) {
    integrate<T, float>(image, width, height, channels, mean_, table_);
    return;
  }
  std::vector<T> first;
  integrate<T, float>(image, width, height, channels, mean_, first);
  if (offset) {
    // Centre the first-order table too; the second differences of the Bartlett lookup cancel it exactly.
    std::vector<double> s1(static_cast<std::size_t>(channels), 0.0);
    const std::size_t m = static_cast<std::size_t>(width + 1) * (height + 1);
    for (std::size_t i = 0; i < m; ++i)
      for (int k = 0; k < channels; ++k) s1[k] += static_cast<double>(first[i * channels + k]);
    for (int k = 0; k < channels; ++k) mean1_[k] = s1[k] / static_cast<double>(m);
  }
  integrate<T, T>(first.data(), width + 1, height + 1, channels, mean1_, table_);
}

template <typename T>
double SummedAreaTable<T>::max_abs() const {
  double m = 0.0;
  for (const T v : table_) m = std::max(m, std::fabs(static_cast<double>(v)));
  return m;
}

template <typename T>
void SummedAreaTable<T>::box_sum(int x0, int y0, int x1, int y1, double* out) const {
  if (order_ != 1) throw std::logic_error("box_sum needs a first-order table");
  if (x0 < 0 || y0 < 0 || x1 > width_ || y1 > height_ || x0 > x1 || y0 > y1)
    throw std::out_of_range("box_sum: rectangle outside the table");
  const double area = static_cast<double>(x1 - x0) * static_cast<double>(y1 - y0);
  for (int k = 0; k < channels_; ++k)
    out[k] = entry(x1, y1, k) - entry(x0, y1, k) - entry(x1, y0, k) + entry(x0, y0, k) + mean_[k] * area;
}

template <typename T>
void SummedAreaTable<T>::bartlett_sum(int cx, int cy, int rx, int ry, double* out) const {
  if (order_ != 2) throw std::logic_error("bartlett_sum needs a second-order table");
  if (rx < 1 || ry < 1) throw std::out_of_range("bartlett_sum: radii must be >= 1");
  if (cx - rx + 1 < 0 || cy - ry + 1 < 0 || cx + rx > width_ || cy + ry > height_)
    throw std::out_of_range("bartlett_sum: filter support outside the table");
  // 1-D: S2[i] = sum_k f[k] (i - 1 - k)_+, so S2[c+r+1] - 2 S2[c+1] + S2[c-r+1] = sum_k f[k] (r - |k - c|)_+.
  const int xs[3] = {cx + rx + 1, cx + 1, cx - rx + 1};
  const int ys[3] = {cy + ry + 1, cy + 1, cy - ry + 1};
  const double wt[3] = {1.0, -2.0, 1.0};
  const double norm = static_cast<double>(rx) * rx * static_cast<double>(ry) * ry;
  for (int k = 0; k < channels_; ++k) {
    double s = 0.0;
    for (int j = 0; j < 3; ++j)
      for (int i = 0; i < 3; ++i) s += wt[j] * wt[i] * entry(xs[i], ys[j], k);
    out[k] = s + mean_[k] * norm;
  }
}

template class SummedAreaTable<float>;
template class SummedAreaTable<double>;

}  // namespace sim_core
