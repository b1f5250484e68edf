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
}

Environment::~Environment() = default;
Environment::Environment(Environment&& o) noexcept
    : constant_(o.constant_), mean_(o.mean_), width_(o.width_), height_(o.height_), cos_rot_(o.cos_rot_),
      sin_rot_(o.sin_rot_), rgb_(std::move(o.rgb_)) {
  if (!is_map()) mean_ = constant_;
}
Environment& Environment::operator=(Environment&& o) noexcept {
  constant_ = o.constant_; mean_ = o.mean_; width_ = o.width_; height_ = o.height_; rgb_ = std::move(o.rgb_);
  cos_rot_ = o.cos_rot_; sin_rot_ = o.sin_rot_;
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
