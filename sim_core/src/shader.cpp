#include "sim_core/shader.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "sim_core/low_discrepancy.h"

namespace sim_core {
namespace {

// Observes the traversal for the energy model: node and triangle fetches go through the tile's cache (a
// node record i of `bytes` bytes sits at kNodeBaseAddress + i * bytes), closest-hit comparisons into the
// comparator histogram.
struct TileRecorder {
  TileContext& ctx;
  void node(std::uint32_t i, std::uint32_t bytes) {
    ++ctx.counters.bvh_node_visits;
    ctx.cache.access(kNodeBaseAddress + static_cast<std::uint64_t>(i) * bytes, bytes);
  }
  void tri(std::uint32_t i) {
    ++ctx.counters.triangle_tests;
    ctx.cache.access(kTriBaseAddress + static_cast<std::uint64_t>(i) * sizeof(TriRecord), sizeof(TriRecord));
  }
  void compare(float candidate, float best) {
    ++ctx.counters.closest_hit_comparisons;
    // Operands as the comparator sees them: non-negative distances (a miss-so-far is +inf).
    ++ctx.histogram[comparator_chain_length(std::fabs(candidate), std::fabs(best))];
  }
};

enum class RayKind { kPrimary, kReflection, kGlossy, kRefraction };

// Cut-out layers a ray may pass before the surface counts as opaque (a bound, so no scene can hang it).
constexpr int kMaxCutoutLayers = 64;
// Glossy rays a rough reflection spawns at the primary hit (one deeper down the ray tree).
constexpr int kGlossyRays = 4;
// An area light's specular term integrates its emitter as kAreaCells x kAreaCells cells.
constexpr int kAreaCells = 4;

// The footprint of a ray (ray cones, Ray Tracing Gems ch. 20): width at its origin and spread angle;
// the width at distance t is width + spread * t. It picks texture mip levels.
struct RayCone {
  float width = 0.f;
  float spread = 0.f;
  float at(float t) const { return width + spread * t; }
};

// What an escaping glossy ray's environment lookup averages: a cone (the SAT filter's footprint).
struct Lobe {
  Vec3 axis;
  float half_angle = 0.f;
};

// Schlick's Fresnel, its grazing value f90 = min(1, 50 f0) (Karis 2013): no reflectance at all (f0 = 0, a
// dielectric of IOR 1, like Principled BSDF at IOR 1) stays none at grazing angles.
Vec3 schlick(Vec3 f0, float cos_theta) {
  const float m = std::min(1.f, std::max(0.f, 1.f - cos_theta));
  const float m2 = m * m, w = m2 * m2 * m;
  const float f90 = std::min(1.f, 50.f * max_component(f0));
  return f0 + (Vec3(f90, f90, f90) - f0) * w;
}
// Exact unpolarised Fresnel reflectance of a dielectric interface; eta = n_i / n_t.
float fresnel_dielectric(float cos_i, float eta) {
  const float sin_t2 = eta * eta * std::max(0.f, 1.f - cos_i * cos_i);
  if (sin_t2 >= 1.f) return 1.f;
  const float cos_t = std::sqrt(1.f - sin_t2);
  const float rs = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
  const float rp = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
  return 0.5f * (rs * rs + rp * rp);
}

// Share of a material's specular reflection that reflection rays trace: all of a metal's, and a
// dielectric's fading out as its roughness reaches Material::kReflectRoughness. The rest (rough lobes)
// reflects the environment's cosine-convolved radiance in the ambient phase.
float reflection_gloss(const Material& mat) {
  const float smooth = std::min(1.f, std::max(0.f, 1.f - mat.roughness / Material::kReflectRoughness));
  return mat.metallic + (1.f - mat.metallic) * smooth;
}
// Normal-incidence reflectance of a dielectric of index `ior` in air: ((ior - 1) / (ior + 1))^2 (0.04 at 1.5,
// 0 at 1: Principled BSDF's specular from its IOR at the default IOR level).
float dielectric_f0(float ior) {
  const float r = (ior - 1.f) / (ior + 1.f);
  return r * r;
}
// GGX roughness of a material (Principled BSDF: alpha = roughness^2), floored so lobes stay finite.
float ggx_alpha(float roughness) {
  const float r = std::max(roughness, 0.02f);
  return r * r;
}
// Half angle of the cone the SAT filter averages for a glossy reflection: 3 alpha (the median reflected
// angle of GGX is ~2 alpha, its lobe's long tail reaches well beyond), at most the filter's widest cone.
float glossy_cone(float roughness) {
  return std::min(3.f * ggx_alpha(roughness), EnvironmentFilter::kMaxConeHalfAngle);
}
// Cycles' spot cone: smoothstep over the outer `blend` fraction of (1 - cos(half angle)); a hard edge
// when blend is 0. `from_light` is the unit direction from the light to the point.
float spot_attenuation(const Light& L, Vec3 from_light) {
  const float c = dot(from_light, L.direction);
  const float cos_half = std::cos(L.spot_angle);
  if (!(c > cos_half)) return 0.f;
  const float width = (1.f - cos_half) * L.spot_blend;
  if (!(width > 0.f)) return 1.f;
  const float t = std::min(1.f, (c - cos_half) / width);
  return t * t * (3.f - 2.f * t);
}

// Projected solid angle of a planar polygon (vertices relative to the receiving point) above the plane
// with unit normal n: Lambert's formula after clipping the polygon to n's hemisphere (Sutherland-Hodgman).
// The irradiance of a uniform Lambertian emitter of radiance L is L times this.
float projected_solid_angle(const Vec3* vertices, int count, Vec3 n) {
  constexpr int kMax = 24;
  Vec3 clipped[kMax];
  int m = 0;
  for (int i = 0; i < count && m < kMax - 1; ++i) {
    const Vec3 a = vertices[i], b = vertices[(i + 1) % count];
    const float da = dot(a, n), db = dot(b, n);
    if (da > 0.f) clipped[m++] = a;
    if ((da > 0.f) != (db > 0.f)) clipped[m++] = a + (b - a) * (da / (da - db));
  }
  if (m < 3) return 0.f;
  float sum = 0.f;
  for (int i = 0; i < m; ++i) {
    const Vec3 a = normalize(clipped[i]), b = normalize(clipped[(i + 1) % m]);
    const Vec3 c = cross(a, b);
    const float len = length(c);
    if (!(len > 0.f)) continue;
    sum += std::atan2(len, dot(a, b)) * dot(c, n) / len;
  }
  return 0.5f * std::fabs(sum);
}

// Outline of an area light for the irradiance formula: its 4 corners, or an area-preserving 16-gon for
// an ellipse (circumradius scaled by sqrt(pi / (8 sin(pi / 8))) so the polygon's area is the ellipse's).
int area_outline(const Light& L, Vec3 origin, Vec3* out) {
  const Vec3 c = L.position - origin;
  const Vec3 hu = L.axis_u * (0.5f * L.size_u), hv = L.axis_v * (0.5f * L.size_v);
  if (L.shape == AreaShape::kRectangle) {
    out[0] = c - hu - hv; out[1] = c + hu - hv; out[2] = c + hu + hv; out[3] = c - hu + hv;
    return 4;
  }
  constexpr int kSides = 16;
  const float k = 1.0129670f;
  for (int i = 0; i < kSides; ++i) {
    const float phi = 2.f * kPi * static_cast<float>(i) / kSides;
    out[i] = c + hu * (k * std::cos(phi)) + hv * (k * std::sin(phi));
  }
  return kSides;
}

// A point of an area light's emitting surface from a unit-square sample (uniform over the shape).
Vec3 area_point(const Light& L, Sample2 s) {
  float x = s.u - 0.5f, y = s.v - 0.5f;
  if (L.shape == AreaShape::kEllipse) {
    concentric_disk(s, &x, &y);
    x *= 0.5f; y *= 0.5f;
  }
  return L.position + L.axis_u * (x * L.size_u) + L.axis_v * (y * L.size_v);
}

// Where a ray sits in its sample's ray tree: bounce depth and branch code (root 1, reflection child
// 3p + 1, refraction child 3p + 2). Random numbers hash (sample key, branch), never the tracing order.
// Ray sets that estimate an integral (soft-shadow points, ambient-occlusion directions, glossy lobe
// directions) are stratified over a 4x4 block of the sample grid: the N rays of a sample are its share,
// `place` (0..15), of one 16N-point set of the block, and the places are ordered so that each 2x2 block
// (an FSAA pixel's sub-samples, or neighbouring pixels) holds a contiguous quarter of it. A pixel and its
// neighbours, which the pixel filter averages, thus cover the integral 4x and 16x as densely as one
// sample, with errors that cancel instead of adding up as independent sets' would.
struct Branch {
  std::uint32_t key;
  std::uint32_t path;
  int depth;
  std::uint32_t place = 0;
  std::uint32_t block = 0;  // key of the 4x4 block
  std::uint32_t random_key() const { return hash_combine(key, path); }
  // Rotation key of the block's stratified sets along this branch, and the index of this place's i-th
  // of n rays in the block's set.
  std::uint32_t block_key() const { return hash_combine(block, path); }
  std::uint32_t stratum(int i, int n) const { return static_cast<std::uint32_t>(i + n * static_cast<int>(place)); }
  // The same within the 2x2 block only (a set that is not rotated per block: see add_reflection).
  std::uint32_t stratum_2x2(int i, int n) const { return static_cast<std::uint32_t>(i + n * static_cast<int>(place & 3u)); }
  // Glossy ray i of a reflection gets its own random numbers (i << 20 stays clear of depth-4 codes).
  Branch reflected(std::uint32_t i = 0) const { return {key, (path * 3u + 1u) + (i << 20), depth + 1, place, block}; }
  Branch refracted() const { return {key, path * 3u + 2u, depth + 1, place, block}; }
};

struct HitInfo {  // what the caller (primary sample) records about a ray's first hit
  std::int32_t object = -1;
  Vec3 normal;
  Vec3 position;
  float t = kInf;
  std::uint32_t shadow_bits = 0;
  AmbientSample ambient;  // the hit's diffuse ambient light and its AO rays
};

// Geometry of a ray's hit, oriented towards the incoming ray, with its textured base colour and alpha.
struct SurfacePoint {
  const TriRecord* tri;
  const Material* mat;
  Vec3 base_color;  // material base colour times its texture (linear)
  float alpha;      // material alpha times the texture's alpha
  float cone_width; // the ray footprint's width here (texture level of detail, shadow-ray alpha tests)
  Vec3 p;           // hit point
  Vec3 dir;         // unit incoming direction
  Vec3 view;        // -dir
  Vec3 ng;          // unit geometric normal, facing the incoming ray
  Vec3 n;           // unit shading normal, same side as ng
  bool front;       // the ray hit the winding's front face
  float n_dot_v;
  Vec3 origin_out;  // spawn point for rays leaving on the incoming side
  Vec3 origin_in;   // spawn point for rays entering the surface (refraction)
};

// The material's scattering terms at a hit: Lambert diffuse under a GGX microfacet specular lobe (alpha =
// roughness^2 as in the Principled BSDF; Trowbridge-Reitz distribution, height-correlated Smith
// visibility, Schlick's Fresnel with f0 from the IOR for dielectrics), scaled by the opaque
// (non-transmitted) fraction. As in Principled BSDF, the diffuse base is what the dielectric specular
// layer lets through (1 - its Fresnel reflectance at the view angle). Metals take their specular colour
// from the (textured) base colour.
struct SurfaceBrdf {
  Vec3 base_color;
  float opaque;
  Vec3 diffuse_albedo;
  Vec3 f0;
  float alpha;

