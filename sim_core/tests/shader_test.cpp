// Shading of one sample: a primary ray that hits the sphere records its geometry (and its reflection's
// first hit, which the similarity test reads) and counts every ray it spawns by kind; one that leaves the
// scene sees the environment colour; the same key gives the same sample; depth and shadow limits hold.
// Area lights: a small one lights like a point light of the same intensity, a large disk's irradiance is
// the analytic one, a tilted rectangle's matches a brute-force integral (horizon clipped), the penumbra
// widens with the light's size. Textures: magnified texels land where their UVs say, grazing views stay
// finite and tend to the texture's mean, alpha cut-outs let primary and shadow rays through.
#include <cmath>
#include <memory>
#include <stdexcept>
#include <vector>

#include "sim_core/shader.h"

#include "check.h"
#include "tracer_fixture.h"

using namespace sim_core;

namespace {

std::uint64_t rays_by_kind(const Counters& c) {
  return c.rays_primary + c.rays_shadow + c.rays_reflection + c.rays_refraction + c.rays_ao + c.rays_glossy +
         c.rays_alpha;
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

// ---- scenes for the light and texture checks: a large ground quad (object 1) plus optional quads ----

struct Quad {
  Vec3 corner, edge_u, edge_v;  // corner + s * edge_u + t * edge_v, s, t in [0, 1]
  std::uint32_t material, object;
};

// Diffuse white, no specular layer (ior 1): a pixel's colour is irradiance / pi.
constexpr float kDiffuse[kMaterialFields] = {1.f, 1.f, 1.f, 0.f, 1.f, 0.f, 1.f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.5f, -1.f};

Scene make_quads(const std::vector<Quad>& quads, const std::vector<float>& materials, const std::vector<float>& lights,
                 const std::vector<float>* uvs = nullptr, std::vector<std::shared_ptr<const Texture>> textures = {}) {
  std::vector<float> pos;
  std::vector<std::uint32_t> tri, mat, obj;
  for (const Quad& q : quads) {
    const std::uint32_t b = static_cast<std::uint32_t>(pos.size() / 3);
    for (Vec3 p : {q.corner, q.corner + q.edge_u, q.corner + q.edge_u + q.edge_v, q.corner + q.edge_v})
      pos.insert(pos.end(), {p.x, p.y, p.z});
    tri.insert(tri.end(), {b, b + 1, b + 2, b, b + 2, b + 3});
    mat.insert(mat.end(), {q.material, q.material});
    obj.insert(obj.end(), {q.object, q.object});
  }
  std::vector<std::int64_t> ids(tri.size() / 3);
  for (std::size_t i = 0; i < ids.size(); ++i) ids[i] = static_cast<std::int64_t>(i);
  return Scene(pos.data(), pos.size() / 3, tri.data(), tri.size() / 3, ids.data(), nullptr, mat.data(), obj.data(),
               materials.data(), materials.size() / kMaterialFields, lights.data(), lights.size() / kLightFields,
               Environment(Vec3(0.f, 0.f, 0.f)), uvs ? uvs->data() : nullptr, std::move(textures));
}

const Quad kGround{Vec3(-50.f, -50.f, 0.f), Vec3(100.f, 0.f, 0.f), Vec3(0.f, 100.f, 0.f), 0, 1};

std::vector<float> area_light(float radiance, Vec3 pos, Vec3 dir, float su, float sv, int shape,
                              Vec3 axis_u = Vec3(1.f, 0.f, 0.f)) {
  return {3.f, pos.x, pos.y, pos.z, dir.x, dir.y, dir.z, 1.f, 1.f, 1.f, radiance, 0.f, 0.f, 0.f,
          static_cast<float>(shape), su, sv, axis_u.x, axis_u.y, axis_u.z};
}
std::vector<float> point_light(float intensity, Vec3 pos) {
  return {0.f, pos.x, pos.y, pos.z, 0.f, 0.f, -1.f, 1.f, 1.f, 1.f, intensity, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.f};
}

// Colour seen straight down at ground point (x, y) (a 1x1 camera just above it).
Vec3 shade_at(const Scene& s, float x, float y, const RenderSettings& st, std::uint32_t key = 1u,
              TileContext* counters = nullptr) {
  Camera cam;
  cam.position = Vec3(x, y, 0.05f);
  cam.forward = Vec3(0.f, 0.f, -1.f);
  cam.right = Vec3(1.f, 0.f, 0.f);
  cam.up = Vec3(0.f, 1.f, 0.f);
  cam.vfov = 0.01f;
  cam.width = cam.height = 1;
  TileContext ctx(s, st, cam, test::kCache);
  const Vec3 c = trace_sample(ctx, 0.5f, 0.5f, key).color;
  if (counters) counters->counters += ctx.counters;
  return c;
}

RenderSettings unshadowed() {
  RenderSettings st;
  st.shadow_samples = 0;
  st.max_depth = 0;
  return st;
}

void check_small_area_light_is_a_point_light() {
  // A 2 cm square of radiance L has on-axis intensity L * A; off axis it falls with the emitter's cosine.
  const float radiance = 1.0e4f, side = 0.02f, height = 2.f;
  const std::vector<float> mats(kDiffuse, kDiffuse + kMaterialFields);
  const Scene area = make_quads({kGround}, mats, area_light(radiance, Vec3(0.f, 0.f, height), Vec3(0.f, 0.f, -1.f), side, side, 0));
  const Scene point = make_quads({kGround}, mats, point_light(radiance * side * side, Vec3(0.f, 0.f, height)));
  for (float x : {0.f, 0.7f, 2.5f}) {
    const float ea = shade_at(area, x, 0.3f, unshadowed()).x, ep = shade_at(point, x, 0.3f, unshadowed()).x;
    const float cos_emitter = height / std::sqrt(height * height + x * x + 0.09f);
    CHECK(std::fabs(ea / (ep * cos_emitter) - 1.f) < 1e-3f);
  }
  // Behind the emitting face nothing is lit (one-sided, like Blender's area lights).
  const Scene up = make_quads({kGround}, mats, area_light(radiance, Vec3(0.f, 0.f, height), Vec3(0.f, 0.f, 1.f), side, side, 0));
  CHECK(shade_at(up, 0.f, 0.f, unshadowed()).x == 0.f);
}

void check_disk_and_rectangle_irradiance() {
  const std::vector<float> mats(kDiffuse, kDiffuse + kMaterialFields);
  // Disk of radius R at height h, on its axis: E = pi L R^2 / (R^2 + h^2).
  const float radiance = 2.f, radius = 1.5f, h = 1.f;
  const Scene disk = make_quads({kGround}, mats, area_light(radiance, Vec3(0.f, 0.f, h), Vec3(0.f, 0.f, -1.f), 2 * radius, 2 * radius, 1));
  const float analytic = kPi * radiance * radius * radius / (radius * radius + h * h);
  CHECK(std::fabs(shade_at(disk, 0.f, 0.f, unshadowed()).x * kPi / analytic - 1.f) < 0.01f);  // 16-gon outline
  // A tilted rectangle partly below the receiver's horizon, against a brute-force integral of
  // L cos(receiver) cos(emitter) / d^2 over the emitter (midpoint rule, double precision).
  const Vec3 centre(-0.8f, 0.4f, 0.3f), dir = normalize(Vec3(1.f, -0.3f, 0.2f));
  const Vec3 axis_u = normalize(cross(Vec3(0.f, 0.f, 1.f), dir));
  const Vec3 axis_v = cross(axis_u, dir);
  const float su = 1.2f, sv = 1.6f;
  const Scene rect = make_quads({kGround}, mats, area_light(radiance, centre, dir, su, sv, 0, axis_u));
  for (float x : {0.f, 0.5f, -0.2f}) {
    const Vec3 p(x, 0.1f, 0.f);
    double e = 0.0;
    const int n = 600;
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < n; ++j) {
        const float a = (i + 0.5f) / n - 0.5f, b = (j + 0.5f) / n - 0.5f;
        const Vec3 q = centre + axis_u * (a * su) + axis_v * (b * sv);
        const Vec3 d = q - p;
        const double d2 = dot(d, d), len = std::sqrt(d2);
        const double cr = std::max(0.0, double(d.z) / len), ce = std::max(0.0, -double(dot(d, dir)) / len);
        e += radiance * cr * ce / d2 * (double(su) * sv / (double(n) * n));
      }
    CHECK(std::fabs(shade_at(rect, x, 0.1f, unshadowed()).x * kPi / e - 1.0) < 2e-3);
  }
}

// Width of the shadow edge on the ground (10 % to 90 % of the unshadowed light) under a square area light
// of side `size` at height 3, cast by an occluder at height 1 covering x < 0.
float penumbra_width(float size) {
  std::vector<float> mats(kDiffuse, kDiffuse + kMaterialFields);
  mats.insert(mats.end(), kDiffuse, kDiffuse + kMaterialFields);
  const Quad occluder{Vec3(-20.f, -20.f, 1.f), Vec3(20.f, 0.f, 0.f), Vec3(0.f, 40.f, 0.f), 1, 2};
  const Scene s = make_quads({kGround, occluder}, mats, area_light(5.f, Vec3(0.f, 0.f, 3.f), Vec3(0.f, 0.f, -1.f), size, size, 0));
  RenderSettings st = unshadowed();
  st.shadow_samples = 256;
  float lo = kInf, hi = -kInf;
  for (int i = 0; i <= 400; ++i) {
    const float x = -2.f + 4.f * i / 400.f;
    const float lit = shade_at(s, x, 0.f, st, static_cast<std::uint32_t>(i)).x / shade_at(s, x, 0.f, unshadowed()).x;
    if (lit > 0.1f) lo = std::min(lo, x);
    if (lit < 0.9f) hi = std::max(hi, x);
  }
  return hi - lo;
}

void check_penumbra_grows_with_light_size() {
  // Similar triangles: the penumbra is size * 1 / (3 - 1) wide; 10-90 % of a linear-ish ramp is ~0.8 of it.
  const float small = penumbra_width(0.5f), large = penumbra_width(2.f);
  CHECK(small > 0.1f && small < 0.3f);
  CHECK(large > 0.6f && large < 1.1f);
  CHECK(large > 3.f * small);
}

void check_zero_size_area_light_is_rejected() {
  const std::vector<float> mats(kDiffuse, kDiffuse + kMaterialFields);
  bool threw = false;
  try {
    make_quads({kGround}, mats, area_light(1.f, Vec3(0.f, 0.f, 1.f), Vec3(0.f, 0.f, -1.f), 0.f, 1.f, 0));
  } catch (const std::invalid_argument&) {
    threw = true;
  }
  CHECK(threw);
}

// A 2x2 float texture: top-left red, top-right green, bottom-left blue, bottom-right half white; the
// bottom-left texel is transparent (alpha 0).
std::shared_ptr<const Texture> quadrants() {
  const float px[16] = {1.f, 0.f, 0.f, 1.f, 0.f, 1.f, 0.f, 1.f, 0.f, 0.f, 1.f, 0.f, 0.5f, 0.5f, 0.5f, 1.f};
  return std::make_shared<const Texture>(px, 2, 2, TexelFormat::kRgba32F, TextureWrap::kClamp, TextureWrap::kClamp);
}

void check_texture_lands_where_uvs_say() {
  // The ground quad [-50, 50]^2 maps UV (0, 0) at (-50, -50) to (1, 1) at (50, 50); its material is textured.
  std::vector<float> mats(kDiffuse, kDiffuse + kMaterialFields);
  mats[13] = 0.f;  // texture 0
  mats[0] = mats[1] = mats[2] = kPi;  // base colour pi: colour = texel * irradiance (1 W/m^2 sun)
  const std::vector<float> sun = {2.f, 0.f, 0.f, 0.f, 0.f, 0.f, -1.f, 1.f, 1.f, 1.f, 1.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.f};
  const std::vector<float> uvs = {0.f, 0.f, 1.f, 0.f, 1.f, 1.f, 0.f, 1.f};
  const Scene s = make_quads({kGround}, mats, sun, &uvs, {quadrants()});
  RenderSettings st = unshadowed();
  TileContext ctx(s, st, test::make_camera(), test::kCache);
  const Vec3 tl = shade_at(s, -25.f, 25.f, st, 1u, &ctx), tr = shade_at(s, 25.f, 25.f, st, 1u, &ctx);
  const Vec3 bl = shade_at(s, -25.f, -25.f, st, 1u, &ctx), br = shade_at(s, 25.f, -25.f, st, 1u, &ctx);
  CHECK(std::fabs(tl.x - 1.f) < 1e-4f && tl.y < 1e-4f && tl.z < 1e-4f);
  CHECK(std::fabs(tr.y - 1.f) < 1e-4f && tr.x < 1e-4f);
  CHECK(std::fabs(bl.z - 1.f) < 1e-4f && bl.x < 1e-4f);
  CHECK(std::fabs(br.x - 0.5f) < 1e-4f && std::fabs(br.z - 0.5f) < 1e-4f);
  // Each primary hit fetched once from the finest level (4 texels; the footprint is far below a texel).
  CHECK(ctx.counters.texture_fetches == 4 && ctx.counters.texel_reads == 16);
  CHECK(ctx.counters.alpha_tests == 0 && ctx.counters.rays_alpha == 0);  // opaque material: no alpha tests
}

void check_grazing_texture_views_saturate() {
  // A repeating 64x64 checker seen almost edge-on: every colour finite, far samples near the mean (0.5).
  std::vector<float> px;
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) {
      const float c = ((x + y) % 2) ? 1.f : 0.f;
      px.insert(px.end(), {c, c, c, 1.f});
    }
  auto checker = std::make_shared<const Texture>(px.data(), 64, 64, TexelFormat::kRgba32F, TextureWrap::kRepeat,
                                                 TextureWrap::kRepeat);
  std::vector<float> mats(kDiffuse, kDiffuse + kMaterialFields);
  mats[13] = 0.f;
  mats[0] = mats[1] = mats[2] = kPi;
  const std::vector<float> sun = {2.f, 0.f, 0.f, 0.f, 0.f, 0.f, -1.f, 1.f, 1.f, 1.f, 1.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.f};
  const std::vector<float> uvs = {0.f, 0.f, 400.f, 0.f, 400.f, 400.f, 0.f, 400.f};  // 400 repeats
  const Scene s = make_quads({kGround}, mats, sun, &uvs, {checker});
  Camera cam;
  cam.position = Vec3(0.f, -49.9f, 0.01f);  // rows look 0.0007 rad down to 0.0003 rad up: hits 14..99 m away
  cam.forward = normalize(Vec3(0.f, 1.f, -0.0002f));
  cam.right = Vec3(1.f, 0.f, 0.f);
  cam.up = cross(cam.right, cam.forward);
  cam.vfov = 0.001f;
  cam.width = 16;
  cam.height = 16;
  RenderSettings st = unshadowed();
  TileContext ctx(s, st, cam, test::kCache);
  float far_sum = 0.f;
  int far_n = 0;
  for (int y = 0; y < 16; ++y)
    for (int x = 0; x < 16; ++x) {
      const SampleResult r = trace_sample(ctx, x + 0.5f, y + 0.5f, static_cast<std::uint32_t>(y * 16 + x));
      CHECK(is_finite(r.color) && r.color.x >= 0.f && r.color.x <= 1.0001f);
      if (r.geom.object == 1 && r.geom.depth > 30.f) { far_sum += r.color.x; ++far_n; }
    }
  CHECK(far_n > 10);
  CHECK(far_n == 0 || std::fabs(far_sum / far_n - 0.5f) < 0.05f);
}

