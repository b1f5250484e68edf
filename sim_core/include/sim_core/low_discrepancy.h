// Deterministic low-discrepancy sampling: the R2 sequence (Roberts 2018, generalised golden ratio) with a
// per-sample Cranley-Patterson rotation from an integer hash of (sample position, path, purpose). Every
// random number depends only on where the sample is, never on which thread or in which order it is
// traced, so images are identical for any thread count and an I-sample traced by the adaptive modes is
// bit-identical to the same sample traced at full rate.
#pragma once
#include <cmath>
#include <cstdint>

#include "sim_core/math.h"

namespace sim_core {

inline std::uint32_t hash_u32(std::uint32_t x) {  // lowbias32 (Chris Wellons)
  x ^= x >> 16; x *= 0x7feb352du;
  x ^= x >> 15; x *= 0x846ca68bu;
  x ^= x >> 16;
  return x;
}
inline std::uint32_t hash_combine(std::uint32_t seed, std::uint32_t v) {
  return hash_u32(seed ^ (v + 0x9e3779b9u + (seed << 6) + (seed >> 2)));
}
// Key of the sample at global sample-grid coordinates (sx, sy) of a grid tagged `grid` (its sub-pixel
// count, plus a flag for a differently scheduled grid): seeds every random number of that sample.
inline std::uint32_t sample_key(std::uint32_t sx, std::uint32_t sy, std::uint32_t grid) {
  return hash_combine(hash_combine(hash_u32(sx), sy), grid);
}
inline float u32_to_unit(std::uint32_t x) { return static_cast<float>(x >> 8) * (1.f / 16777216.f); }

struct Sample2 { float u, v; };

// i-th point of the R2 sequence rotated by the hash `key`.
inline Sample2 r2_sample(std::uint32_t key, std::uint32_t i) {
  constexpr double a1 = 0.7548776662466927, a2 = 0.5698402909980532;
  const double r1 = u32_to_unit(hash_u32(key)), r2 = u32_to_unit(hash_u32(key ^ 0x5bd1e995u));
  double u = r1 + a1 * i, v = r2 + a2 * i;
  u -= std::floor(u); v -= std::floor(v);
  return {static_cast<float>(u), static_cast<float>(v)};
}

// Purposes of random numbers along a path (mixed into the key).
enum class SamplePurpose : std::uint32_t { kShadow = 1, kAo = 2, kGlossy = 3, kAlpha = 4 };

inline Vec3 cosine_hemisphere(Sample2 s, Vec3 n) {
  const float r = std::sqrt(s.u), phi = 2.f * kPi * s.v;
  Vec3 t, b;
  onb(n, &t, &b);
  const float z = std::sqrt(std::max(0.f, 1.f - s.u));
  return normalize(t * (r * std::cos(phi)) + b * (r * std::sin(phi)) + n * z);
}

// Uniform direction in the cone of half angle `half` around unit `axis`.
inline Vec3 uniform_cone(Sample2 s, Vec3 axis, float half) {
  const float cos_max = std::cos(half);
  const float c = 1.f - s.u * (1.f - cos_max);
  const float sn = std::sqrt(std::max(0.f, 1.f - c * c)), phi = 2.f * kPi * s.v;
  Vec3 t, b;
  onb(axis, &t, &b);
  return normalize(t * (sn * std::cos(phi)) + b * (sn * std::sin(phi)) + axis * c);
}

// Microfacet normal of the GGX (Trowbridge-Reitz) distribution with roughness alpha around unit n, sampled
// proportionally to D(h) cos(theta_h) (Walter et al. 2007, eq. 35-36).
inline Vec3 ggx_normal(Sample2 s, Vec3 n, float alpha) {
  const float tan2 = alpha * alpha * s.u / std::max(1e-7f, 1.f - s.u);
  const float c = 1.f / std::sqrt(1.f + tan2), sn = std::sqrt(std::max(0.f, 1.f - c * c));
  const float phi = 2.f * kPi * s.v;
  Vec3 t, b;
  onb(n, &t, &b);
  return normalize(t * (sn * std::cos(phi)) + b * (sn * std::sin(phi)) + n * c);
}

// Uniform point on the unit disk (concentric mapping, Shirley & Chiu).
inline void concentric_disk(Sample2 s, float* x, float* y) {
  const float a = 2.f * s.u - 1.f, b = 2.f * s.v - 1.f;
  if (a == 0.f && b == 0.f) { *x = 0.f; *y = 0.f; return; }
  float r, phi;
  if (std::fabs(a) > std::fabs(b)) { r = a; phi = (kPi / 4.f) * (b / a); }
  else { r = b; phi = kPi / 2.f - (kPi / 4.f) * (a / b); }
  *x = r * std::cos(phi); *y = r * std::sin(phi);
}

}  // namespace sim_core