  SurfaceBrdf(const Material& mat, Vec3 base, float n_dot_v)
      : base_color(base),
        opaque(1.f - mat.transmission),
        f0(lerp(Vec3(1.f, 1.f, 1.f) * dielectric_f0(mat.ior), base, mat.metallic)),
        alpha(ggx_alpha(mat.roughness)) {
    const float layer = 1.f - schlick(Vec3(1.f, 1.f, 1.f) * dielectric_f0(mat.ior), n_dot_v).x;
    diffuse_albedo = base * ((1.f - mat.metallic) * opaque * layer);
  }
  Vec3 diffuse() const { return diffuse_albedo * (1.f / kPi); }
  // Specular BRDF for light arriving from unit `to_light`, seen from unit `view`, about shading normal n.
  // A light of angular radius `widen` widens the lobe to alpha + widen / 2 (Karis 2013, "Real Shading in
  // Unreal Engine 4"): its highlight spreads over the emitter instead of peaking at one point.
  Vec3 specular(Vec3 n, Vec3 to_light, Vec3 view, float widen = 0.f) const {
    if (!(opaque > 0.f) || !(max_component(f0) > 0.f)) return Vec3();
    const float n_l = std::max(dot(n, to_light), 1e-4f), n_v = std::max(dot(n, view), 1e-4f);
    const Vec3 h = normalize(to_light + view);
    // Floored at 0.01 (roughness 0.1): a point light on a near-mirror is a highlight of bounded
    // brightness rather than one firefly pixel.
    const float a = std::min(1.f, std::max(0.01f, alpha + 0.5f * std::max(widen, 0.f)));
    const float a2 = a * a;
    const float n_h = std::max(dot(n, h), 0.f);
    const float q = n_h * n_h * (a2 - 1.f) + 1.f;
    const float d = a2 / (kPi * q * q);
    // Height-correlated Smith visibility G / (4 n.l n.v) (Heitz 2014).
    const float vis = 0.5f / (n_l * std::sqrt(n_v * n_v * (1.f - a2) + a2) + n_v * std::sqrt(n_l * n_l * (1.f - a2) + a2));
    return schlick(f0, std::max(dot(h, view), 0.f)) * (d * vis * opaque);
  }
};

// Light arriving at a surface point from one light, before shadowing.
struct LightArrival {
  Vec3 to_centre;   // unit direction towards the light's centre (shadow rays of hard shadows)
  Vec3 irradiance;  // unshadowed, cosine at the receiver included (colour x intensity x geometry)
  Vec3 specular;    // unshadowed radiance the specular lobe reflects of this light
};

// How much of a hit's light goes into each secondary ray (the Fresnel split of reflection/refraction).
struct SecondaryWeights {
  Vec3 reflection;        // mirror/glossy reflection weight (both the specular and the dielectric part)
  bool refracts = false;  // a transmitted ray exists (not total internal reflection)
  float refraction = 0.f;
  Vec3 refraction_dir;
};

class Shader {
 public:
  explicit Shader(TileContext& ctx) : ctx_(ctx), rec_{ctx} {}

