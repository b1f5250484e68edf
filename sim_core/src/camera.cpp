#include "sim_core/camera.h"

#include <cmath>
#include <stdexcept>

namespace sim_core {

void Camera::validate() const {
  if (width < 1 || height < 1 || width > 16384 || height > 16384)
    throw std::invalid_argument("camera resolution must be between 1 and 16384 pixels per side");
  if (!(vfov > 0.f && vfov < 3.1f)) throw std::invalid_argument("camera vfov must be in (0, 3.1) radians");
  if (!is_finite(position) || !is_finite(right) || !is_finite(up) || !is_finite(forward))
    throw std::invalid_argument("camera position and axes must be finite");
  if (crop_x < 0 || crop_y < 0 || full_width < 0 || full_height < 0 || crop_x + width > frame_width() ||
      crop_y + height > frame_height() || frame_width() > 16384 || frame_height() > 16384)
    throw std::invalid_argument("camera window must lie inside its frame (at most 16384 pixels per side)");
  for (Vec3 a : {right, up, forward})
    if (std::fabs(length(a) - 1.f) > 1e-3f) throw std::invalid_argument("camera axes must be unit vectors");
}

float Camera::tan_half() const { return std::tan(0.5f * vfov); }

Ray Camera::primary(float px, float py) const {
  return primary_frame(px + static_cast<float>(crop_x), py + static_cast<float>(crop_y));
}

Ray Camera::primary_frame(float fx, float fy) const {
  const float th = tan_half();
  const float fw = static_cast<float>(frame_width()), fh = static_cast<float>(frame_height());
  const float aspect = fw / fh;
  const float sx = (2.f * fx / fw - 1.f) * th * aspect;
  const float sy = (1.f - 2.f * fy / fh) * th;
  Ray r;
  r.origin = position;
  r.dir = normalize(forward + right * sx + up * sy);
  return r;
}

bool Camera::project(Vec3 p, float* px, float* py, float* depth) const {
  const Vec3 d = p - position;
  const float z = dot(d, forward);
  if (!(z > 0.f)) return false;
  *depth = z;
  const float th = tan_half();
  const float fw = static_cast<float>(frame_width()), fh = static_cast<float>(frame_height());
  const float aspect = fw / fh;
  const float sx = dot(d, right) / z, sy = dot(d, up) / z;
  *px = (sx / (th * aspect) + 1.f) * 0.5f * fw - static_cast<float>(crop_x);
  *py = (1.f - sy / th) * 0.5f * fh - static_cast<float>(crop_y);
  return true;
}

bool Camera::project_direction(Vec3 d, float* px, float* py) const {
  float depth;
  return project(position + d, px, py, &depth);
}

Camera Camera::resized(int w, int h) const {
  Camera c = *this;
  c.width = w;
  c.height = h;
  c.crop_x = c.crop_y = c.full_width = c.full_height = 0;  // the whole frame at the new size
  return c;
}

Camera Camera::shifted(float dx) const {
  Camera c = *this;
  c.position = position + right * dx;
  return c;
}

}  // namespace sim_core
