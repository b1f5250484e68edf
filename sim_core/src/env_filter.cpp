#include "sim_core/env_filter.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace sim_core {
namespace {
constexpr double kPiD = 3.14159265358979323846;

int wrap(int x, int n) {
  const int r = x % n;
  return r < 0 ? r + n : r;
}
}  // namespace

void equirect_pixel(Vec3 d, int width, int height, float* column, float* row) {
  const float len = length(d);
  if (!(len > 0.f) || !std::isfinite(len)) throw std::invalid_argument("equirect_pixel: zero or non-finite direction");
  const double z = std::clamp(static_cast<double>(d.z) / len, -1.0, 1.0);
  double u = 0.5 - std::atan2(static_cast<double>(d.y), static_cast<double>(d.x)) / (2.0 * kPiD);
  u -= std::floor(u);
  *column = static_cast<float>(u * width);
  if (*column >= static_cast<float>(width)) *column = 0.f;
  *row = static_cast<float>(std::acos(z) / kPiD * height);
}

Vec3 equirect_direction(float column, float row, int width, int height) {
  const double u = static_cast<double>(column) / width;
  const double v = 1.0 - static_cast<double>(row) / height;
  const double phi = -2.0 * kPiD * u + kPiD;  // Cycles: equirectangular_to_direction
  const double theta = -kPiD * v + kPiD;
  return Vec3(static_cast<float>(std::sin(theta) * std::cos(phi)), static_cast<float>(std::sin(theta) * std::sin(phi)),
              static_cast<float>(std::cos(theta)));
}

EnvironmentFilter::EnvironmentFilter(const float* rgb, int width, int height, int order, int table_bits)
    : width_(width), height_(height), order_(order) {
  if (rgb == nullptr) throw std::invalid_argument("EnvironmentFilter: null map");
  if (width < 1 || height < 1) throw std::invalid_argument("EnvironmentFilter: map must be at least 1x1");
  if (order != 1 && order != 2)
    throw std::invalid_argument("EnvironmentFilter: order must be 1 (box) or 2 (Bartlett), got " + std::to_string(order));
  if (table_bits != 0 && table_bits != 32 && table_bits != 64)
    throw std::invalid_argument("EnvironmentFilter: table_bits must be 0 (auto), 32 or 64");
  const std::size_t n = static_cast<std::size_t>(width) * height * 3;
  rgb_.assign(rgb, rgb + n);
  for (const float v : rgb_)
    if (!std::isfinite(v) || v < 0.f) throw std::invalid_argument("EnvironmentFilter: map has NaN, Inf or negative values");
  // Padding covers the widest footprint: half the circumference horizontally, and the vertical half-extent
  // of a kMaxConeHalfAngle cone (Bartlett radius ~ sqrt(2) x box radius, see lookup()).
  pad_x_ = width / 2 + 2;
  pad_y_ = std::min(height, static_cast<int>(std::ceil(0.36 * height)) + 3);
  const int pw = width + 2 * pad_x_, ph = height + 2 * pad_y_;
  std::vector<float> padded(static_cast<std::size_t>(pw) * ph * 3);
  for (int y = 0; y < ph; ++y) {
    int sy = y - pad_y_;
    int shift = 0;
    if (sy < 0) { sy = -1 - sy; shift = width / 2; }                      // across the north pole
    else if (sy >= height) { sy = 2 * height - 1 - sy; shift = width / 2; }  // across the south pole
    sy = std::clamp(sy, 0, height - 1);
    for (int x = 0; x < pw; ++x) {
      const int sx = wrap(x - pad_x_ + shift, width);
      const float* src = &rgb_[(static_cast<std::size_t>(sy) * width + sx) * 3];
      float* dst = &padded[(static_cast<std::size_t>(y) * pw + x) * 3];
      dst[0] = src[0]; dst[1] = src[1]; dst[2] = src[2];
    }
  }
  if (table_bits == 64 || (table_bits == 0 && order == 2))
    table64_ = std::make_unique<SummedAreaTable<double>>(padded.data(), pw, ph, 3, order, /*offset=*/true);
  else
    table_ = std::make_unique<SummedAreaTable<float>>(padded.data(), pw, ph, 3, order, /*offset=*/true);
}

