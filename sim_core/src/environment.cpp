#include "sim_core/environment.h"

#include "sim_core/env_filter.h"

#include <cmath>
#include <stdexcept>

namespace sim_core {

Environment::Environment(const float* rgb, int width, int height, float rotation_z)
    : width_(width), height_(height), cos_rot_(std::cos(rotation_z)), sin_rot_(std::sin(rotation_z)) {
  if (width < 1 || height < 1) throw std::invalid_argument("environment map must be at least 1x1");
  if (!std::isfinite(rotation_z)) throw std::invalid_argument("environment rotation must be finite");
  rgb_.assign(rgb, rgb + static_cast<std::size_t>(width) * height * 3);
  double sum[3] = {0, 0, 0}, wsum = 0;
  for (int row = 0; row < height; ++row) {
    const double theta = (row + 0.5) / height * 3.14159265358979323846;
    const double w = std::sin(theta);
    for (int col = 0; col < width; ++col) {
      const float* p = &rgb_[(static_cast<std::size_t>(row) * width + col) * 3];
      for (int c = 0; c < 3; ++c) {
        if (!std::isfinite(p[c]) || p[c] < 0.f)
          throw std::invalid_argument("environment map values must be finite and >= 0");
        sum[c] += w * p[c];
      }
      wsum += w;
    }
  }
  mean_ = Vec3(static_cast<float>(sum[0] / wsum), static_cast<float>(sum[1] / wsum),
               static_cast<float>(sum[2] / wsum));
  // Order-2 SH projection of the radiance (texel solid angle sin(theta) dtheta dphi).
  double sh[9][3] = {};
  const double texel = (2.0 * 3.14159265358979323846 / width) * (3.14159265358979323846 / height);
  for (int row = 0; row < height; ++row) {
    const double w = std::sin((row + 0.5) / height * 3.14159265358979323846) * texel;
    for (int col = 0; col < width; ++col) {
      const Vec3 d = equirect_direction(col + 0.5f, row + 0.5f, width, height);
      const double x = d.x, y = d.y, z = d.z;
      const double basis[9] = {0.282095, 0.488603 * y, 0.488603 * z, 0.488603 * x, 1.092548 * x * y,
                               1.092548 * y * z, 0.315392 * (3.0 * z * z - 1.0), 1.092548 * x * z,
                               0.546274 * (x * x - y * y)};
      const float* p = &rgb_[(static_cast<std::size_t>(row) * width + col) * 3];
      for (int k = 0; k < 9; ++k)
        for (int c = 0; c < 3; ++c) sh[k][c] += basis[k] * w * p[c];
    }
  }
  for (int k = 0; k < 9; ++k)
    sh_[k] = Vec3(static_cast<float>(sh[k][0]), static_cast<float>(sh[k][1]), static_cast<float>(sh[k][2]));
}

Vec3 Environment::sh_evaluate(const Vec3* coefficients, Vec3 direction) const {
  const Vec3 d = to_map(normalize(direction));
  const float x = d.x, y = d.y, z = d.z;
  const float basis[9] = {0.282095f, 0.488603f * y, 0.488603f * z, 0.488603f * x, 1.092548f * x * y,
                          1.092548f * y * z, 0.315392f * (3.f * z * z - 1.f), 1.092548f * x * z,
                          0.546274f * (x * x - y * y)};
  Vec3 e;
  for (int k = 0; k < 9; ++k) e += coefficients[k] * basis[k];
  return vmax(e, Vec3(0.f, 0.f, 0.f));  // order-2 ringing can dip below 0 under a tiny bright source
}

Vec3 Environment::diffuse_radiance(Vec3 normal) const {
  if (!is_map()) return constant_;
  // Convolution with the clamped cosine scales band l by A_l / pi (A0 = pi, A1 = 2 pi / 3, A2 = pi / 4).
  static constexpr float kBand[9] = {1.f, 2.f / 3.f, 2.f / 3.f, 2.f / 3.f, 0.25f, 0.25f, 0.25f, 0.25f, 0.25f};
  Vec3 convolved[9];
  for (int k = 0; k < 9; ++k) convolved[k] = sh_[k] * kBand[k];
  return sh_evaluate(convolved, normal);
}

Vec3 Environment::smooth_radiance(Vec3 direction) const {
  if (!is_map()) return constant_;
  return sh_evaluate(sh_, direction);
}

Environment::~Environment() = default;
Environment::Environment(Environment&& o) noexcept
    : constant_(o.constant_), mean_(o.mean_), width_(o.width_), height_(o.height_), cos_rot_(o.cos_rot_),
      sin_rot_(o.sin_rot_), rgb_(std::move(o.rgb_)) {
  if (!is_map()) mean_ = constant_;
  for (int k = 0; k < 9; ++k) sh_[k] = o.sh_[k];
}
Environment& Environment::operator=(Environment&& o) noexcept {
  constant_ = o.constant_; mean_ = o.mean_; width_ = o.width_; height_ = o.height_; rgb_ = std::move(o.rgb_);
  cos_rot_ = o.cos_rot_; sin_rot_ = o.sin_rot_;
  for (int k = 0; k < 9; ++k) sh_[k] = o.sh_[k];
  if (!is_map()) mean_ = constant_;
  filters_[0].reset(); filters_[1].reset();
  return *this;
}

Vec3 Environment::radiance(Vec3 direction) const {
  if (!is_map()) return constant_;
  const Vec3 d = to_map(direction);
  const float len = length(d);
  const float z = std::min(1.f, std::max(-1.f, d.z / len));
  const float u = 0.5f - std::atan2(d.y, d.x) / (2.f * kPi);
  const float v = std::acos(z) / kPi;
  int col = static_cast<int>(std::floor(u * width_)) % width_;
  if (col < 0) col += width_;
  const int row = std::min(height_ - 1, std::max(0, static_cast<int>(v * height_)));
  const float* p = &rgb_[(static_cast<std::size_t>(row) * width_ + col) * 3];
  return Vec3(p[0], p[1], p[2]);
}

const EnvironmentFilter* Environment::filter(int order) const {
  std::lock_guard<std::mutex> lock(filter_mutex_);
  auto& f = filters_[order - 1];
  if (!f) f = std::make_unique<EnvironmentFilter>(rgb_.data(), width_, height_, order);
  return f.get();
}

Vec3 Environment::filtered(Vec3 direction, float cone_half_angle, int order) const {
  if (!is_map()) return constant_;  // a constant environment is its own filtered value
  if (order != 1 && order != 2) throw std::invalid_argument("environment filter order must be 1 or 2");
  return filter(order)->lookup(to_map(direction), cone_half_angle);
}

}  // namespace sim_core
