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

Vec3 schlick(Vec3 f0, float cos_theta) {
  const float m = std::min(1.f, std::max(0.f, 1.f - cos_theta));
  const float m2 = m * m, w = m2 * m2 * m;
  return f0 + (Vec3(1.f, 1.f, 1.f) - f0) * w;
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
float smoothstep(float e0, float e1, float x) {
  if (e0 == e1) return x >= e1 ? 1.f : 0.f;
  const float t = std::min(1.f, std::max(0.f, (x - e0) / (e1 - e0)));
  return t * t * (3.f - 2.f * t);
}

// Half angle of the cone a glossy reflection samples (and the SAT filter averages over).
float glossy_cone(float roughness) {
  return std::min(roughness, 1.f) * EnvironmentFilter::kMaxConeHalfAngle;
}

// Where a ray sits in its sample's ray tree: bounce depth and branch code (root 1, reflection child
// 3p + 1, refraction child 3p + 2). Random numbers hash (sample key, branch), never the tracing order.
struct Branch {
  std::uint32_t key;
  std::uint32_t path;
  int depth;
  std::uint32_t random_key() const { return hash_combine(key, path); }
  Branch reflected() const { return {key, path * 3u + 1u, depth + 1}; }
  Branch refracted() const { return {key, path * 3u + 2u, depth + 1}; }
};

struct HitInfo {  // what the caller (primary sample) records about a ray's first hit
  std::int32_t object = -1;
  Vec3 normal;
  Vec3 position;
  float t = kInf;
  std::uint32_t shadow_bits = 0;
};

// Geometry of a ray's hit, oriented towards the incoming ray.
struct SurfacePoint {
  const TriRecord* tri;
  const Material* mat;
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

// The material's scattering terms at a hit: Lambert diffuse plus normalised Blinn-Phong specular with
// Schlick's Fresnel, scaled by the opaque (non-transmitted) fraction.
struct SurfaceBrdf {
  Vec3 base_color;
  float opaque;
  Vec3 diffuse_albedo;
  Vec3 f0;
  float shininess;
  float spec_norm;

  explicit SurfaceBrdf(const Material& mat)
      : base_color(mat.base_color),
        opaque(1.f - mat.transmission),
        diffuse_albedo(mat.base_color * ((1.f - mat.metallic) * opaque)),
        f0(lerp(Vec3(0.04f, 0.04f, 0.04f), mat.base_color, mat.metallic)) {
    const float r = std::max(mat.roughness, 0.02f);
    shininess = std::min(2.f / (r * r * r * r) - 2.f, 1.0e4f);
    spec_norm = (shininess + 8.f) / (8.f * kPi);
  }
  // BRDF value for light arriving from unit `to_light`, seen from unit `view`, about shading normal n.
  Vec3 eval(Vec3 n, Vec3 to_light, Vec3 view) const {
    const Vec3 h = normalize(to_light + view);
    const float spec = spec_norm * std::pow(std::max(dot(n, h), 0.f), shininess);
    return diffuse_albedo * (1.f / kPi) + schlick(f0, std::max(dot(h, view), 0.f)) * (spec * opaque);
  }
};

// Light arriving at a surface point from one light, before shadowing.
struct LightArrival {
  Vec3 to_light;  // unit direction towards the light (its centre)
  float n_dot_l;
  Vec3 radiance;  // after distance falloff and spot cone
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
  // first hits of its reflection/refraction rays.
  Vec3 trace(const Ray& ray, RayKind kind, Branch branch, float cone, HitInfo* info, SampleGeometry* geom);

 private:
  TileContext& ctx_;
  TileRecorder rec_;

  // The tile's tree walk (the 4-wide BVH, or the binary reference walk when the context asks for it):
  // closest hit, and any hit for shadow and ambient-occlusion rays.
  Hit closest(const Ray& ray, RayKind kind) {
    if (ctx_.trace.log_rays) ctx_.ray_log.push_back({ray, traced_kind(kind)});
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
  Vec3 environment(const Ray& ray, RayKind kind, float cone);
  // Primary-hit phase: hit point, oriented normals and spawn points.
  SurfacePoint surface_at(const Ray& ray, const Hit& hit) const;
  // Direct-light phase: every light's contribution, shadowed by shadow rays; sets one shadow bit per
  // occluded light.
  void add_direct_light(const SurfacePoint& s, const SurfaceBrdf& brdf, std::uint32_t random_key, Vec3* color,
                        std::uint32_t* shadow_bits);
  bool light_arrival(const Light& light, const SurfacePoint& s, LightArrival* out) const;
  // Fraction of shadow rays towards `light` that reach it (1 with shadows off); counts its shadow bit.
  float light_visibility(const Light& light, std::size_t index, const SurfacePoint& s, Vec3 to_light,
                         std::uint32_t random_key, std::uint32_t* shadow_bits);
  // Ambient phase: the environment's mean radiance on the diffuse term, occluded by AO rays.
  void add_ambient_light(const SurfacePoint& s, const SurfaceBrdf& brdf, std::uint32_t random_key, Vec3* color);
  float ambient_visibility(const SurfacePoint& s, std::uint32_t random_key);
  // Secondary-ray phases (Whitted): the Fresnel split, then reflection and refraction.
  SecondaryWeights secondary_weights(const SurfacePoint& s, const SurfaceBrdf& brdf) const;
  void add_reflection(const SurfacePoint& s, Vec3 weight, Branch branch, SampleGeometry* geom, Vec3* color);
  void add_refraction(const SurfacePoint& s, const SurfaceBrdf& brdf, const SecondaryWeights& w, Branch branch,
                      SampleGeometry* geom, Vec3* color);
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

Vec3 Shader::trace(const Ray& ray, RayKind kind, Branch branch, float cone, HitInfo* info,
                   SampleGeometry* geom) {
  count_ray(kind);
  const Hit hit = closest(ray, kind);
  if (!hit.hit()) {
    if (info) info->object = -1;
    return environment(ray, kind, cone);
  }
  ++ctx_.counters.shading_evals;
  const SurfacePoint s = surface_at(ray, hit);
  const SurfaceBrdf brdf(*s.mat);
  const std::uint32_t random_key = branch.random_key();
  Vec3 color = s.mat->emission;
  std::uint32_t shadow_bits = 0;
  add_direct_light(s, brdf, random_key, &color, &shadow_bits);
  add_ambient_light(s, brdf, random_key, &color);
  if (info) {
    info->object = static_cast<std::int32_t>(s.tri->object);
    info->normal = s.n;
    info->position = s.p;
    info->t = hit.t;
    info->shadow_bits = shadow_bits;
  }
  if (branch.depth < ctx_.settings.max_depth) {
    const SecondaryWeights w = secondary_weights(s, brdf);
    if (max_component(w.reflection) > 0.f) add_reflection(s, w.reflection, branch, geom, &color);
    if (w.refracts && w.refraction > 0.f) add_refraction(s, brdf, w, branch, geom, &color);
  }
  return color;
}

Vec3 Shader::environment(const Ray& ray, RayKind kind, float cone) {
  const Environment& env = ctx_.scene.environment();
  if (kind == RayKind::kGlossy && ctx_.settings.env_filter != EnvFilter::kOff && env.is_map()) {
    ++ctx_.counters.env_filtered_lookups;
    return env.filtered(ray.dir, cone, static_cast<int>(ctx_.settings.env_filter));
  }
  if (env.is_map()) ++ctx_.counters.env_lookups;  // a constant colour needs no lookup
  return env.radiance(ray.dir);
}

SurfacePoint Shader::surface_at(const Ray& ray, const Hit& hit) const {
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
  return s;
}

void Shader::add_direct_light(const SurfacePoint& s, const SurfaceBrdf& brdf, std::uint32_t random_key,
                              Vec3* color, std::uint32_t* shadow_bits) {
  // A fully transmissive surface has no direct BRDF: no light, no shadow rays.
  const auto& lights = ctx_.scene.lights();
  const std::size_t light_count = brdf.opaque > 0.f ? lights.size() : 0;
  for (std::size_t li = 0; li < light_count; ++li) {
    LightArrival a;
    if (!light_arrival(lights[li], s, &a)) continue;
    const float visibility = light_visibility(lights[li], li, s, a.to_light, random_key, shadow_bits);
    if (visibility <= 0.f) continue;
    *color += brdf.eval(s.n, a.to_light, s.view) * a.radiance * (a.n_dot_l * visibility);
  }
}

bool Shader::light_arrival(const Light& L, const SurfacePoint& s, LightArrival* out) const {
  Vec3 to_light;
  float dist = kInf;
  if (L.kind == LightKind::kSun) {
    to_light = -L.direction;
  } else {
    const Vec3 d = L.position - s.p;
    dist = length(d);
    if (!(dist > 0.f)) return false;
    to_light = d / dist;
  }
  const float n_dot_l = dot(s.n, to_light);
  if (n_dot_l <= 0.f || dot(s.ng, to_light) <= 0.f) return false;  // facing away: no light, no shadow ray
  Vec3 radiance = L.color * L.intensity;
  if (L.kind != LightKind::kSun) radiance = radiance / (dist * dist);
  if (L.kind == LightKind::kSpot) {
    const float c = dot(-to_light, L.direction);
    radiance = radiance * smoothstep(std::cos(L.spot_angle), std::cos(L.spot_angle * 0.85f), c);
  }
  if (max_component(radiance) <= 0.f) return false;
  out->to_light = to_light;
  out->n_dot_l = n_dot_l;
  out->radiance = radiance;
  return true;
}

float Shader::light_visibility(const Light& L, std::size_t index, const SurfacePoint& s, Vec3 to_light,
                               std::uint32_t random_key, std::uint32_t* shadow_bits) {
  const RenderSettings& st = ctx_.settings;
  if (st.shadow_samples <= 0) return 1.f;
  // Soft shadows sample the light's sphere (point, spot) or cone of directions (sun).
  const bool soft = L.radius > 0.f && st.shadow_samples > 1;
  const int ns = soft ? st.shadow_samples : 1;
  int blocked = 0;
  const std::uint32_t skey = hash_combine(random_key, (static_cast<std::uint32_t>(SamplePurpose::kShadow) << 8) +
                                                          static_cast<std::uint32_t>(index));
  Vec3 t, b;
  onb(to_light, &t, &b);
  for (int i = 0; i < ns; ++i) {
    Ray sr;
    sr.origin = s.origin_out;
    if (L.kind == LightKind::kSun) {
      sr.dir = soft ? uniform_cone(r2_sample(skey, i), to_light, L.radius) : to_light;
      sr.tmax = kInf;
    } else {
      Vec3 target = L.position;
      if (soft) {
        float dx, dy;
        concentric_disk(r2_sample(skey, i), &dx, &dy);
        target = target + t * (dx * L.radius) + b * (dy * L.radius);
      }
      sr.dir = target - sr.origin;
      sr.tmax = 1.f - 1e-4f;  // stop just short of the light
    }
    ++ctx_.counters.rays_shadow;
    ++ctx_.counters.rays_total;
    if (occluded(sr, TracedKind::kShadow)) ++blocked;
  }
  if (blocked > 0 && index < 32) *shadow_bits |= 1u << index;
  return 1.f - static_cast<float>(blocked) / static_cast<float>(ns);
}

void Shader::add_ambient_light(const SurfacePoint& s, const SurfaceBrdf& brdf, std::uint32_t random_key,
                               Vec3* color) {
  const Vec3 ambient = ctx_.scene.environment().mean();
  if (!(max_component(brdf.diffuse_albedo) > 0.f && max_component(ambient) > 0.f)) return;
  const float ao = ambient_visibility(s, random_key);
  *color += brdf.diffuse_albedo * ambient * ao;
}

float Shader::ambient_visibility(const SurfacePoint& s, std::uint32_t random_key) {
  const int samples = ctx_.settings.ao_samples;
  if (samples <= 0) return 1.f;
  const std::uint32_t akey = hash_combine(random_key, static_cast<std::uint32_t>(SamplePurpose::kAo) << 8);
  int open = 0;
  for (int i = 0; i < samples; ++i) {
    Ray ar;
    ar.origin = s.origin_out;
    ar.dir = cosine_hemisphere(r2_sample(akey, i), s.n);
    if (dot(ar.dir, s.ng) <= 0.f) ar.dir = reflect(ar.dir, s.ng);
    ar.tmax = ctx_.ao_distance;
    ++ctx_.counters.rays_ao;
    ++ctx_.counters.rays_total;
    if (!occluded(ar, TracedKind::kAo)) ++open;
  }
  return static_cast<float>(open) / static_cast<float>(samples);
}

SecondaryWeights Shader::secondary_weights(const SurfacePoint& s, const SurfaceBrdf& brdf) const {
  const Material& mat = *s.mat;
  SecondaryWeights w;
  Vec3 specular;             // reflection of the opaque part (metal or smooth dielectric coat)
  float dielectric = 0.f;    // Fresnel reflection of the transmissive part
  if (mat.reflects()) {
    const float gloss = mat.metallic + (1.f - mat.metallic) *
                                           std::min(1.f, std::max(0.f, 1.f - mat.roughness / Material::kReflectRoughness));
    specular = schlick(brdf.f0, s.n_dot_v) * (gloss * brdf.opaque);
  }
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

void Shader::add_reflection(const SurfacePoint& s, Vec3 weight, Branch branch, SampleGeometry* geom,
                            Vec3* color) {
  const Material& mat = *s.mat;
  Vec3 rdir = reflect(s.dir, s.n);
  if (dot(rdir, s.ng) <= 0.f) rdir = reflect(s.dir, s.ng);
  const bool glossy = mat.roughness > 1e-3f && !mat.refracts();
  RayKind kind = RayKind::kReflection;
  float cone = 0.f;
  if (glossy) {
    kind = RayKind::kGlossy;
    cone = glossy_cone(mat.roughness);
    if (ctx_.settings.env_filter == EnvFilter::kOff) {
      // Point-sampled glossy lobe: one ray in the cone (the filtered path traces the mirror ray and
      // lets the summed-area table average the environment over the cone instead).
      const std::uint32_t gkey =
          hash_combine(branch.random_key(), static_cast<std::uint32_t>(SamplePurpose::kGlossy) << 8);
      const Vec3 g = uniform_cone(r2_sample(gkey, 0), rdir, cone);
      if (dot(g, s.ng) > 0.f) rdir = g;
    }
  }
  Ray rr;
  rr.origin = s.origin_out;
  rr.dir = rdir;
  HitInfo sec;
  const Vec3 c = trace(rr, kind, branch.reflected(), cone, geom ? &sec : nullptr, nullptr);
  *color += c * weight;
  if (geom) {
    geom->sec_object[0] = sec.object;
    geom->sec_normal[0] = sec.normal;
    geom->sec_shadow_bits |= sec.shadow_bits;
  }
}

void Shader::add_refraction(const SurfacePoint& s, const SurfaceBrdf& brdf, const SecondaryWeights& w,
                            Branch branch, SampleGeometry* geom, Vec3* color) {
  Ray tr;
  tr.origin = s.origin_in;
  tr.dir = w.refraction_dir;
  HitInfo sec;
  const Vec3 c = trace(tr, RayKind::kRefraction, branch.refracted(), 0.f, geom ? &sec : nullptr, nullptr);
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
                         const TraceOptions& options)
    : scene(s), settings(st), camera(c), cache(cc), trace(options) {
  trace.validate();
  cos_threshold = st.normal_threshold_deg < 0.f ? 2.f : std::cos(st.normal_threshold_deg * kPi / 180.f);
  ao_distance = st.ao_distance > 0.f ? st.ao_distance : 0.1f * s.diagonal();
}

void TileContext::finish() {
  const CacheStats& cs = cache.stats();
  counters.cache_accesses += cs.accesses;
  counters.cache_misses += cs.misses;
  counters.dram_bytes_read += cs.dram_bytes;
}

SampleResult trace_sample(TileContext& ctx, float px, float py, std::uint32_t key) {
  Shader shader(ctx);
  ++ctx.counters.raygen_evals;
  const Ray ray = ctx.camera.primary(px, py);
  SampleResult out;
  HitInfo info;
  out.color = shader.trace(ray, RayKind::kPrimary, Branch{key, 1u, 0}, 0.f, &info, &out.geom);
  out.geom.object = info.object;
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
