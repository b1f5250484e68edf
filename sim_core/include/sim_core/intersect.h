// Ray traversal of the BVH and the watertight ray-triangle test (Woop, Benthin, Wald 2013, "Watertight
// Ray/Triangle Intersection"). Header-only so the traversal loop inlines; a Recorder policy observes every
// node fetch, triangle fetch and closest-hit comparison (NullRecorder for the plain intersect() path,
// the tile recorder with cache model and counters inside the renderer).
#pragma once
#include <cmath>
#include <cstdint>
#include <limits>
#include <utility>

#if defined(__SSE2__) && !defined(SIM_CORE_NO_SSE)
#include <immintrin.h>
#define SIM_CORE_SSE 1
#endif

#include "sim_core/bvh.h"
#include "sim_core/math.h"

namespace sim_core {

inline constexpr float kInf = std::numeric_limits<float>::infinity();

struct Ray {
  Vec3 origin;
  Vec3 dir;  // need not be unit length; t is measured in units of |dir|
  float tmin = 0.f;
  float tmax = kInf;
};

struct Hit {
  float t = kInf;
  std::uint32_t tri = ~0u;  // index into the scene's (leaf-ordered) triangle records, ~0u on miss
  float b0 = 0.f, b1 = 0.f, b2 = 0.f;  // barycentric weights of v0, v1, v2
  bool hit() const { return tri != ~0u; }
};

struct NullRecorder {
  void node(std::uint32_t) {}
  void tri(std::uint32_t) {}
  void compare(float, float) {}
};

// Per-ray constants of the traversal and of the watertight test.
struct PreparedRay {
  float org[3];
  float dir[3];
  float inv[3];
  int sign[3];  // 1 when the direction component is negative
  int kx, ky, kz;
  float sx, sy, sz;
#if SIM_CORE_SSE
  __m128 org4, inv4;
#endif

