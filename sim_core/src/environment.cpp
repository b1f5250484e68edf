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
  std::vector<float> residual = rgb_;
  extract_suns(&residual);
  // Order-2 SH projection of the radiance without the suns (texel solid angle sin(theta) dtheta dphi).
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
      const float* p = &residual[(static_cast<std::size_t>(row) * width + col) * 3];
      for (int k = 0; k < 9; ++k)
        for (int c = 0; c < 3; ++c) sh[k][c] += basis[k] * w * p[c];
    }
  }
  for (int k = 0; k < 9; ++k)
    sh_[k] = Vec3(static_cast<float>(sh[k][0]), static_cast<float>(sh[k][1]), static_cast<float>(sh[k][2]));
}

void Environment::extract_suns(std::vector<float>* residual) {
  constexpr double kPiD = 3.14159265358979323846;
  const int W = width_, H = height_;
  std::vector<double> solid(static_cast<std::size_t>(H));  // solid angle of a texel of each row
  for (int row = 0; row < H; ++row) solid[row] = std::sin((row + 0.5) / H * kPiD) * (2.0 * kPiD / W) * (kPiD / H);
  auto at = [&](int row, int col) { return &(*residual)[(static_cast<std::size_t>(row) * W + col) * 3]; };
  auto luminance = [](const float* p) { return 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]; };
  double power = 0.0;  // luminance integrated over the sphere
  for (int row = 0; row < H; ++row)
    for (int col = 0; col < W; ++col) power += luminance(at(row, col)) * solid[row];
  const double threshold = kSunThreshold * power / (4.0 * kPiD);
  if (!(threshold > 0.0)) return;
  const double cos_radius = std::cos(static_cast<double>(kSunRadius));
  const int row_reach = static_cast<int>(std::ceil(kSunRadius / kPiD * H)) + 1;
  std::vector<std::uint8_t> taken(static_cast<std::size_t>(W) * H, 0);
  for (int n = 0; n < kMaxSuns; ++n) {
    // The brightest texel left.
    int peak_row = -1, peak_col = -1;
    double peak = threshold;
    for (int row = 0; row < H; ++row)
      for (int col = 0; col < W; ++col) {
        const double y = luminance(at(row, col));
        if (y > peak && !taken[static_cast<std::size_t>(row) * W + col]) { peak = y; peak_row = row; peak_col = col; }
      }
    if (peak_row < 0) return;
    const Vec3 axis = equirect_direction(peak_col + 0.5f, peak_row + 0.5f, W, H);
    // Its region: texels above the threshold within kSunRadius (rows near the peak's; every column, as the
    // region may wrap around or reach a pole).
    const int r0 = std::max(0, peak_row - row_reach), r1 = std::min(H - 1, peak_row + row_reach);
    std::vector<std::pair<int, int>> region;
    for (int row = r0; row <= r1; ++row)
      for (int col = 0; col < W; ++col) {
        const std::size_t i = static_cast<std::size_t>(row) * W + col;
        if (taken[i] || !(luminance(at(row, col)) > threshold)) continue;
        if (dot(equirect_direction(col + 0.5f, row + 0.5f, W, H), axis) < cos_radius) continue;
        region.emplace_back(row, col);
        taken[i] = 1;
      }
    // The background it sits on: the mean of the texels bordering it.
    double bg[3] = {0.0, 0.0, 0.0}, bg_weight = 0.0;
    for (const auto& [row, col] : region) {
      const int nb[4][2] = {{row - 1, col}, {row + 1, col}, {row, (col + W - 1) % W}, {row, (col + 1) % W}};
      for (const auto& q : nb) {
        if (q[0] < 0 || q[0] >= H || taken[static_cast<std::size_t>(q[0]) * W + q[1]]) continue;
        const float* p = at(q[0], q[1]);
        for (int c = 0; c < 3; ++c) bg[c] += p[c] * solid[q[0]];
        bg_weight += solid[q[0]];
      }
    }
    for (double& b : bg) b = bg_weight > 0.0 ? b / bg_weight : 0.0;
    // What rises above the background: its power, power-weighted direction and spread.
    double e[3] = {0.0, 0.0, 0.0}, region_power = 0.0, area = 0.0;
    Vec3 centre;
    for (const auto& [row, col] : region) {
      const float* p = at(row, col);
      double excess[3];
      for (int c = 0; c < 3; ++c) excess[c] = std::max(0.0, p[c] - bg[c]) * solid[row];
      const double y = 0.2126 * excess[0] + 0.7152 * excess[1] + 0.0722 * excess[2];
      centre += equirect_direction(col + 0.5f, row + 0.5f, W, H) * static_cast<float>(y);
      region_power += y;
      area += solid[row];
    }
    if (!(region_power >= kSunMinPower * power) || !(length(centre) > 0.f)) continue;  // a glint, not a sun
    centre = normalize(centre);
    double spread = 0.0;  // power-weighted mean squared angle from the centre
    for (const auto& [row, col] : region) {
      float* p = at(row, col);
      const Vec3 d = equirect_direction(col + 0.5f, row + 0.5f, W, H);
      const double cos_a = std::min(1.0, std::max(-1.0, static_cast<double>(dot(d, centre))));
      double y = 0.0;
      for (int c = 0; c < 3; ++c) {
        const double excess = std::max(0.0, p[c] - bg[c]) * solid[row];
        e[c] += excess * cos_a;
        y += (c == 0 ? 0.2126 : c == 1 ? 0.7152 : 0.0722) * excess;
        p[c] = static_cast<float>(std::min(static_cast<double>(p[c]), bg[c]));  // the background stays
      }
      spread += y * std::acos(cos_a) * std::acos(cos_a);
    }
    // A uniform disc of radius r has mean squared angle r^2 / 2; at least the region's own size.
    const double radius = std::max(std::sqrt(2.0 * spread / region_power), std::sqrt(area / kPiD));
    lights_.push_back({from_map(centre), Vec3(static_cast<float>(e[0]), static_cast<float>(e[1]), static_cast<float>(e[2])),
                       static_cast<float>(radius)});
  }
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
  lights_ = std::move(o.lights_);
  if (!is_map()) mean_ = constant_;
  for (int k = 0; k < 9; ++k) sh_[k] = o.sh_[k];
}
Environment& Environment::operator=(Environment&& o) noexcept {
  constant_ = o.constant_; mean_ = o.mean_; width_ = o.width_; height_ = o.height_; rgb_ = std::move(o.rgb_);
  cos_rot_ = o.cos_rot_; sin_rot_ = o.sin_rot_; lights_ = std::move(o.lights_);
  for (int k = 0; k < 9; ++k) sh_[k] = o.sh_[k];
  if (!is_map()) mean_ = constant_;
  filters_[0].reset(); filters_[1].reset();
  return *this;
}

