// Summed-area tables (thesis ch. 2): first-order tables give box-filter sums in four reads, second-order
// tables (the table of the table) give Bartlett (triangle) filter sums in nine reads, for any filter size.
// "Offset" tables subtract the image mean before summing (thesis sec. 2.3.2): the table then starts and
// ends near 0 instead of growing to W*H*mean, which keeps float32 tables precise on large HDR maps.
// For a second-order offset table the mean of the first-order table is subtracted too; the Bartlett
// weights (second differences) cancel any such constant exactly, so no correction is needed for it.
#pragma once
#include <cstdint>
#include <vector>

namespace sim_core {

// Scalar type T is the storage *and* accumulation type (float models the hardware; double is the
// reference). Tables are exclusive: S(x, y) = sum of f over columns < x and rows < y, size (W+1)x(H+1).
template <typename T>
class SummedAreaTable {
 public:
  // image: row-major (height, width, channels), finite values. order in {1, 2}. offset: subtract the
  // per-channel mean first. Throws std::invalid_argument on bad sizes, order or non-finite values.
  SummedAreaTable(const float* image, int width, int height, int channels, int order, bool offset);

  int width() const { return width_; }
  int height() const { return height_; }
  int channels() const { return channels_; }
  int order() const { return order_; }
  bool offset() const { return offset_; }
  // Per-channel offset that was subtracted from the image (0 when offset is false).
  double mean(int channel) const { return mean_[static_cast<std::size_t>(channel)]; }

  // Order 1: sum of the ORIGINAL image over columns [x0, x1) x rows [y0, y1) (offset added back),
  // out[channels]. Requires 0 <= x0 <= x1 <= width, 0 <= y0 <= y1 <= height.
  void box_sum(int x0, int y0, int x1, int y1, double* out) const;
  // Order 2: weighted sum of the ORIGINAL image with the separable triangle weight
  // (rx - |x - cx|)_+ * (ry - |y - cy|)_+ (rx, ry >= 1), out[channels]; divide by rx^2 ry^2 for the mean.
  // Requires the support [cx - rx, cx + rx] x [cy - ry, cy + ry] inside the image.
  void bartlett_sum(int cx, int cy, int rx, int ry, double* out) const;

  // Largest magnitude stored in the table (the dynamic range the storage format must hold).
  double max_abs() const;
  std::size_t size_bytes() const { return table_.size() * sizeof(T); }

 private:
  int width_, height_, channels_, order_;
  bool offset_;
  std::vector<double> mean_;   // offset of the image, per channel
  std::vector<double> mean1_;  // offset of the first-order table (order 2 only), per channel
  int stride_;                 // table row length in entries: (width + order) * channels
  std::vector<T> table_;       // (height + order) rows
  double entry(int x, int y, int c) const {
    return static_cast<double>(table_[static_cast<std::size_t>(y) * stride_ + static_cast<std::size_t>(x) * channels_ + c]);
  }
};

extern template class SummedAreaTable<float>;
extern template class SummedAreaTable<double>;

}  // namespace sim_core
