// Ray traversal of the BVH and the watertight ray-triangle test (Woop, Benthin, Wald 2013, "Watertight
// Ray/Triangle Intersection"). Header-only so the traversal loops inline. One traversal core per tree
// (traverse_bvh4: the 4-wide tree the renderer and the host-side queries walk; traverse_bvh: the binary
// tree, kept as the slow reference) serves every query; a query (ClosestHitQuery, AnyHitQuery) decides what
// a leaf's triangles do and when the walk may stop. A Recorder policy observes every node fetch, triangle
// fetch and closest-hit comparison of either walk (NullRecorder for plain queries, the tile recorder with
// cache model and counters inside the renderer).
//
// The scalar triangle test (intersect_triangle) and its 4-lane SIMD twin (test_block4) are kept as a
// slow-reference / fast-path pair: the same operations in the same order, bit-identical per lane.
#pragma once
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <type_traits>
#include <utility>

#if defined(__SSE2__) && !defined(SIM_CORE_NO_SSE)
#include <immintrin.h>
#define SIM_CORE_SSE 1
#endif

#include "sim_core/bvh.h"
#include "sim_core/math.h"

namespace sim_core {

inline constexpr float kInf = std::numeric_limits<float>::infinity();
// Far-distance scale of the robust slab test: 1 + 2 * gamma(3) (Ize 2013).
inline constexpr float kSlabRobust = 1.0000004f;

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

// What a traversal reports to its recorder: node(i, bytes) = fetch of node record i, `bytes` long (32: a
// binary node, one box; 128: a 4-wide node, four child boxes tested in one step); tri(i) = fetch and test of
// the 48-byte triangle record i; compare(t, best) = one closest-hit distance comparison (candidate t against
// the current best). NullRecorder observes nothing (plain queries).
struct NullRecorder {
  void node(std::uint32_t, std::uint32_t) {}
  void tri(std::uint32_t) {}
  void compare(float, float) {}
};
template <class Recorder>
inline constexpr bool kRecords = !std::is_same_v<Recorder, NullRecorder>;

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

// The next float above a finite x >= 0.
inline float next_up(float x) {
  std::uint32_t bits;
  std::memcpy(&bits, &x, sizeof bits);
  ++bits;
  std::memcpy(&x, &bits, sizeof bits);
  return x;
}

// The closest-hit order is (t, triangle index), lexicographic: coplanar overlapping triangles are hit at
// exactly the same t, and the lower index wins whichever order a walk (binary, 4-wide, streaming) meets
// them in. Returns the far end of the open interval triangle i must fall in to become the closest hit
// when (best, best_tri) is the closest so far (best_tri ~0u: none yet, best = the ray's tmax).
inline float closest_limit(float best, std::uint32_t best_tri, std::uint32_t i) {
  return best_tri != ~0u && i < best_tri ? next_up(best) : best;
}

// Robust slab test (Ize 2013 / pbrt: far distance scaled by 1 + 2*gamma(3) so rounding never culls a box
// the exact ray hits) of the box whose planes nearer / farther along the ray are `near` / `far` (per axis).
// Writes the entry distance; true when the box is entered within [tmin, tmax].
inline bool slab_entry(const float near[3], const float far[3], const PreparedRay& r, float tmin, float tmax,
                       float* entry) {
  const float x0 = (near[0] - r.org[0]) * r.inv[0], x1 = (far[0] - r.org[0]) * r.inv[0];
  const float y0 = (near[1] - r.org[1]) * r.inv[1], y1 = (far[1] - r.org[1]) * r.inv[1];
  const float z0 = (near[2] - r.org[2]) * r.inv[2], z1 = (far[2] - r.org[2]) * r.inv[2];
  // Written so a NaN (0 * inf on a slab plane) never tightens the interval.
  float tn = x0 > tmin ? x0 : tmin;
  tn = y0 > tn ? y0 : tn;
  tn = z0 > tn ? z0 : tn;
  float tf = x1 < tmax ? x1 : tmax;
  tf = y1 < tf ? y1 : tf;
  tf = z1 < tf ? z1 : tf;
  *entry = tn;
  return tn <= tf * kSlabRobust;
}

// Entry distance of a BVH node's box, or +inf when it is missed within [tmin, tmax].
inline float box_entry(const BvhNode& n, const PreparedRay& r, float tmin, float tmax) {
  const float near[3] = {(r.sign[0] ? n.hi : n.lo)[0], (r.sign[1] ? n.hi : n.lo)[1], (r.sign[2] ? n.hi : n.lo)[2]};
  const float far[3] = {(r.sign[0] ? n.lo : n.hi)[0], (r.sign[1] ? n.lo : n.hi)[1], (r.sign[2] ? n.lo : n.hi)[2]};
  float tn;
  return slab_entry(near, far, r, tmin, tmax, &tn) ? tn : kInf;
}

// Entry distances of both children of an interior node (nodes c and c + 1, one 64-byte pair).
inline void box_entry_pair(const BvhNode* pair, const PreparedRay& r, float tmin, float tmax, float* t0,
                           float* t1) {
#if SIM_CORE_SSE
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
  const __m128 ok = _mm_cmple_ps(tn, _mm_mul_ps(tf, _mm_set1_ps(kSlabRobust)));
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

#if SIM_CORE_SSE
// The watertight test of up to four triangles of a block at once, before any decision: the same operations,
// in the same order, as intersect_triangle, so every lane's edge functions, t and barycentrics are
// bit-identical to the scalar test's. `crossed`: lanes whose ray crosses the triangle's plane inside its
// edges (the scalar test's `compared`); `inside`: those with tmin < t < far; `edge0`: lanes with an edge
// function exactly 0, which the scalar test decides in double precision (in neither mask).
struct Block4Test {
  int crossed, inside, edge0;
  __m128 t, u, v, w, rcp;
};

inline Block4Test test_block4(const TriBlock4& b, const PreparedRay& r, float tmin, float far) {
  const int kx = r.kx, ky = r.ky, kz = r.kz;
  const __m128 okx = _mm_set1_ps(r.org[kx]), oky = _mm_set1_ps(r.org[ky]), okz = _mm_set1_ps(r.org[kz]);
  const __m128 sx = _mm_set1_ps(r.sx), sy = _mm_set1_ps(r.sy), sz = _mm_set1_ps(r.sz);
  const __m128 az = _mm_sub_ps(_mm_load_ps(b.v[0][kz]), okz);
  const __m128 bz = _mm_sub_ps(_mm_load_ps(b.v[1][kz]), okz);
  const __m128 cz = _mm_sub_ps(_mm_load_ps(b.v[2][kz]), okz);
  const __m128 ax = _mm_sub_ps(_mm_sub_ps(_mm_load_ps(b.v[0][kx]), okx), _mm_mul_ps(sx, az));
  const __m128 ay = _mm_sub_ps(_mm_sub_ps(_mm_load_ps(b.v[0][ky]), oky), _mm_mul_ps(sy, az));
  const __m128 bx = _mm_sub_ps(_mm_sub_ps(_mm_load_ps(b.v[1][kx]), okx), _mm_mul_ps(sx, bz));
  const __m128 by = _mm_sub_ps(_mm_sub_ps(_mm_load_ps(b.v[1][ky]), oky), _mm_mul_ps(sy, bz));
  const __m128 cx = _mm_sub_ps(_mm_sub_ps(_mm_load_ps(b.v[2][kx]), okx), _mm_mul_ps(sx, cz));
  const __m128 cy = _mm_sub_ps(_mm_sub_ps(_mm_load_ps(b.v[2][ky]), oky), _mm_mul_ps(sy, cz));
  Block4Test out;
  out.u = _mm_sub_ps(_mm_mul_ps(cx, by), _mm_mul_ps(cy, bx));
  out.v = _mm_sub_ps(_mm_mul_ps(ax, cy), _mm_mul_ps(ay, cx));
  out.w = _mm_sub_ps(_mm_mul_ps(bx, ay), _mm_mul_ps(by, ax));
  const __m128 zero = _mm_setzero_ps();
  const int valid = (1 << b.count) - 1;
  out.edge0 = _mm_movemask_ps(_mm_or_ps(_mm_or_ps(_mm_cmpeq_ps(out.u, zero), _mm_cmpeq_ps(out.v, zero)),
                                        _mm_cmpeq_ps(out.w, zero))) & valid;
  const __m128 anyneg = _mm_or_ps(_mm_or_ps(_mm_cmplt_ps(out.u, zero), _mm_cmplt_ps(out.v, zero)),
                                  _mm_cmplt_ps(out.w, zero));
  const __m128 anypos = _mm_or_ps(_mm_or_ps(_mm_cmpgt_ps(out.u, zero), _mm_cmpgt_ps(out.v, zero)),
                                  _mm_cmpgt_ps(out.w, zero));
  const __m128 det = _mm_add_ps(_mm_add_ps(out.u, out.v), out.w);
  const __m128 ts = _mm_add_ps(_mm_add_ps(_mm_mul_ps(out.u, _mm_mul_ps(sz, az)), _mm_mul_ps(out.v, _mm_mul_ps(sz, bz))),
                               _mm_mul_ps(out.w, _mm_mul_ps(sz, cz)));
  out.rcp = _mm_div_ps(_mm_set1_ps(1.f), det);
  out.t = _mm_mul_ps(ts, out.rcp);
  const __m128 crossed = _mm_andnot_ps(_mm_and_ps(anyneg, anypos), _mm_cmpneq_ps(det, zero));
  const __m128 in_range = _mm_and_ps(_mm_cmpgt_ps(out.t, _mm_set1_ps(tmin)), _mm_cmplt_ps(out.t, _mm_set1_ps(far)));
  out.crossed = _mm_movemask_ps(crossed) & valid & ~out.edge0;
  out.inside = _mm_movemask_ps(_mm_and_ps(crossed, in_range)) & valid & ~out.edge0;
  return out;
}
#endif

// Traversal queries: what the triangles of a leaf do to a query, how far along the ray boxes still
// matter, and which popped subtrees may be skipped. The traversal loops below (traverse_bvh over the binary
// tree, traverse_bvh4 over the 4-wide tree) are the same for every query.
//
// ClosestHitQuery keeps the nearest accepted triangle, shrinks the search interval to it, reports every
// distance comparison to the recorder (the comparator model) and skips popped subtrees that start behind
// the closest hit (with the slab test's robust margin: a box whose rounded entry lies a few ulps past the
// closest hit may still hold a nearer triangle, e.g. one lying in the box's face, so both trees find the
// same nearest t). AnyHitQuery (shadow and ambient-occlusion rays) keeps the ray's interval, never skips
// a popped subtree and stops at the first accepted triangle; it makes no closest-hit comparisons.
struct ClosestHitQuery {
  Hit hit;
  float best;  // far end of the search interval: ray.tmax, then the closest accepted t

  explicit ClosestHitQuery(const Ray& ray) : best(ray.tmax) {}
  float far() const { return best; }
  bool skip(float entry) const { return !(entry <= best * kSlabRobust); }
  // Tests triangle i; true would stop the traversal (a closest-hit query never stops early).
  template <class Recorder>
  bool triangle(const TriRecord& tri, std::uint32_t i, const PreparedRay& r, float tmin, Recorder& rec) {
    float t = 0.f, b0 = 0.f, b1 = 0.f, b2 = 0.f;
    bool compared = false;
    const bool h = intersect_triangle(tri, r, tmin, closest_limit(best, hit.tri, i), &t, &b0, &b1, &b2, &compared);
    if (compared) rec.compare(t, best);
    if (h) {
      best = t;
      hit.t = t; hit.tri = i; hit.b0 = b0; hit.b1 = b1; hit.b2 = b2;
    }
    return false;
  }
  // Up to four triangles of a 4-wide leaf at once: the same fetches, comparisons (with the same operands,
  // lane by lane) and result as triangle() on each lane in order.
  template <class Recorder>
  bool block4(const TriBlock4& b, const TriRecord* tris, const PreparedRay& r, float tmin, Recorder& rec) {
    if constexpr (kRecords<Recorder>)
      for (std::uint32_t l = 0; l < b.count; ++l) rec.tri(b.first + l);
#if SIM_CORE_SSE
    // Lanes at exactly `best` may still win a tie (closest_limit): test up to the next float.
    const Block4Test k = test_block4(b, r, tmin, hit.hit() ? next_up(best) : best);
    // Without a recorder only accepted lanes matter; with one, every comparison is reported.
    const int decide = (kRecords<Recorder> ? k.crossed : k.inside) | k.edge0;
    if (decide == 0) return false;
    alignas(16) float tl[4];
    _mm_store_ps(tl, k.t);
    for (std::uint32_t l = 0; l < b.count; ++l) {
      const int bit = 1 << l;
      const std::uint32_t i = b.first + l;
      if (k.edge0 & bit) {
        triangle(tris[i], i, r, tmin, rec);
      } else if (k.crossed & bit) {
        rec.compare(tl[l], best);
        if (tl[l] > tmin && tl[l] < closest_limit(best, hit.tri, i)) {
          alignas(16) float ul[4], vl[4], wl[4], rl[4];
          _mm_store_ps(ul, k.u); _mm_store_ps(vl, k.v); _mm_store_ps(wl, k.w); _mm_store_ps(rl, k.rcp);
          best = tl[l];
          hit.t = tl[l]; hit.tri = i; hit.b0 = ul[l] * rl[l]; hit.b1 = vl[l] * rl[l]; hit.b2 = wl[l] * rl[l];
        }
      }
    }
#else
    for (std::uint32_t l = 0; l < b.count; ++l) triangle(tris[b.first + l], b.first + l, r, tmin, rec);
#endif
    return false;
  }
};

// Shadow and ambient-occlusion rays.
struct AnyHitQuery {
  bool occluded = false;
  float tmax;

  explicit AnyHitQuery(const Ray& ray) : tmax(ray.tmax) {}
  float far() const { return tmax; }
  bool skip(float) const { return false; }
  template <class Recorder>
  bool triangle(const TriRecord& tri, std::uint32_t, const PreparedRay& r, float tmin, Recorder&) {
    float t = 0.f, b0 = 0.f, b1 = 0.f, b2 = 0.f;
    bool compared = false;
    if (intersect_triangle(tri, r, tmin, tmax, &t, &b0, &b1, &b2, &compared)) occluded = true;
    return occluded;
  }
  // Up to four triangles of a 4-wide leaf: tests (and fetches) lanes in order up to the first accepted one,
  // as triangle() on each lane would.
  template <class Recorder>
  bool block4(const TriBlock4& b, const TriRecord* tris, const PreparedRay& r, float tmin, Recorder& rec) {
#if SIM_CORE_SSE
    const Block4Test k = test_block4(b, r, tmin, tmax);
    if ((k.inside | k.edge0) == 0) {
      if constexpr (kRecords<Recorder>)
        for (std::uint32_t l = 0; l < b.count; ++l) rec.tri(b.first + l);
      return false;
    }
    for (std::uint32_t l = 0; l < b.count; ++l) {
      const int bit = 1 << l;
      const std::uint32_t i = b.first + l;
      rec.tri(i);
      if (k.inside & bit) return occluded = true;
      if ((k.edge0 & bit) && triangle(tris[i], i, r, tmin, rec)) return true;
    }
    return false;
#else
    for (std::uint32_t l = 0; l < b.count; ++l) {
      rec.tri(b.first + l);
      if (triangle(tris[b.first + l], b.first + l, r, tmin, rec)) return true;
    }
    return false;
#endif
  }
};

// Depth-first walk of the binary BVH, nearer child first, for any query: the slow reference of
// traverse_bvh4. The recorder sees every 32-byte node fetch (the root, then both children of each interior
// node entered) and every triangle fetch.
template <class Query, class Recorder>
inline void traverse_bvh(const BvhNode* nodes, const TriRecord* tris, const Ray& ray, Query& query,
                         Recorder& rec) {
  const PreparedRay r(ray);
  struct Entry { std::uint32_t node; float t; };
  Entry stack[64];
  int sp = 0;
  rec.node(0, sizeof(BvhNode));
  if (box_entry(nodes[0], r, ray.tmin, query.far()) == kInf) return;
  std::uint32_t cur = 0;
  for (;;) {
    const BvhNode& n = nodes[cur];
    if (n.count == 0) {
      const std::uint32_t c = n.first;
      rec.node(c, sizeof(BvhNode));
      rec.node(c + 1, sizeof(BvhNode));
      float t0, t1;
      prefetch_node(nodes[c], nodes, tris);
      prefetch_node(nodes[c + 1], nodes, tris);
      box_entry_pair(nodes + c, r, ray.tmin, query.far(), &t0, &t1);
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
        if (query.triangle(tris[i], i, r, ray.tmin, rec)) return;
      }
    }
    // Pop the next node the query still needs.
    for (;;) {
      if (sp == 0) return;
      const Entry e = stack[--sp];
      if (!query.skip(e.t)) { cur = e.node; break; }
    }
  }
}

// Closest hit along r within (r.tmin, r.tmax), binary walk.
template <class Recorder>
inline Hit intersect_closest(const BvhNode* nodes, const TriRecord* tris, const Ray& ray, Recorder& rec) {
  ClosestHitQuery query(ray);
  traverse_bvh(nodes, tris, ray, query, rec);
  return query.hit;
}

// Any hit within (r.tmin, r.tmax), binary walk.
template <class Recorder>
inline bool intersect_any(const BvhNode* nodes, const TriRecord* tris, const Ray& ray, Recorder& rec) {
  AnyHitQuery query(ray);
  traverse_bvh(nodes, tris, ray, query, rec);
  return query.occluded;
}

// Per-ray constants of the 4-wide slab test: which SoA box rows are the near and far planes per axis
// (rows 2a (lo) and 2a + 1 (hi), swapped for negative directions), and the broadcast ray.
struct PreparedRay4 {
  int nx, ny, nz, fx, fy, fz;
#if SIM_CORE_SSE
  __m128 ox, oy, oz, ix, iy, iz, vtmin, robust;
#endif
  PreparedRay4(const PreparedRay& r, float tmin)
      : nx(r.sign[0]), ny(2 + r.sign[1]), nz(4 + r.sign[2]),
        fx(1 - r.sign[0]), fy(3 - r.sign[1]), fz(5 - r.sign[2]) {
#if SIM_CORE_SSE
    ox = _mm_set1_ps(r.org[0]); oy = _mm_set1_ps(r.org[1]); oz = _mm_set1_ps(r.org[2]);
    ix = _mm_set1_ps(r.inv[0]); iy = _mm_set1_ps(r.inv[1]); iz = _mm_set1_ps(r.inv[2]);
    vtmin = _mm_set1_ps(tmin);
    robust = _mm_set1_ps(kSlabRobust);
#else
    (void)tmin;
#endif
  }
};

// Entry distances of the four children of `n` into tn; returns the mask of the children the ray enters
// within [tmin, tmax] (the same robust test as box_entry, four lanes at once).
inline int box_entry4(const Bvh4Node& n, const PreparedRay& r, const PreparedRay4& q, float tmin, float tmax,
                      float tn[4]) {
#if SIM_CORE_SSE
  (void)r; (void)tmin;
  const __m128 tnx = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(n.box[q.nx]), q.ox), q.ix);
  const __m128 tny = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(n.box[q.ny]), q.oy), q.iy);
  const __m128 tnz = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(n.box[q.nz]), q.oz), q.iz);
  const __m128 tfx = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(n.box[q.fx]), q.ox), q.ix);
  const __m128 tfy = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(n.box[q.fy]), q.oy), q.iy);
  const __m128 tfz = _mm_mul_ps(_mm_sub_ps(_mm_load_ps(n.box[q.fz]), q.oz), q.iz);
  // Operand order as in box_entry: a NaN slab distance never tightens the interval.
  const __m128 vn = _mm_max_ps(tnz, _mm_max_ps(tny, _mm_max_ps(tnx, q.vtmin)));
  const __m128 vf = _mm_min_ps(tfz, _mm_min_ps(tfy, _mm_min_ps(tfx, _mm_set1_ps(tmax))));
  _mm_store_ps(tn, vn);
  return _mm_movemask_ps(_mm_cmple_ps(vn, _mm_mul_ps(vf, q.robust)));