void EnvironmentFilter::box_sum(int x0, int y0, int x1, int y1, double* out) const {
  if (table_) table_->box_sum(x0, y0, x1, y1, out);
  else table64_->box_sum(x0, y0, x1, y1, out);
}

void EnvironmentFilter::bartlett_sum(int cx, int cy, int rx, int ry, double* out) const {
  if (table_) table_->bartlett_sum(cx, cy, rx, ry, out);
  else table64_->bartlett_sum(cx, cy, rx, ry, out);
}

Vec3 EnvironmentFilter::texel(Vec3 direction) const {
  float col = 0.f, row = 0.f;
  equirect_pixel(direction, width_, height_, &col, &row);
  const int x = wrap(static_cast<int>(std::floor(col)), width_);
  const int y = std::clamp(static_cast<int>(std::floor(row)), 0, height_ - 1);
  const float* p = &rgb_[(static_cast<std::size_t>(y) * width_ + x) * 3];
  return {p[0], p[1], p[2]};
}

Vec3 EnvironmentFilter::lookup(Vec3 direction, float cone_half_angle) const {
  if (!std::isfinite(cone_half_angle)) throw std::invalid_argument("EnvironmentFilter::lookup: non-finite cone angle");
  float col = 0.f, row = 0.f;
  equirect_pixel(direction, width_, height_, &col, &row);
  if (cone_half_angle <= 0.f) return texel(direction);
  const double theta = std::min(cone_half_angle, kMaxConeHalfAngle);
  const double len = static_cast<double>(length(direction));
  const double z = static_cast<double>(direction.z) / len;
  const double sin_polar = std::sqrt(std::max(0.0, 1.0 - z * z));
  // Footprint half-extents in texels: rows span pi, columns span 2 pi shrunk by sin(polar angle).
  const double ry = theta / kPiD * height_;
  const double rx = std::min(theta / std::max(sin_polar, 1e-6) * width_ / (2.0 * kPiD), 0.5 * width_);
  const int cx = wrap(static_cast<int>(std::floor(col)), width_) + pad_x_;
  const int cy = std::clamp(static_cast<int>(std::floor(row)), 0, height_ - 1) + pad_y_;
  double out[3] = {0.0, 0.0, 0.0};
  if (order_ == 1) {
    const int hx = std::min(static_cast<int>(std::lround(rx)), (width_ - 1) / 2);
    const int hy = std::min(static_cast<int>(std::lround(ry)), pad_y_);
    if (hx == 0 && hy == 0) return texel(direction);
    box_sum(cx - hx, cy - hy, cx + hx + 1, cy + hy + 1, out);
    const double area = static_cast<double>(2 * hx + 1) * (2 * hy + 1);
    return {static_cast<float>(out[0] / area), static_cast<float>(out[1] / area), static_cast<float>(out[2] / area)};
  }
  // Bartlett radius with the variance of the box of the same footprint: (R^2 - 1)/6 = h (h + 1)/3.
  const int bx = std::min(static_cast<int>(std::lround(std::sqrt(2.0 * rx * (rx + 1.0) + 1.0))), width_ / 2);
  const int by = std::min(static_cast<int>(std::lround(std::sqrt(2.0 * ry * (ry + 1.0) + 1.0))), pad_y_);
  if (bx <= 1 && by <= 1) return texel(direction);
  const int Rx = std::max(bx, 1), Ry = std::max(by, 1);
  bartlett_sum(cx, cy, Rx, Ry, out);
  const double norm = static_cast<double>(Rx) * Rx * static_cast<double>(Ry) * Ry;
  auto clamp0 = [](double v) { return static_cast<float>(std::max(0.0, v)); };  // rounding can dip below 0
  return {clamp0(out[0] / norm), clamp0(out[1] / norm), clamp0(out[2] / norm)};
}

}  // namespace sim_core