Vec3 Environment::radiance(Vec3 direction, bool bilinear) const {
  if (!is_map()) return constant_;
  const Vec3 d = to_map(direction);
  const float len = length(d);
  const float z = std::min(1.f, std::max(-1.f, d.z / len));
  const float u = 0.5f - std::atan2(d.y, d.x) / (2.f * kPi);
  const float v = std::acos(z) / kPi;
  auto texel = [&](int row, int col) {
    col %= width_;
    if (col < 0) col += width_;
    row = std::min(height_ - 1, std::max(0, row));
    const float* p = &rgb_[(static_cast<std::size_t>(row) * width_ + col) * 3];
    return Vec3(p[0], p[1], p[2]);
  };
  if (!bilinear) return texel(static_cast<int>(v * height_), static_cast<int>(std::floor(u * width_)));
  // Between the four nearest texel centres (wrapping around in u, clamped at the poles).
  const float x = u * width_ - 0.5f, y = v * height_ - 0.5f;
  const float x0 = std::floor(x), y0 = std::floor(y);
  const float fx = x - x0, fy = y - y0;
  const int c = static_cast<int>(x0), r = static_cast<int>(y0);
  return lerp(lerp(texel(r, c), texel(r, c + 1), fx), lerp(texel(r + 1, c), texel(r + 1, c + 1), fx), fy);
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
