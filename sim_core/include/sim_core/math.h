// Small vector maths shared by every part of the core (float, like the hardware datapaths it models).
#pragma once
#include <algorithm>
#include <cmath>
#include <cstdint>

namespace sim_core {

struct Vec3 {
  float x = 0.f, y = 0.f, z = 0.f;
  constexpr Vec3() = default;
  constexpr Vec3(float x_, float y_, float z_) : x(x_), y(y_), z(z_) {}
  constexpr float operator[](int i) const { return i == 0 ? x : (i == 1 ? y : z); }
  float& operator[](int i) { return i == 0 ? x : (i == 1 ? y : z); }
};

constexpr Vec3 operator+(Vec3 a, Vec3 b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
constexpr Vec3 operator-(Vec3 a, Vec3 b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
constexpr Vec3 operator-(Vec3 a) { return {-a.x, -a.y, -a.z}; }
constexpr Vec3 operator*(Vec3 a, float s) { return {a.x * s, a.y * s, a.z * s}; }
constexpr Vec3 operator*(float s, Vec3 a) { return a * s; }
constexpr Vec3 operator*(Vec3 a, Vec3 b) { return {a.x * b.x, a.y * b.y, a.z * b.z}; }
constexpr Vec3 operator/(Vec3 a, float s) { return {a.x / s, a.y / s, a.z / s}; }
inline Vec3& operator+=(Vec3& a, Vec3 b) { a = a + b; return a; }
inline Vec3& operator*=(Vec3& a, float s) { a = a * s; return a; }

constexpr float dot(Vec3 a, Vec3 b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
constexpr Vec3 cross(Vec3 a, Vec3 b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline float length(Vec3 a) { return std::sqrt(dot(a, a)); }
inline Vec3 normalize(Vec3 a) {
  const float l = length(a);
  return l > 0.f ? a / l : a;
}
inline Vec3 vmin(Vec3 a, Vec3 b) { return {std::min(a.x, b.x), std::min(a.y, b.y), std::min(a.z, b.z)}; }
inline Vec3 vmax(Vec3 a, Vec3 b) { return {std::max(a.x, b.x), std::max(a.y, b.y), std::max(a.z, b.z)}; }
inline float max_component(Vec3 a) { return std::max(a.x, std::max(a.y, a.z)); }
inline bool is_finite(Vec3 a) { return std::isfinite(a.x) && std::isfinite(a.y) && std::isfinite(a.z); }

}  // namespace sim_core

// ---- Tracer helpers (shading, sampling, robust offsets) ----
#include <cstring>

namespace sim_core {

inline constexpr float kPi = 3.14159265358979323846f;

inline float max_abs_component(Vec3 a) {
  return std::max(std::fabs(a.x), std::max(std::fabs(a.y), std::fabs(a.z)));
}
inline int max_abs_axis(Vec3 a) {
  const float ax = std::fabs(a.x), ay = std::fabs(a.y), az = std::fabs(a.z);
  return ax > ay ? (ax > az ? 0 : 2) : (ay > az ? 1 : 2);
}
inline Vec3 lerp(Vec3 a, Vec3 b, float t) { return a + (b - a) * t; }
// Mirror reflection of incident direction d about unit normal n (d points towards the surface).
inline Vec3 reflect(Vec3 d, Vec3 n) { return d - n * (2.f * dot(d, n)); }
// Refraction of unit d through unit n (n faces the incident side, dot(d, n) < 0) with eta = n_i / n_t.
// Returns false on total internal reflection.
inline bool refract(Vec3 d, Vec3 n, float eta, Vec3* out) {
  const float cosi = -dot(d, n);
  const float k = 1.f - eta * eta * (1.f - cosi * cosi);
  if (k < 0.f) return false;
  *out = normalize(d * eta + n * (eta * cosi - std::sqrt(k)));
  return true;
}
// Orthonormal basis around unit n (Duff et al. 2017, "Building an Orthonormal Basis, Revisited").
inline void onb(Vec3 n, Vec3* t, Vec3* b) {
  const float sign = std::copysign(1.f, n.z);
  const float a = -1.f / (sign + n.z);
  const float c = n.x * n.y * a;
  *t = Vec3(1.f + sign * n.x * n.x * a, sign * c, -sign * n.x);
  *b = Vec3(c, sign + n.y * n.y * a, -n.y);
}

inline std::int32_t float_as_int(float f) { std::int32_t i; std::memcpy(&i, &f, 4); return i; }
inline float int_as_float(std::int32_t i) { float f; std::memcpy(&f, &i, 4); return f; }

// Robust origin for a ray leaving a surface point p on the side of geometric normal n (Wächter & Binder,
// "A Fast and Robust Method for Avoiding Self-Intersection", Ray Tracing Gems ch. 6): the offset is a
// fixed number of ulps of p, so it scales with the point's magnitude, plus a tiny absolute offset near 0.
inline Vec3 offset_ray_origin(Vec3 p, Vec3 n) {
  constexpr float kOrigin = 1.f / 32.f, kFloatScale = 1.f / 65536.f, kIntScale = 256.f;
  Vec3 out;
  for (int i = 0; i < 3; ++i) {
    const float pi = p[i], ni = n[i];
    const std::int32_t off = static_cast<std::int32_t>(kIntScale * ni);
    const float moved = int_as_float(float_as_int(pi) + (pi < 0.f ? -off : off));
    out[i] = std::fabs(pi) < kOrigin ? pi + kFloatScale * ni : moved;
  }
  return out;
}

}  // namespace sim_core