  explicit PreparedRay(const Ray& r) {
    org[0] = r.origin.x; org[1] = r.origin.y; org[2] = r.origin.z;
    dir[0] = r.dir.x; dir[1] = r.dir.y; dir[2] = r.dir.z;
    for (int a = 0; a < 3; ++a) {
      // A (near) zero component becomes +-1e-30 before inverting: the slab test then never forms
      // 0 * inf = NaN, and only distances beyond ~1e30 could change.
      const float d = std::fabs(dir[a]) < 1e-30f ? std::copysign(1e-30f, dir[a]) : dir[a];
      inv[a] = 1.f / d;
      sign[a] = std::signbit(inv[a]) ? 1 : 0;
    }
#if SIM_CORE_SSE
    org4 = _mm_setr_ps(org[0], org[1], org[2], 0.f);
    inv4 = _mm_setr_ps(inv[0], inv[1], inv[2], 0.f);
#endif
    kz = max_abs_axis(r.dir);
    kx = kz + 1 == 3 ? 0 : kz + 1;
    ky = kx + 1 == 3 ? 0 : kx + 1;
    if (dir[kz] < 0.f) std::swap(kx, ky);
    sz = 1.f / dir[kz];
    sx = dir[kx] * sz;
    sy = dir[ky] * sz;
  }
};

// Robust slab test (Ize 2013 / pbrt: far distance scaled by 1 + 2*gamma(3) so rounding never culls a box
// the exact ray hits). Returns the entry distance or +inf when the box is missed within [tmin, tmax].
inline float box_entry(const BvhNode& n, const PreparedRay& r, float tmin, float tmax) {
  constexpr float kRobust = 1.0000004f;  // 1 + 2 * gamma(3)
  const float* lo = n.lo;
  const float* hi = n.hi;
  const float x0 = ((r.sign[0] ? hi : lo)[0] - r.org[0]) * r.inv[0];
  const float x1 = ((r.sign[0] ? lo : hi)[0] - r.org[0]) * r.inv[0];
  const float y0 = ((r.sign[1] ? hi : lo)[1] - r.org[1]) * r.inv[1];
  const float y1 = ((r.sign[1] ? lo : hi)[1] - r.org[1]) * r.inv[1];
  const float z0 = ((r.sign[2] ? hi : lo)[2] - r.org[2]) * r.inv[2];
  const float z1 = ((r.sign[2] ? lo : hi)[2] - r.org[2]) * r.inv[2];
  // Written so a NaN (0 * inf on a slab plane) never tightens the interval.
  float tn = x0 > tmin ? x0 : tmin;
  tn = y0 > tn ? y0 : tn;
  tn = z0 > tn ? z0 : tn;
  float tf = x1 < tmax ? x1 : tmax;
  tf = y1 < tf ? y1 : tf;
  tf = z1 < tf ? z1 : tf;
  return tn <= tf * kRobust ? tn : kInf;
}

// Entry distances of both children of an interior node (nodes c and c + 1, one 64-byte pair).
inline void box_entry_pair(const BvhNode* pair, const PreparedRay& r, float tmin, float tmax, float* t0,
                           float* t1) {
#if SIM_CORE_SSE
  constexpr float kRobust = 1.0000004f;
  // Lane 3 of each load is the node's first/count word; it is never read out of the horizontal reductions.
  const __m128 lo0 = _mm_loadu_ps(pair[0].lo), hi0 = _mm_loadu_ps(pair[0].hi);
  const __m128 lo1 = _mm_loadu_ps(pair[1].lo), hi1 = _mm_loadu_ps(pair[1].hi);
  const __m128 a0 = _mm_mul_ps(_mm_sub_ps(lo0, r.org4), r.inv4), b0 = _mm_mul_ps(_mm_sub_ps(hi0, r.org4), r.inv4);
  const __m128 a1 = _mm_mul_ps(_mm_sub_ps(lo1, r.org4), r.inv4), b1 = _mm_mul_ps(_mm_sub_ps(hi1, r.org4), r.inv4);
  const __m128 n0 = _mm_min_ps(a0, b0), f0 = _mm_max_ps(a0, b0);
  const __m128 n1 = _mm_min_ps(a1, b1), f1 = _mm_max_ps(a1, b1);
  const __m128 vmin = _mm_set1_ps(tmin), vmax = _mm_set1_ps(tmax);
  // Horizontal max of lanes 0..2 (and tmin) / min of lanes 0..2 (and tmax), both children at once.
  const __m128 nn = _mm_movelh_ps(n0, n1);                 // n0.x n0.y n1.x n1.y
  const __m128 nz = _mm_shuffle_ps(n0, n1, _MM_SHUFFLE(2, 2, 2, 2));  // n0.z n0.z n1.z n1.z
  const __m128 ff = _mm_movelh_ps(f0, f1);
  const __m128 fz = _mm_shuffle_ps(f0, f1, _MM_SHUFFLE(2, 2, 2, 2));
  __m128 tn = _mm_max_ps(nn, _mm_shuffle_ps(nn, nn, _MM_SHUFFLE(2, 3, 0, 1)));  // max(x, y) in lanes 0 and 2
  tn = _mm_max_ps(_mm_max_ps(tn, nz), vmin);
  __m128 tf = _mm_min_ps(ff, _mm_shuffle_ps(ff, ff, _MM_SHUFFLE(2, 3, 0, 1)));
  tf = _mm_min_ps(_mm_min_ps(tf, fz), vmax);
  const __m128 ok = _mm_cmple_ps(tn, _mm_mul_ps(tf, _mm_set1_ps(kRobust)));
  const int mask = _mm_movemask_ps(ok);
  *t0 = (mask & 1) ? _mm_cvtss_f32(tn) : kInf;
  *t1 = (mask & 4) ? _mm_cvtss_f32(_mm_movehl_ps(tn, tn)) : kInf;
#else
  *t0 = box_entry(pair[0], r, tmin, tmax);
  *t1 = box_entry(pair[1], r, tmin, tmax);
#endif
}

// Starts fetching what visiting `n` will read (its children pair, or its triangles) so that the
// dependent-load chain of the descent overlaps with the box tests of the current level.
inline void prefetch_node(const BvhNode& n, const BvhNode* nodes, const TriRecord* tris) {
#if SIM_CORE_SSE
  if (n.count == 0) {
    _mm_prefetch(reinterpret_cast<const char*>(nodes + n.first), _MM_HINT_T0);
  } else {
    const char* p = reinterpret_cast<const char*>(tris + n.first);
    _mm_prefetch(p, _MM_HINT_T0);
    _mm_prefetch(p + 64, _MM_HINT_T0);
  }
#else
  (void)n; (void)nodes; (void)tris;
#endif
}

// Watertight test of one triangle. When the ray crosses the triangle's plane inside its edges, sets
// `compared` and writes the candidate distance to t_out (the closest-hit comparison the comparator model
// prices); returns true, with barycentrics, only when tmin < t < best.
inline bool intersect_triangle(const TriRecord& tri, const PreparedRay& r, float tmin, float best,
                               float* t_out, float* b0, float* b1, float* b2, bool* compared) {
  const float* v = tri.v;
  const int kx = r.kx, ky = r.ky, kz = r.kz;
  const float az = v[kz] - r.org[kz], bz = v[3 + kz] - r.org[kz], cz = v[6 + kz] - r.org[kz];
  const float ax = v[kx] - r.org[kx] - r.sx * az;
  const float ay = v[ky] - r.org[ky] - r.sy * az;
  const float bx = v[3 + kx] - r.org[kx] - r.sx * bz;
  const float by = v[3 + ky] - r.org[ky] - r.sy * bz;
  const float cx = v[6 + kx] - r.org[kx] - r.sx * cz;
  const float cy = v[6 + ky] - r.org[ky] - r.sy * cz;
  float u = cx * by - cy * bx;
  float w_v = ax * cy - ay * cx;
  float w = bx * ay - by * ax;
  if (u == 0.f || w_v == 0.f || w == 0.f) {
    // Exactly on an edge in float: decide in double so shared edges are claimed consistently.
    u = static_cast<float>(static_cast<double>(cx) * by - static_cast<double>(cy) * bx);
    w_v = static_cast<float>(static_cast<double>(ax) * cy - static_cast<double>(ay) * cx);
    w = static_cast<float>(static_cast<double>(bx) * ay - static_cast<double>(by) * ax);
  }
  if ((u < 0.f || w_v < 0.f || w < 0.f) && (u > 0.f || w_v > 0.f || w > 0.f)) return false;
  const float det = u + w_v + w;
  if (det == 0.f) return false;
  const float t_scaled = u * (r.sz * az) + w_v * (r.sz * bz) + w * (r.sz * cz);
  const float rcp = 1.f / det;
  const float t = t_scaled * rcp;
  *compared = true;
  *t_out = t;
  if (!(t > tmin && t < best)) return false;
  *b0 = u * rcp;
  *b1 = w_v * rcp;
  *b2 = w * rcp;
  return true;
}

// Closest hit along r within (r.tmin, r.tmax).
template <class Recorder>
inline Hit intersect_closest(const BvhNode* nodes, const TriRecord* tris, const Ray& ray, Recorder& rec) {
  const PreparedRay r(ray);
  Hit hit;
  float best = ray.tmax;
  struct Entry { std::uint32_t node; float t; };
  Entry stack[64];
  int sp = 0;
  rec.node(0);
  if (box_entry(nodes[0], r, ray.tmin, best) == kInf) return hit;
  std::uint32_t cur = 0;
  for (;;) {
    const BvhNode& n = nodes[cur];
    if (n.count == 0) {
      const std::uint32_t c = n.first;
      rec.node(c);
      rec.node(c + 1);
      float t0, t1;
      prefetch_node(nodes[c], nodes, tris);
      prefetch_node(nodes[c + 1], nodes, tris);
      box_entry_pair(nodes + c, r, ray.tmin, best, &t0, &t1);
      if (t0 != kInf && t1 != kInf) {
        if (t0 <= t1) { stack[sp++] = {c + 1, t1}; cur = c; }
        else { stack[sp++] = {c, t0}; cur = c + 1; }
        continue;
      }
      if (t0 != kInf) { cur = c; continue; }
      if (t1 != kInf) { cur = c + 1; continue; }
    } else {
      const std::uint32_t end = n.first + n.count;
      for (std::uint32_t i = n.first; i < end; ++i) {
        rec.tri(i);
        float t = 0.f, b0 = 0.f, b1 = 0.f, b2 = 0.f;
        bool compared = false;
        const bool h = intersect_triangle(tris[i], r, ray.tmin, best, &t, &b0, &b1, &b2, &compared);
        if (compared) rec.compare(t, best);
        if (h) {
          best = t;
          hit.t = t; hit.tri = i; hit.b0 = b0; hit.b1 = b1; hit.b2 = b2;
        }
      }
    }
    // Pop the next node still in front of the closest hit.
    for (;;) {
      if (sp == 0) return hit;
      const Entry e = stack[--sp];
      if (e.t < best) { cur = e.node; break; }
    }
  }
}

// Any hit within (r.tmin, r.tmax): shadow and ambient-occlusion rays.
template <class Recorder>
inline bool intersect_any(const BvhNode* nodes, const TriRecord* tris, const Ray& ray, Recorder& rec) {
  const PreparedRay r(ray);
  std::uint32_t stack[64];
  int sp = 0;
  rec.node(0);
  if (box_entry(nodes[0], r, ray.tmin, ray.tmax) == kInf) return false;
  std::uint32_t cur = 0;
  for (;;) {
    const BvhNode& n = nodes[cur];
    if (n.count == 0) {
      const std::uint32_t c = n.first;
      rec.node(c);
      rec.node(c + 1);
      float t0, t1;
      prefetch_node(nodes[c], nodes, tris);
      prefetch_node(nodes[c + 1], nodes, tris);
      box_entry_pair(nodes + c, r, ray.tmin, ray.tmax, &t0, &t1);
      if (t0 != kInf && t1 != kInf) {
        if (t0 <= t1) { stack[sp++] = c + 1; cur = c; }
        else { stack[sp++] = c; cur = c + 1; }
        continue;
      }
      if (t0 != kInf) { cur = c; continue; }
      if (t1 != kInf) { cur = c + 1; continue; }
    } else {
      const std::uint32_t end = n.first + n.count;
      for (std::uint32_t i = n.first; i < end; ++i) {
        rec.tri(i);
        float t = 0.f, b0 = 0.f, b1 = 0.f, b2 = 0.f;
        bool compared = false;
        if (intersect_triangle(tris[i], r, ray.tmin, ray.tmax, &t, &b0, &b1, &b2, &compared)) return true;
      }
    }
    if (sp == 0) return false;
    cur = stack[--sp];
  }
}

}  // namespace sim_core