#else
  int mask = 0;
  for (int i = 0; i < 4; ++i) {
    const float near[3] = {n.box[q.nx][i], n.box[q.ny][i], n.box[q.nz][i]};
    const float far[3] = {n.box[q.fx][i], n.box[q.fy][i], n.box[q.fz][i]};
    if (slab_entry(near, far, r, tmin, tmax, &tn[i])) mask |= 1 << i;
  }
  return mask;
#endif
}

// Starts fetching a BVH4 child: a 128-byte node, or the first 160-byte triangle block of a leaf.
inline void prefetch_bvh4_child(const Bvh4Node* nodes, const TriBlock4* blocks, std::uint32_t child,
                                std::uint32_t count) {
#if SIM_CORE_SSE
  const char* p = count == 0 ? reinterpret_cast<const char*>(nodes + child)
                             : reinterpret_cast<const char*>(blocks + child);
  _mm_prefetch(p, _MM_HINT_T0);
  _mm_prefetch(p + 64, _MM_HINT_T0);
  if (count != 0) _mm_prefetch(p + 128, _MM_HINT_T0);
#else
  (void)nodes; (void)blocks; (void)child; (void)count;
#endif
}

// Depth-first walk of the 4-wide BVH, hit children nearest first, for any query. The recorder sees one
// 128-byte node fetch per interior node visited (its four child boxes are tested in that step; a child
// pushed and then skipped at pop is never fetched) and every triangle a leaf's blocks test.
template <class Query, class Recorder>
inline void traverse_bvh4(const Bvh4Node* nodes, const TriBlock4* blocks, const TriRecord* tris,
                          const Ray& ray, Query& query, Recorder& rec) {
  const PreparedRay r(ray);
  const PreparedRay4 r4(r, ray.tmin);
  struct Entry { std::uint32_t child, count; float t; };
  Entry stack[256];
  int sp = 0;
  std::uint32_t cur = 0, cur_count = 0;
  for (;;) {
    if (cur_count == 0) {
      const Bvh4Node& n = nodes[cur];
      rec.node(cur, sizeof(Bvh4Node));
      alignas(16) float tn[4];
      const int mask = box_entry4(n, r, r4, ray.tmin, query.far(), tn);
      if (mask != 0) {
        // Visit the hit children nearest first: push the others far to near.
        Entry hits[4];
        int nh = 0;
        for (int i = 0; i < 4; ++i) {
          if (!(mask & (1 << i))) continue;
          Entry e{n.child[i], n.count[i], tn[i]};
          int j = nh++;
          while (j > 0 && hits[j - 1].t < e.t) { hits[j] = hits[j - 1]; --j; }  // descending t
          hits[j] = e;
        }
        for (int i = 0; i < nh - 1; ++i) stack[sp++] = hits[i];
        cur = hits[nh - 1].child;
        cur_count = hits[nh - 1].count;
        prefetch_bvh4_child(nodes, blocks, cur, cur_count);
        continue;
      }
    } else {
      const std::uint32_t nb = (cur_count + 3) / 4;
      for (std::uint32_t k = 0; k < nb; ++k)
        if (query.block4(blocks[cur + k], tris, r, ray.tmin, rec)) return;
    }
    for (;;) {
      if (sp == 0) return;
      const Entry e = stack[--sp];
      if (!query.skip(e.t)) { cur = e.child; cur_count = e.count; break; }
    }
  }
}

// Closest hit along r within (r.tmin, r.tmax) over the 4-wide BVH. Same boxes and triangle test as
// intersect_closest (its leaves group the same triangles, small subtrees merged) and the same (t, index)
// order, so hit/miss, t and triangle agree with it; they can differ only where two different triangles lie
// at the same exact distance but their rounded t differ (coplanar duplicates seen from a ray starting on
// them), and a walk that culls the box of the one with the smaller rounded t never tests it.
template <class Recorder>
inline Hit intersect_closest4(const Bvh4Node* nodes, const TriBlock4* blocks, const TriRecord* tris,
                              const Ray& ray, Recorder& rec) {
  ClosestHitQuery query(ray);
  traverse_bvh4(nodes, blocks, tris, ray, query, rec);
  return query.hit;
}

// Any hit within (r.tmin, r.tmax) over the 4-wide BVH: the same answer as intersect_any.
template <class Recorder>
inline bool intersect_any4(const Bvh4Node* nodes, const TriBlock4* blocks, const TriRecord* tris, const Ray& ray,
                           Recorder& rec) {
  AnyHitQuery query(ray);
  traverse_bvh4(nodes, blocks, tris, ray, query, rec);
  return query.occluded;
}

}  // namespace sim_core