void check_alpha_cutout_passes_rays() {
  // A cut-out quad at height 1 over the ground: its transparent texel (bottom-left quarter in UV) lets
  // camera and shadow rays through; elsewhere it is an opaque card.
  std::vector<float> mats(kDiffuse, kDiffuse + kMaterialFields);
  mats.insert(mats.end(), kDiffuse, kDiffuse + kMaterialFields);
  mats[kMaterialFields + 11] = 1.f;  // clip
  mats[kMaterialFields + 13] = 0.f;  // texture 0
  const Quad card{Vec3(-1.f, -1.f, 1.f), Vec3(2.f, 0.f, 0.f), Vec3(0.f, 2.f, 0.f), 1, 0};
  std::vector<float> uvs = {0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f};  // ground: unused
  uvs.insert(uvs.end(), {0.f, 0.f, 1.f, 0.f, 1.f, 1.f, 0.f, 1.f});
  const std::vector<float> sun = {2.f, 0.f, 0.f, 0.f, 0.f, 0.f, -1.f, 1.f, 1.f, 1.f, 1.f, 0.f, 0.f, 0.f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.f};
  const Scene s = make_quads({kGround, card}, mats, sun, &uvs, {quadrants()});
  CHECK(s.has_cutouts());
  Camera cam;
  cam.position = Vec3(0.f, 0.f, 5.f);
  cam.forward = Vec3(0.f, 0.f, -1.f);
  cam.right = Vec3(1.f, 0.f, 0.f);
  cam.up = Vec3(0.f, 1.f, 0.f);
  cam.vfov = 0.5f;
  cam.width = cam.height = 8;
  RenderSettings st;
  st.max_depth = 0;
  TileContext ctx(s, st, cam, test::kCache);
  const SampleResult through = trace_sample(ctx, 2.5f, 5.5f, 1u);  // x < 0, y < 0: the transparent texel
  const SampleResult card_hit = trace_sample(ctx, 5.5f, 2.5f, 2u);
  CHECK(through.geom.object == 1 && card_hit.geom.object == 0);
  CHECK(ctx.counters.rays_alpha >= 1 && ctx.counters.alpha_tests >= 2);
  CHECK(ctx.counters.rays_total == rays_by_kind(ctx.counters));
  // On the ground, under the transparent quarter the sun gets through; under the opaque rest it does not.
  RenderSettings hard = unshadowed();
  hard.shadow_samples = 1;
  CHECK(shade_at(s, -0.5f, -0.5f, hard).x > 0.3f);
  CHECK(shade_at(s, 0.5f, 0.5f, hard).x == 0.f);
}

}  // namespace

int main() {
  const Scene s = test::make_scene();
  check_hit_and_miss(s);
  check_depth_limit(s);
  check_small_area_light_is_a_point_light();
  check_disk_and_rectangle_irradiance();
  check_penumbra_grows_with_light_size();
  check_zero_size_area_light_is_rejected();
  check_texture_lands_where_uvs_say();
  check_grazing_texture_views_saturate();
  check_alpha_cutout_passes_rays();
  return check_exit_code();
}
