// Binary and 4-wide traversal against brute force (hit/miss, t, SIMD barycentrics equal to the scalar
// test's), the two walks against each other, any-hit queries against the closest hit, and what each query
// reports to the recorder (the 4-lane leaf tests report exactly what the scalar test would, lane by lane).
#include <cmath>
#include <random>
#include <vector>

#include "sim_core/intersect.h"
#include "sim_core/scene.h"

#include "check.h"
#include "tracer_fixture.h"

using namespace sim_core;

namespace {

void check_against_brute_force(const Scene& s) {
  std::mt19937 rng(3);
  std::normal_distribution<float> nd;
  int mismatches = 0;
  for (int i = 0; i < 20000; ++i) {
    Ray r;
    r.origin = Vec3(nd(rng) * 3.f, nd(rng) * 3.f, 1.f + nd(rng) * 3.f);
    r.dir = normalize(Vec3(nd(rng), nd(rng), nd(rng)));
    const Hit h = s.closest(r);
    float best = kInf;
    const PreparedRay pr(r);
    for (std::uint32_t t = 0; t < s.triangle_count(); ++t) {
      float tt, b0, b1, b2;
      bool cmp = false;
      if (intersect_triangle(s.tri(t), pr, 0.f, best, &tt, &b0, &b1, &b2, &cmp)) best = tt;
    }
    if (h.t != best) ++mismatches;
    const Hit h2 = s.closest_binary(r);
    if (h2.t != best || h2.hit() != h.hit()) ++mismatches;
    // The same closest triangle and barycentrics (ties at equal t go to the lower index in both walks).
    if (h2.tri != h.tri || h2.b0 != h.b0 || h2.b1 != h.b1 || h2.b2 != h.b2) ++mismatches;
    if (h.hit()) {  // barycentrics of the SIMD lane equal the scalar test's
      float tt, b0, b1, b2;
      bool cmp = false;
      CHECK(intersect_triangle(s.tri(h.tri), pr, 0.f, kInf, &tt, &b0, &b1, &b2, &cmp) && tt == h.t);
      CHECK(b0 == h.b0 && b1 == h.b1 && b2 == h.b2);
    }
    // Any-hit over the same traversal core: something is hit within (0, inf) exactly when a closest hit
    // exists, and nothing lies strictly in front of the closest hit.
    NullRecorder rec;
    CHECK(s.occluded(Ray{r.origin, r.dir, 0.f, kInf}, rec) == (best < kInf));
    CHECK(!s.occluded(Ray{r.origin, r.dir, 0.f, best}, rec));
    CHECK(s.occluded_binary(Ray{r.origin, r.dir, 0.f, kInf}, rec) == (best < kInf));
    CHECK(!s.occluded_binary(Ray{r.origin, r.dir, 0.f, best}, rec));
  }
  CHECK(mismatches == 0);
}

// Counts what a traversal reports: the closest-hit query prices its distance comparisons, the any-hit
// query makes none and stops at its first hit (so never fetches more than the closest-hit walk).
struct CountingRecorder {
  std::uint64_t nodes = 0, tris = 0, compares = 0;
  std::uint32_t node_bytes = 0;
  void node(std::uint32_t, std::uint32_t bytes) { ++nodes; node_bytes = bytes; }
  void tri(std::uint32_t) { ++tris; }
  void compare(float, float) { ++compares; }
};

// Every event a walk reports, in order.
struct Event {
  char kind;  // 'n' node, 't' triangle, 'c' comparison
  std::uint32_t index;
  float a, b;
  bool operator==(const Event& o) const { return kind == o.kind && index == o.index && a == o.a && b == o.b; }
};
struct LoggingRecorder {
  std::vector<Event> events;
  void node(std::uint32_t i, std::uint32_t bytes) { events.push_back({'n', i, static_cast<float>(bytes), 0.f}); }
  void tri(std::uint32_t i) { events.push_back({'t', i, 0.f, 0.f}); }
  void compare(float t, float best) { events.push_back({'c', 0, t, best}); }
};

// The queries with their leaf blocks tested one scalar triangle() per lane, in lane order: the reference
// the 4-lane leaf tests must equal event for event.
struct ScalarClosest : ClosestHitQuery {
  using ClosestHitQuery::ClosestHitQuery;
  template <class Recorder>
  bool block4(const TriBlock4& b, const TriRecord* tris, const PreparedRay& r, float tmin, Recorder& rec) {
    for (std::uint32_t l = 0; l < b.count; ++l) rec.tri(b.first + l);
    for (std::uint32_t l = 0; l < b.count; ++l) triangle(tris[b.first + l], b.first + l, r, tmin, rec);
    return false;
  }
};
struct ScalarAny : AnyHitQuery {
  using AnyHitQuery::AnyHitQuery;
  template <class Recorder>
  bool block4(const TriBlock4& b, const TriRecord* tris, const PreparedRay& r, float tmin, Recorder& rec) {
    for (std::uint32_t l = 0; l < b.count; ++l) {
      rec.tri(b.first + l);
      if (triangle(tris[b.first + l], b.first + l, r, tmin, rec)) return true;
    }
    return false;
  }
};

void check_block4_reports_like_scalar_lanes(const Scene& s) {
  std::mt19937 rng(9);
  std::normal_distribution<float> nd;
  const Bvh4& w = s.bvh4();
  const TriRecord* tris = &s.tri(0);
  for (int i = 0; i < 3000; ++i) {
    Ray r;
    r.origin = Vec3(nd(rng) * 3.f, nd(rng) * 3.f, 1.f + nd(rng) * 3.f);
    r.dir = normalize(Vec3(nd(rng), nd(rng), nd(rng)));
    if (i % 3 == 0) r.tmax = std::fabs(nd(rng)) * 4.f;
    LoggingRecorder simd, scalar;
    ClosestHitQuery q1(r);
    ScalarClosest q2(r);
    traverse_bvh4(w.nodes.data(), w.blocks.data(), tris, r, q1, simd);
    traverse_bvh4(w.nodes.data(), w.blocks.data(), tris, r, q2, scalar);
    CHECK(simd.events == scalar.events);
    CHECK(q1.hit.t == q2.hit.t && q1.hit.tri == q2.hit.tri && q1.hit.b0 == q2.hit.b0 && q1.hit.b1 == q2.hit.b1);
    LoggingRecorder any_simd, any_scalar;
    AnyHitQuery a1(r);
    ScalarAny a2(r);
    traverse_bvh4(w.nodes.data(), w.blocks.data(), tris, r, a1, any_simd);
    traverse_bvh4(w.nodes.data(), w.blocks.data(), tris, r, a2, any_scalar);
    CHECK(any_simd.events == any_scalar.events);
    CHECK(a1.occluded == a2.occluded);
    // An occluded ray's last event is the triangle that stopped it.
    if (a1.occluded) CHECK(any_simd.events.back().kind == 't');
    // Node events are 128-byte 4-wide nodes.
    for (const Event& e : simd.events)
      if (e.kind == 'n') CHECK(e.a == 128.f);
  }
}

void check_recorded_events(const Scene& s) {
  std::mt19937 rng(5);
  std::normal_distribution<float> nd;
  std::uint64_t closest_compares = 0;
  for (int i = 0; i < 2000; ++i) {
    Ray r;
    r.origin = Vec3(nd(rng) * 3.f, nd(rng) * 3.f, 1.f + nd(rng) * 3.f);
    r.dir = normalize(Vec3(nd(rng), nd(rng), nd(rng)));
    CountingRecorder closest, any;
    const Hit h = s.closest(r, closest);
    const bool occluded = s.occluded(r, any);
    CHECK(occluded == h.hit());
    CHECK(any.compares == 0);
    CHECK(closest.compares <= closest.tris);
    CHECK(!h.hit() || closest.compares >= 1);
    CHECK(closest.nodes >= 1 && any.nodes >= 1);
    CHECK(closest.node_bytes == sizeof(Bvh4Node) && any.node_bytes == sizeof(Bvh4Node));
    if (h.hit()) {  // the same walk up to the first accepted triangle, where the any-hit query stops
      CHECK(any.nodes <= closest.nodes && any.tris <= closest.tris);
    } else {
      CHECK(any.nodes == closest.nodes && any.tris == closest.tris);
    }
    closest_compares += closest.compares;
  }
  CHECK(closest_compares > 0);
}

}  // namespace

int main() {
  const Scene s = test::make_scene();
  check_against_brute_force(s);
  check_recorded_events(s);
  check_block4_reports_like_scalar_lanes(s);
  return check_exit_code();
}
