// Binary and 4-wide traversal against brute force (hit/miss, t, SIMD barycentrics equal to the scalar
// test's), any-hit queries against the closest hit, and what each query reports to the recorder.
#include <cmath>
#include <random>

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
  }
  CHECK(mismatches == 0);
}

// Counts what a traversal reports: the closest-hit query prices its distance comparisons, the any-hit
// query makes none and stops at its first hit (so never fetches more than the closest-hit walk).
struct CountingRecorder {
  std::uint64_t nodes = 0, tris = 0, compares = 0;
  void node(std::uint32_t) { ++nodes; }
  void tri(std::uint32_t) { ++tris; }
  void compare(float, float) { ++compares; }
};

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
  return check_exit_code();
}
