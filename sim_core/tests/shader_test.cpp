// Shading of one sample: a primary ray that hits the sphere records its geometry (and its reflection's
// first hit, which the similarity test reads) and counts every ray it spawns by kind; one that leaves the
// scene sees the environment colour; the same key gives the same sample; depth and shadow limits hold.
#include <cmath>

#include "sim_core/shader.h"

#include "check.h"
#include "tracer_fixture.h"

using namespace sim_core;

namespace {

std::uint64_t rays_by_kind(const Counters& c) {
  return c.rays_primary + c.rays_shadow + c.rays_reflection + c.rays_refraction + c.rays_ao + c.rays_glossy;
}

void check_hit_and_miss(const Scene& s) {
  const Camera cam = test::make_camera();
  RenderSettings st;
  st.shadow_samples = 4;
  st.ao_samples = 3;
  st.max_depth = 2;
  const CacheConfig cache = test::kCache;
  TileContext ctx(s, st, cam, cache);
  // The image centre looks at the sphere (object 0).
  const SampleResult hit = trace_sample(ctx, 20.f, 15.f, 7u);
  CHECK(hit.geom.object == 0);
  CHECK(std::isfinite(hit.geom.depth) && hit.geom.depth > 0.f);
  CHECK(std::fabs(length(hit.geom.normal) - 1.f) < 1e-5f);
  CHECK(dot(hit.geom.normal, cam.position - hit.geom.position) > 0.f);  // faces the camera
  CHECK(hit.geom.sec_object[0] != -2);  // the metallic sphere traced a reflection ray
  const Counters& c = ctx.counters;
  CHECK(c.raygen_evals == 1 && c.rays_primary == 1);
  CHECK(c.rays_total == rays_by_kind(c));
  CHECK(c.rays_ao > 0);  // the reflection reaches the diffuse ground, which casts AO rays
  CHECK(c.shading_evals >= 1 && c.bvh_node_visits > 0 && c.closest_hit_comparisons > 0);
  // The top-left corner looks above the horizon: the environment's constant colour, no lookup counted.
  TileContext sky(s, st, cam, cache);
  const SampleResult miss = trace_sample(sky, 0.5f, 0.5f, 8u);
  CHECK(miss.geom.object == -1 && std::isinf(miss.geom.depth));
  CHECK(miss.color.x == 0.3f && miss.color.y == 0.3f && miss.color.z == 0.35f);
  CHECK(sky.counters.env_lookups == 0 && sky.counters.shading_evals == 0);
  // The same key gives the same sample, whatever was traced before.
  const SampleResult again = trace_sample(sky, 20.f, 15.f, 7u);
  CHECK(again.color.x == hit.color.x && again.color.y == hit.color.y && again.color.z == hit.color.z);
  CHECK(again.geom.shadow_bits == hit.geom.shadow_bits);
}

void check_depth_limit(const Scene& s) {
  const Camera cam = test::make_camera();
  const CacheConfig cache{0, 64, 4};
  RenderSettings st;
  st.max_depth = 0;  // no secondary rays at all
  st.ao_samples = 3;
  TileContext ctx(s, st, cam, cache);
  const SampleResult r = trace_sample(ctx, 20.f, 15.f, 7u);
  CHECK(r.geom.sec_object[0] == -2 && r.geom.sec_object[1] == -2);
  CHECK(ctx.counters.rays_reflection == 0 && ctx.counters.rays_refraction == 0 && ctx.counters.rays_glossy == 0);
  CHECK(ctx.counters.rays_ao == 0);  // the metallic sphere has no diffuse term: no ambient occlusion rays
  // Shadows off: no shadow ray, no shadow bit.
  st.shadow_samples = 0;
  TileContext unshadowed(s, st, cam, cache);
  const SampleResult u = trace_sample(unshadowed, 20.f, 15.f, 7u);
  CHECK(unshadowed.counters.rays_shadow == 0 && u.geom.shadow_bits == 0);
}

}  // namespace

int main() {
  const Scene s = test::make_scene();
  check_hit_and_miss(s);
  check_depth_limit(s);
  return check_exit_code();
}