  // Radiance along `ray`. `info` (may be null) receives the first hit; `geom` (primary ray only) the
  // first hits of its reflection/refraction rays. `lobe` (glossy rays only) is what a filtered
  // environment lookup averages when the ray leaves the scene.
  Vec3 trace(const Ray& ray, RayKind kind, Branch branch, RayCone cone, const Lobe* lobe, HitInfo* info,
             SampleGeometry* geom);

 private:
  TileContext& ctx_;
  TileRecorder rec_;

  // The tile's tree walk (the 4-wide BVH, or the binary reference walk when the context asks for it):
  // closest hit, and any hit for shadow and ambient-occlusion rays.
  Hit closest(const Ray& ray, RayKind kind) { return closest_traced(ray, traced_kind(kind)); }
  Hit closest_traced(const Ray& ray, TracedKind kind) {  // also shadow and AO rays through cut-outs
    if (ctx_.trace.log_rays) ctx_.ray_log.push_back({ray, kind});
    return ctx_.trace.bvh_width == 2 ? ctx_.scene.closest_binary(ray, rec_) : ctx_.scene.closest(ray, rec_);
  }
  bool occluded(const Ray& ray, TracedKind kind) {
    if (ctx_.trace.log_rays) ctx_.ray_log.push_back({ray, kind});
    return ctx_.trace.bvh_width == 2 ? ctx_.scene.occluded_binary(ray, rec_) : ctx_.scene.occluded(ray, rec_);
  }
  static TracedKind traced_kind(RayKind kind) {
    switch (kind) {
      case RayKind::kReflection: return TracedKind::kReflection;
      case RayKind::kGlossy: return TracedKind::kGlossy;
      case RayKind::kRefraction: return TracedKind::kRefraction;
      default: return TracedKind::kPrimary;
    }
  }
  void count_ray(RayKind kind);
  // Environment phase: what a ray that leaves the scene sees (cone-filtered for glossy rays when asked).
  Vec3 environment(const Ray& ray, RayKind kind, const Lobe* lobe);
  // Primary-hit phase: hit point, oriented normals, spawn points, then the texture phase (textured base
  // colour and alpha, mip level from the ray cone's width here).
  SurfacePoint surface_at(const Ray& ray, const Hit& hit, float cone_width);
  Rgba texture_sample(const Material& mat, std::uint32_t tri, const Hit& hit, float cone_width, float cos_incidence);
  // Alpha phase: whether a hit of a cut-out material lets the ray through (clip: alpha below the cutoff;
  // hashed: alpha below a per-sample random threshold). Counts the test.
  bool cut_out(const Material& mat, float alpha, std::uint32_t random_key, int layer);
  // Any hit before ray.tmax, looking through cut-outs (the plain any-hit walk when the scene has none).
  bool occluded_past_cutouts(Ray ray, TracedKind kind, std::uint32_t random_key, float cone_width);
  // Direct-light phase: every light's contribution, shadowed by shadow rays; sets one shadow bit per
  // occluded light.
  void add_direct_light(const SurfacePoint& s, const SurfaceBrdf& brdf, const Branch& branch, Vec3* color,
                        std::uint32_t* shadow_bits);
  bool light_arrival(const Light& light, const SurfacePoint& s, const SurfaceBrdf& brdf, LightArrival* out);
  bool area_arrival(const Light& light, const SurfacePoint& s, const SurfaceBrdf& brdf, LightArrival* out);
  // Fraction of shadow rays towards `light` that reach it (1 with shadows off): one ray to its centre
  // (hard), or N stratified points on its emitter (sphere disk, sun cone, area surface); counts its bit.
  float light_visibility(const Light& light, std::size_t index, const SurfacePoint& s, const LightArrival& a,
                         const Branch& branch, std::uint32_t* shadow_bits);
  // Ambient phase: the environment's irradiance at the normal (SH for a map) on the diffuse term and its
  // prefiltered reflection on the rough specular share reflection rays leave out, occluded by AO rays.
  // `record` (may be null) receives the diffuse ambient term's parts for the resolve's denoiser.
  void add_ambient_light(const SurfacePoint& s, const SurfaceBrdf& brdf, const Branch& branch, Vec3* color,
                         AmbientSample* record);
  // Open fraction of the AO rays (1 without AO rays); `seen` / `all` get the (smooth) radiance the open /
  // all rays carry.
  float ambient_visibility(const SurfacePoint& s, const Branch& branch, Vec3* seen, Vec3* all);
  // Secondary-ray phases (Whitted): the Fresnel split, then reflection (mirror, or a few GGX-distributed
  // glossy rays whose escapes read the cone-filtered environment) and refraction.
  SecondaryWeights secondary_weights(const SurfacePoint& s, const SurfaceBrdf& brdf) const;
  void add_reflection(const SurfacePoint& s, Vec3 weight, Branch branch, RayCone cone, SampleGeometry* geom,
                      Vec3* color);
  void add_refraction(const SurfacePoint& s, const SurfaceBrdf& brdf, const SecondaryWeights& w, Branch branch,
                      RayCone cone, SampleGeometry* geom, Vec3* color);
};

void Shader::count_ray(RayKind kind) {
  ++ctx_.counters.rays_total;
  switch (kind) {
    case RayKind::kPrimary: ++ctx_.counters.rays_primary; break;
    case RayKind::kReflection: ++ctx_.counters.rays_reflection; break;
    case RayKind::kGlossy: ++ctx_.counters.rays_glossy; break;
    case RayKind::kRefraction: ++ctx_.counters.rays_refraction; break;
  }
}

// Where a ray continues after passing through the surface it hit at `hit` (alpha cut-outs): just behind
// the surface, same direction, what is left of its extent.
Ray continue_past(const Ray& ray, const Hit& hit, Vec3 p, Vec3 ng) {
  Ray next = ray;
  next.origin = offset_ray_origin(p, dot(ray.dir, ng) > 0.f ? ng : -ng);
  next.tmin = 0.f;
  next.tmax = ray.tmax - hit.t;
  return next;
}

Vec3 Shader::trace(const Ray& ray, RayKind kind, Branch branch, RayCone cone, const Lobe* lobe, HitInfo* info,
                   SampleGeometry* geom) {
  count_ray(kind);
  const float dir_len = length(ray.dir);
  const std::uint32_t random_key = branch.random_key();
  Ray r = ray;
  float travelled = 0.f;  // distance from ray.origin to r.origin (past cut-out layers)
  Hit hit;
  SurfacePoint s;
  for (int layer = 0;; ++layer) {
    hit = closest(r, kind);
    if (!hit.hit()) {
      if (info) info->object = -1;
      return environment(r, kind, lobe);
    }
    s = surface_at(r, hit, cone.at(travelled + hit.t * dir_len));
    if (!s.mat->cuts_out || layer + 1 >= kMaxCutoutLayers || !cut_out(*s.mat, s.alpha, random_key, layer)) break;
    travelled += hit.t * dir_len;
    r = continue_past(r, hit, s.p, s.ng);
    ++ctx_.counters.rays_alpha;
    ++ctx_.counters.rays_total;
  }
  ++ctx_.counters.shading_evals;  // the surface that stops the ray (cut-out layers cost alpha tests)
  const SurfaceBrdf brdf(*s.mat, s.base_color, s.n_dot_v);
  Vec3 color = s.mat->emission;
  std::uint32_t shadow_bits = 0;
  add_direct_light(s, brdf, branch, &color, &shadow_bits);
  add_ambient_light(s, brdf, branch, &color, info ? &info->ambient : nullptr);
  if (info) {
    info->object = static_cast<std::int32_t>(s.tri->object);
    info->normal = s.n;
    info->position = s.p;
    info->t = hit.t;
    info->shadow_bits = shadow_bits;
  }
  if (branch.depth < ctx_.settings.max_depth) {
    const SecondaryWeights w = secondary_weights(s, brdf);
    const RayCone here{s.cone_width, cone.spread};
    if (max_component(w.reflection) > 0.f) add_reflection(s, w.reflection, branch, here, geom, &color);
    if (w.refracts && w.refraction > 0.f) add_refraction(s, brdf, w, branch, here, geom, &color);
  }
  return color;
}

Vec3 Shader::environment(const Ray& ray, RayKind kind, const Lobe* lobe) {
  const Environment& env = ctx_.scene.environment();
  if (kind == RayKind::kGlossy && lobe && ctx_.settings.env_filter != EnvFilter::kOff && env.is_map()) {
    ++ctx_.counters.env_filtered_lookups;
    return env.filtered(lobe->axis, lobe->half_angle, static_cast<int>(ctx_.settings.env_filter));
  }
  if (env.is_map()) ++ctx_.counters.env_lookups;  // a constant colour needs no lookup
  // With environment filtering on, what camera and mirror rays see is interpolated between texels too.
  return env.radiance(ray.dir, ctx_.settings.env_filter != EnvFilter::kOff);
}

Rgba Shader::texture_sample(const Material& mat, std::uint32_t tri, const Hit& hit, float cone_width,
                            float cos_incidence) {
  const Scene& scene = ctx_.scene;
  const Texture& tex = scene.texture(mat.base_color_texture);
  const TriTexcoord* tc = scene.texcoord(tri);
  float u = 0.f, v = 0.f, lod = kInf;  // without UVs a texture contributes its mean (the 1x1 level)
  if (tc) {
    scene.uv_at(tri, hit.b0, hit.b1, hit.b2, &u, &v);
    lod = texture_lod(tc->lod_bias, tex.width(), tex.height(), cone_width, cos_incidence);
  }
  ++ctx_.counters.texture_fetches;
  const std::uint64_t base = kTextureBaseAddress + scene.texture_base(mat.base_color_texture);
  const std::uint32_t bytes = tex.texel_bytes();
  return tex.sample(u, v, lod, [&](std::uint64_t offset) {
    ++ctx_.counters.texel_reads;
    ctx_.texture_cache.access(base + offset, bytes);
  });
}

SurfacePoint Shader::surface_at(const Ray& ray, const Hit& hit, float cone_width) {
  const Scene& scene = ctx_.scene;
  SurfacePoint s;
  s.tri = &scene.tri(hit.tri);
  s.mat = &scene.materials()[s.tri->material];
  const TriShading& sh = scene.shading(hit.tri);
  const float* v = s.tri->v;
  // Hit point from barycentrics: as precise as the vertices, also far from the origin.
  s.p = Vec3(v[0], v[1], v[2]) * hit.b0 + Vec3(v[3], v[4], v[5]) * hit.b1 + Vec3(v[6], v[7], v[8]) * hit.b2;
  s.dir = normalize(ray.dir);
  s.ng = sh.ng;
  s.front = dot(s.dir, s.ng) < 0.f;
  if (!s.front) s.ng = -s.ng;  // ng now faces the incoming ray
  s.n = normalize(sh.n[0] * hit.b0 + sh.n[1] * hit.b1 + sh.n[2] * hit.b2);
  if (!s.front) s.n = -s.n;
  if (!(dot(s.n, s.ng) > 0.f) || !is_finite(s.n)) s.n = s.ng;
  s.view = -s.dir;
  s.n_dot_v = std::max(dot(s.n, s.view), 0.f);
  s.origin_out = offset_ray_origin(s.p, s.ng);
  s.origin_in = offset_ray_origin(s.p, -s.ng);
  s.cone_width = cone_width;
  s.base_color = s.mat->base_color;
  s.alpha = s.mat->alpha;
  if (s.mat->base_color_texture >= 0) {
    const Rgba t = texture_sample(*s.mat, hit.tri, hit, cone_width, dot(s.dir, s.ng));
    s.base_color = s.base_color * t.rgb;
    s.alpha *= t.a;
  }
  return s;
}

bool Shader::cut_out(const Material& mat, float alpha, std::uint32_t random_key, int layer) {
  ++ctx_.counters.alpha_tests;
  if (mat.alpha_mode == AlphaMode::kClip) return alpha < mat.alpha_cutoff;
  const std::uint32_t akey = hash_combine(random_key, (static_cast<std::uint32_t>(SamplePurpose::kAlpha) << 8) +
                                                          static_cast<std::uint32_t>(layer));
  return alpha <= u32_to_unit(hash_u32(akey));  // hashed: passes through with probability 1 - alpha
}

bool Shader::occluded_past_cutouts(Ray ray, TracedKind kind, std::uint32_t random_key, float cone_width) {
  const Scene& scene = ctx_.scene;
  if (!scene.has_cutouts()) return occluded(ray, kind);
  // Cut-outs need the hit's material and texture: closest hits, layer by layer (what an any-hit shader
  // does on a GPU).
  for (int layer = 0; layer < kMaxCutoutLayers; ++layer) {
    const Hit hit = closest_traced(ray, kind);
    if (!hit.hit()) return false;
    const TriRecord& tri = scene.tri(hit.tri);
    const Material& mat = scene.materials()[tri.material];
    if (!mat.cuts_out) return true;
    float alpha = mat.alpha;
    const Vec3 ng = scene.shading(hit.tri).ng;
    if (mat.base_color_texture >= 0)
      alpha *= texture_sample(mat, hit.tri, hit, cone_width, dot(normalize(ray.dir), ng)).a;
    if (!cut_out(mat, alpha, random_key, layer)) return true;
    const float* v = tri.v;
    const Vec3 p = Vec3(v[0], v[1], v[2]) * hit.b0 + Vec3(v[3], v[4], v[5]) * hit.b1 + Vec3(v[6], v[7], v[8]) * hit.b2;
    ray = continue_past(ray, hit, p, ng);
    ++ctx_.counters.rays_alpha;
    ++ctx_.counters.rays_total;
  }
  return true;  // a wall of cut-out layers counts as opaque
}

void Shader::add_direct_light(const SurfacePoint& s, const SurfaceBrdf& brdf, const Branch& branch,
                              Vec3* color, std::uint32_t* shadow_bits) {
  // A fully transmissive surface has no direct BRDF: no light, no shadow rays.
  const auto& lights = ctx_.scene.lights();
  const std::size_t light_count = brdf.opaque > 0.f ? lights.size() : 0;
  for (std::size_t li = 0; li < light_count; ++li) {
    LightArrival a;
    if (!light_arrival(lights[li], s, brdf, &a)) continue;
    const float visibility = light_visibility(lights[li], li, s, a, branch, shadow_bits);
    if (visibility <= 0.f) continue;
    *color += (brdf.diffuse() * a.irradiance + a.specular) * visibility;
  }
}

bool Shader::light_arrival(const Light& L, const SurfacePoint& s, const SurfaceBrdf& brdf, LightArrival* out) {
  if (L.kind == LightKind::kArea) return area_arrival(L, s, brdf, out);
  Vec3 to_light;
  float falloff = 1.f;  // 1 / distance^2 (sun: 1)
  float source_angle = 0.f;
  if (L.kind == LightKind::kSun) {
    to_light = -L.direction;
    source_angle = L.radius;
  } else {
    const Vec3 d = L.position - s.p;
    const float dist = length(d);
    if (!(dist > 0.f)) return false;
    to_light = d / dist;
    // A sphere light of radius R lights like a disk facing the point (Cycles' soft falloff):
    // irradiance I / (d^2 + R^2), which stays finite on the light's surface.
    falloff = 1.f / (dist * dist + L.radius * L.radius);
    if (L.radius > 0.f) source_angle = std::atan2(L.radius, dist);
  }
  const float n_dot_l = dot(s.n, to_light);
  if (n_dot_l <= 0.f || dot(s.ng, to_light) <= 0.f) return false;  // facing away: no light, no shadow ray
  Vec3 irradiance = L.color * (L.intensity * falloff * n_dot_l);
  if (L.kind == LightKind::kSpot) irradiance = irradiance * spot_attenuation(L, -to_light);
  if (max_component(irradiance) <= 0.f) return false;
  out->to_centre = to_light;
  out->irradiance = irradiance;
  // A sun of the environment map: reflection rays see it in the map, so its highlight here is only the
  // share of the specular they do not trace.
  const float share = L.environment ? 1.f - reflection_gloss(*s.mat) : 1.f;
  out->specular = brdf.specular(s.n, to_light, s.view, source_angle) * irradiance * share;
  return true;
}

bool Shader::area_arrival(const Light& L, const SurfacePoint& s, const SurfaceBrdf& brdf, LightArrival* out) {
  ++ctx_.counters.area_light_evals;
  // One-sided: only points in front of the emitting face receive light.
  if (!(dot(s.p - L.position, L.direction) > 0.f)) return false;
  Vec3 outline[16];
  const int count = area_outline(L, s.p, outline);
  const float g = projected_solid_angle(outline, count, s.n);  // irradiance per unit radiance (exact)
  if (!(g > 0.f)) return false;
  const Vec3 centre = L.position - s.p;
  const float dist = length(centre);
  if (!(dist > 0.f)) return false;
  const Vec3 radiance = L.color * L.intensity;
  out->to_centre = centre / dist;
  out->irradiance = radiance * g;
  // Specular: the emitter as kAreaCells x kAreaCells equal-area cells, each a small source at its centre
  // whose lobe is widened by the cell's angular size (a filtered quadrature: smooth highlights of the
  // emitter's shape, no single-point overestimate for large lights).
  out->specular = Vec3();
  if (max_component(brdf.f0) > 0.f && brdf.opaque > 0.f) {
    const float cell_area = L.area() / static_cast<float>(kAreaCells * kAreaCells);
    for (int j = 0; j < kAreaCells; ++j)
      for (int i = 0; i < kAreaCells; ++i) {
        const Sample2 cell{(i + 0.5f) / kAreaCells, (j + 0.5f) / kAreaCells};
        const Vec3 d = area_point(L, cell) - s.p;
        const float d2 = dot(d, d), len = std::sqrt(d2);
        if (!(len > 0.f)) continue;
        const Vec3 l = d / len;
        const float cos_r = dot(s.n, l), cos_e = -dot(l, L.direction);
        if (!(cos_r > 0.f && cos_e > 0.f)) continue;
        const float solid = cell_area * cos_e / d2;  // the cell's solid angle
        const float widen = std::sqrt(solid / kPi);  // its equivalent cone's half angle
        out->specular += brdf.specular(s.n, l, s.view, widen) * (solid * cos_r);
      }
    out->specular = out->specular * radiance;
  }
  return max_component(out->irradiance) > 0.f;
}

float Shader::light_visibility(const Light& L, std::size_t index, const SurfacePoint& s, const LightArrival& a,
                               const Branch& branch, std::uint32_t* shadow_bits) {
  const RenderSettings& st = ctx_.settings;
  if (st.shadow_samples <= 0) return 1.f;
  const bool area = L.kind == LightKind::kArea;
  const bool soft = (area || L.radius > 0.f) && st.shadow_samples > 1;
  const int ns = soft ? st.shadow_samples : 1;
  // Visible fraction of the light. Points of an area light are weighted by how much they light the
  // point (cos at the receiver x cos at the emitter / d^2): near parts of a large emitter matter more.
  float open = 0.f, total = 0.f;
  bool any_blocked = false;
  // Points on the light: this place's quarter of the block's stratified set.
  const std::uint32_t skey = hash_combine(branch.block_key(), (static_cast<std::uint32_t>(SamplePurpose::kShadow) << 8) +
                                                                  static_cast<std::uint32_t>(index));
  Vec3 t, b;
  onb(a.to_centre, &t, &b);
  for (int i = 0; i < ns; ++i) {
    Ray sr;
    sr.origin = s.origin_out;
    float weight = 1.f;
    if (L.kind == LightKind::kSun) {
      sr.dir = soft ? uniform_cone(r2_sample(skey, branch.stratum(i, ns)), a.to_centre, L.radius) : a.to_centre;
      sr.tmax = kInf;
    } else {
      Vec3 target = L.position;
      if (soft && area) {
        target = area_point(L, r2_sample(skey, branch.stratum(i, ns)));
      } else if (soft) {
        float dx, dy;
        concentric_disk(r2_sample(skey, branch.stratum(i, ns)), &dx, &dy);
        target = target + t * (dx * L.radius) + b * (dy * L.radius);
      }
      sr.dir = target - sr.origin;
      sr.tmax = 1.f - 1e-4f;  // stop just short of the light
      if (soft && area) {
        const float d2 = dot(sr.dir, sr.dir);
        weight = std::max(0.f, dot(sr.dir, s.n)) * std::max(0.f, -dot(sr.dir, L.direction)) / (d2 * d2);
        if (!(weight > 0.f)) continue;  // a point below the horizon or behind the emitter: no light, no ray
      }
    }
    ++ctx_.counters.rays_shadow;
    ++ctx_.counters.rays_total;
    total += weight;
    if (occluded_past_cutouts(sr, TracedKind::kShadow, hash_combine(skey, branch.stratum(i, ns)),
                              s.cone_width)) {
      any_blocked = true;
    } else {
      open += weight;
    }
  }
  if (any_blocked && index < 32) *shadow_bits |= 1u << index;
  return total > 0.f ? open / total : 0.f;
}

void Shader::add_ambient_light(const SurfacePoint& s, const SurfaceBrdf& brdf, const Branch& branch, Vec3* color,
                               AmbientSample* record) {
  const Environment& env = ctx_.scene.environment();
  if (!(max_component(env.mean()) > 0.f)) return;
  const float rough = 1.f - reflection_gloss(*s.mat);
  const bool diffuse = max_component(brdf.diffuse_albedo) > 0.f;
  const bool specular = rough > 0.f && brdf.opaque > 0.f && max_component(brdf.f0) > 0.f;
  if (!diffuse && !specular) return;
  // Diffuse: the environment's unoccluded irradiance / pi at the normal (SH for a map; its suns are
  // lights), times the share of it that AO rays find open (1 without AO rays). Rough specular (the share
  // reflection rays do not trace): the cosine-convolved environment around the mirror direction, a wide
  // lobe's prefiltered reflection, times the open fraction of the AO rays.
  Vec3 seen, all;
  const float open = ambient_visibility(s, branch, &seen, &all);
  const bool map = env.is_map();  // a constant colour needs no SH evaluation
  if (diffuse) {
    const Vec3 unoccluded = brdf.diffuse_albedo * env.diffuse_radiance(s.n);
    if (map) ++ctx_.counters.env_sh_evals;
    Vec3 visible(1.f, 1.f, 1.f);
    if (max_component(all) > 0.f)
      for (int c = 0; c < 3; ++c) visible[c] = all[c] > 0.f ? seen[c] / all[c] : 0.f;
    *color += unoccluded * visible;
    if (record && max_component(all) > 0.f) *record = {unoccluded, seen, all};
  }
  if (specular) {
    *color += schlick(brdf.f0, s.n_dot_v) * env.diffuse_radiance(reflect(s.dir, s.n)) * (rough * brdf.opaque * open);
    if (map) ++ctx_.counters.env_sh_evals;
  }
}

float Shader::ambient_visibility(const SurfacePoint& s, const Branch& branch, Vec3* seen, Vec3* all) {
  const int samples = ctx_.settings.ao_samples;
  if (samples <= 0) return 1.f;
  const Environment& env = ctx_.scene.environment();
  const bool map = env.is_map();
  // Cosine-distributed directions, this place's share of the block's stratified set. Each ray carries
  // the (smooth, SH) radiance of its direction; the share of that radiance the open rays carry is the
  // visible share of the irradiance (a ratio estimator: exact where nothing blocks the sky, 0 where
  // everything does, and light from bright blocked directions removed, not averaged away). For a
  // constant world it is the open fraction.
  const std::uint32_t akey = hash_combine(branch.block_key(), static_cast<std::uint32_t>(SamplePurpose::kAo) << 8);
  int open = 0;
  for (int i = 0; i < samples; ++i) {
    Ray ar;
    ar.origin = s.origin_out;
    ar.dir = cosine_hemisphere(r2_sample(akey, branch.stratum(i, samples)), s.n);
    if (dot(ar.dir, s.ng) <= 0.f) ar.dir = reflect(ar.dir, s.ng);
    ar.tmax = ctx_.ao_distance;
    ++ctx_.counters.rays_ao;
    ++ctx_.counters.rays_total;
    const Vec3 radiance = map ? env.smooth_radiance(ar.dir) : Vec3(1.f, 1.f, 1.f);
    if (map) ++ctx_.counters.env_sh_evals;
    *all += radiance;
    if (!occluded_past_cutouts(ar, TracedKind::kAo, hash_combine(akey, branch.stratum(i, samples)), s.cone_width)) {
      ++open;
      *seen += radiance;
    }
  }
  return static_cast<float>(open) / static_cast<float>(samples);
}

SecondaryWeights Shader::secondary_weights(const SurfacePoint& s, const SurfaceBrdf& brdf) const {
  const Material& mat = *s.mat;
  SecondaryWeights w;
  Vec3 specular;             // reflection of the opaque part (metal or smooth dielectric coat)
  float dielectric = 0.f;    // Fresnel reflection of the transmissive part
  if (mat.reflects()) specular = schlick(brdf.f0, s.n_dot_v) * (reflection_gloss(mat) * brdf.opaque);
  if (mat.refracts()) {
    const float eta = s.front ? 1.f / mat.ior : mat.ior;
    const float fr = fresnel_dielectric(s.n_dot_v, eta);
    dielectric = mat.transmission * fr;
    if (fr < 1.f && refract(s.dir, s.n, eta, &w.refraction_dir)) {
      w.refracts = true;
      w.refraction = mat.transmission * (1.f - fr);
    } else {
      dielectric = mat.transmission;  // total internal reflection
    }
  }
  w.reflection = specular + Vec3(dielectric, dielectric, dielectric);
  return w;
}

// The cone a filtered environment lookup averages, kept above the surface: a cone reaching under the
// horizon (grazing views) keeps its upper edge and brings its lower edge up to the horizon.
Lobe above_horizon(Vec3 axis, float half_angle, Vec3 ng) {
  Lobe lobe{axis, half_angle};
  const float elevation = std::asin(std::min(1.f, std::max(-1.f, dot(axis, ng))));
  if (elevation >= half_angle) return lobe;
  const Vec3 along = axis - ng * dot(axis, ng);
  const float len = length(along);
  if (!(len > 0.f)) return lobe;
  const float e = 0.5f * (elevation + half_angle);
  lobe.axis = normalize(along * (std::cos(e) / len) + ng * std::sin(e));
  lobe.half_angle = e;
  return lobe;
}

// Smith's Lambda of GGX for a direction at cosine c to the normal (Heitz 2014).
float smith_lambda(float c, float alpha) {
  const float c2 = std::max(c * c, 1e-8f);
  return 0.5f * (std::sqrt(1.f + alpha * alpha * (1.f - c2) / c2) - 1.f);
}

void Shader::add_reflection(const SurfacePoint& s, Vec3 weight, Branch branch, RayCone cone, SampleGeometry* geom,
                            Vec3* color) {
  const Material& mat = *s.mat;
  Vec3 mirror = reflect(s.dir, s.n);
  if (dot(mirror, s.ng) <= 0.f) mirror = reflect(s.dir, s.ng);
  const bool glossy = mat.roughness > 1e-3f && !mat.refracts();
  // Directions to trace and their weights. A mirror: one ray. A rough lobe: GGX microfacet normals
  // (stratified by the R2 sequence), the view mirrored about each, weighted by G2 (v.h) / ((n.h) (n.v))
  // (the importance-sampling weight of D(h) (n.h)) and normalised to the weights' sum: the energy single
  // scattering loses at grazing angles comes back, as Cycles' multiscatter GGX returns it. A glossy ray
  // that leaves the scene reads the filtered environment around its own direction over most of the
  // lobe's cone, so the rays together span the lobe's off-specular spread at grazing views.
  struct Dir { Vec3 d; float w; };
  Dir dirs[kGlossyRays];
  int count = 0;
  float total = 0.f;
  const float lobe_cone = glossy ? glossy_cone(mat.roughness) : 0.f;
  RayCone next = cone;
  if (glossy) {
    const int rays = branch.depth == 0 ? kGlossyRays : 1;
    const float alpha = ggx_alpha(mat.roughness);
    next.spread += lobe_cone / std::sqrt(static_cast<float>(rays));  // one ray's share of the blur
    // Lobe directions: a fixed stratified set (not rotated per block: a rough reflection is smooth, not
    // noisy), a different quarter of it at each place of the 2x2 sample block (the same in every 2x2
    // block: no pattern repeats across pixels).
    const std::uint32_t gkey = static_cast<std::uint32_t>(SamplePurpose::kGlossy) << 8;
    const float n_v = std::max(s.n_dot_v, 1e-4f);
    for (int i = 0; i < rays; ++i) {
      const Vec3 h = ggx_normal(r2_sample(gkey, branch.stratum_2x2(i, rays)), s.n, alpha);
      const Vec3 l = reflect(s.dir, h);
      const float n_l = dot(l, s.n), n_h = dot(h, s.n), v_h = dot(s.view, h);
      if (!(dot(l, s.ng) > 0.f && n_l > 0.f && n_h > 0.f && v_h > 0.f)) continue;  // below the surface
      const float g2 = 1.f / (1.f + smith_lambda(n_v, alpha) + smith_lambda(n_l, alpha));
      const float w = g2 * v_h / (n_h * n_v);
      if (!(w > 0.f) || !std::isfinite(w)) continue;
      dirs[count++] = {l, w};
      total += w;
    }
  }
  if (count == 0) {  // a mirror, or no lobe sample above the surface: the mirror direction
    dirs[0] = {mirror, 1.f};
    count = 1;
    total = 1.f;
  }
  for (int i = 0; i < count; ++i) {
    Ray rr;
    rr.origin = s.origin_out;
    rr.dir = dirs[i].d;
    HitInfo sec;
    const Lobe own = above_horizon(dirs[i].d, 0.75f * lobe_cone, s.ng);
    const Vec3 c = trace(rr, glossy ? RayKind::kGlossy : RayKind::kReflection,
                         branch.reflected(static_cast<std::uint32_t>(i)), next, glossy ? &own : nullptr,
                         (geom && i == 0) ? &sec : nullptr, nullptr);
    *color += c * weight * (dirs[i].w / total);
    if (geom && i == 0) {
      geom->sec_object[0] = sec.object;
      geom->sec_normal[0] = sec.normal;
      geom->sec_shadow_bits |= sec.shadow_bits;
    }
  }
}

void Shader::add_refraction(const SurfacePoint& s, const SurfaceBrdf& brdf, const SecondaryWeights& w,
                            Branch branch, RayCone cone, SampleGeometry* geom, Vec3* color) {
  Ray tr;
  tr.origin = s.origin_in;
  tr.dir = w.refraction_dir;
  HitInfo sec;
  const Vec3 c = trace(tr, RayKind::kRefraction, branch.refracted(), cone, nullptr, geom ? &sec : nullptr, nullptr);
  *color += c * brdf.base_color * w.refraction;
  if (geom) {
    geom->sec_object[1] = sec.object;
    geom->sec_normal[1] = sec.normal;
    geom->sec_shadow_bits |= sec.shadow_bits << 16 | sec.shadow_bits >> 16;
  }
}

}  // namespace

void TraceOptions::validate() const {
  if (bvh_width != 2 && bvh_width != 4) throw std::invalid_argument("bvh_width must be 2 or 4");
}

TileContext::TileContext(const Scene& s, const RenderSettings& st, const Camera& c, const CacheConfig& cc,
                         const TraceOptions& options, const CacheConfig& texture_cc)
    : scene(s), settings(st), camera(c), cache(cc), texture_cache(texture_cc), trace(options) {
  trace.validate();
  cos_threshold = st.normal_threshold_deg < 0.f ? 2.f : std::cos(st.normal_threshold_deg * kPi / 180.f);
  ao_distance = st.ao_distance > 0.f ? st.ao_distance : kInf;
  // Per pixel of the whole frame (a window of it, Camera::crop_*, has the frame's pixels).
  pixel_spread =
      2.f * c.tan_half() / static_cast<float>(std::max(1, c.frame_height())) / static_cast<float>(st.subgrid());
}

void TileContext::finish() {
  const CacheStats& cs = cache.stats();
  counters.cache_accesses += cs.accesses;
  counters.cache_misses += cs.misses;
  counters.dram_bytes_read += cs.dram_bytes;
  const CacheStats& ts = texture_cache.stats();  // texel reads are counted as they happen
  counters.texture_cache_misses += ts.misses;
  counters.texture_dram_bytes += ts.dram_bytes;
}

SampleResult trace_sample(TileContext& ctx, float px, float py, std::uint32_t key) {
  return trace_frame_sample(ctx, px + static_cast<float>(ctx.camera.crop_x), py + static_cast<float>(ctx.camera.crop_y),
                            key);
}

SampleResult trace_frame_sample(TileContext& ctx, float fx, float fy, std::uint32_t key) {
  Shader shader(ctx);
  ++ctx.counters.raygen_evals;
  const Ray ray = ctx.camera.primary_frame(fx, fy);
  SampleResult out;
  HitInfo info;
  // A pixel off the image centre subtends a smaller angle: cos^2 of its angle to the axis (radially), so a
  // plane facing the camera gets the same texel footprint everywhere.
  const float c = dot(ray.dir, ctx.camera.forward);
  const RayCone cone{0.f, ctx.pixel_spread * c * c};
  const int k = ctx.settings.subgrid();
  // The sample's place in its 4x4 block of the sample grid and the block's key, by its position in the
  // whole frame (a window of it samples like the whole). Coordinates may be negative: samples just outside
  // the frame that the pixel filter reads; modulo 2^32 they keep their places and blocks.
  const float fk = static_cast<float>(k);
  const auto sx = static_cast<std::uint32_t>(static_cast<std::int32_t>(std::floor(fx * fk)));
  const auto sy = static_cast<std::uint32_t>(static_cast<std::int32_t>(std::floor(fy * fk)));
  const std::uint32_t place = (sx & 1u) + 2u * (sy & 1u) + 4u * ((sx >> 1) & 1u) + 8u * ((sy >> 1) & 1u);
  const Branch root{key, 1u, 0, place, sample_key(sx >> 2, sy >> 2, static_cast<std::uint32_t>(k) | 0x200u)};
  out.color = shader.trace(ray, RayKind::kPrimary, root, cone, nullptr, &info, &out.geom);
  out.geom.object = info.object;
  out.ambient = info.ambient;
  if (info.object >= 0) {
    out.geom.normal = info.normal;
    out.geom.position = info.position;
    out.geom.depth = dot(info.position - ctx.camera.position, ctx.camera.forward);
    out.geom.shadow_bits = info.shadow_bits;
  } else {
    out.geom.position = ray.dir;  // direction of the miss (a point at infinity)
    out.geom.depth = kInf;
  }
  return out;
}

}  // namespace sim_core
