#include "sim_core/render.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "sim_core/sampler.h"
#include "sim_core/sampling.h"

namespace sim_core {
namespace {

// Observes the traversal for the energy model: node and triangle fetches go through the tile's cache,
// closest-hit comparisons into the comparator histogram.
struct TileRecorder {
  TileContext& ctx;
  void node(std::uint32_t i) {
    ++ctx.counters.bvh_node_visits;
    ctx.cache.access(kNodeBaseAddress + static_cast<std::uint64_t>(i) * sizeof(BvhNode), sizeof(BvhNode));
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

struct HitInfo {  // what the caller (primary sample) records about a ray's first hit
  std::int32_t object = -1;
  Vec3 normal;
  Vec3 position;
  float t = kInf;
  std::uint32_t shadow_bits = 0;
};

class Shader {
 public:
  explicit Shader(TileContext& ctx) : ctx_(ctx), rec_{ctx} {}

  // Radiance along `ray`; depth = bounces so far; path encodes the branch for the sampler key.
  Vec3 trace(const Ray& ray, RayKind kind, int depth, std::uint32_t key, std::uint32_t path, float cone,
             HitInfo* info, SampleGeometry* geom);

 private:
  TileContext& ctx_;
  TileRecorder rec_;

  Vec3 miss(const Ray& ray, RayKind kind, float cone) {
    const Environment& env = ctx_.scene.environment();
    if (kind == RayKind::kGlossy && ctx_.settings.env_filter != EnvFilter::kOff && env.is_map()) {
      ++ctx_.counters.env_filtered_lookups;
      return env.filtered(ray.dir, cone, static_cast<int>(ctx_.settings.env_filter));
    }
    if (env.is_map()) ++ctx_.counters.env_lookups;  // a constant colour needs no lookup
    return env.radiance(ray.dir);
  }

  bool occluded(const Ray& r) {
    return ctx_.scene.occluded(r, rec_);
  }
  void count_ray(RayKind kind) {
    ++ctx_.counters.rays_total;
    switch (kind) {
      case RayKind::kPrimary: ++ctx_.counters.rays_primary; break;
      case RayKind::kReflection: ++ctx_.counters.rays_reflection; break;
      case RayKind::kGlossy: ++ctx_.counters.rays_glossy; break;
      case RayKind::kRefraction: ++ctx_.counters.rays_refraction; break;
    }
  }
};

Vec3 Shader::trace(const Ray& ray, RayKind kind, int depth, std::uint32_t key, std::uint32_t path, float cone,
                   HitInfo* info, SampleGeometry* geom) {
  count_ray(kind);
  const Scene& scene = ctx_.scene;
  const RenderSettings& st = ctx_.settings;
  const Hit hit = scene.closest(ray, rec_);
  if (!hit.hit()) {
    if (info) info->object = -1;
    return miss(ray, kind, cone);
  }
  ++ctx_.counters.shading_evals;
  const TriRecord& tri = scene.tri(hit.tri);
  const TriShading& sh = scene.shading(hit.tri);
  const Material& mat = scene.materials()[tri.material];
  const float* v = tri.v;
  // Hit point from barycentrics: as precise as the vertices, also far from the origin.
  const Vec3 p = Vec3(v[0], v[1], v[2]) * hit.b0 + Vec3(v[3], v[4], v[5]) * hit.b1 + Vec3(v[6], v[7], v[8]) * hit.b2;
  const Vec3 dir = normalize(ray.dir);
  Vec3 ng = sh.ng;
  const bool front = dot(dir, ng) < 0.f;
  if (!front) ng = -ng;  // ng now faces the incoming ray
  Vec3 n = normalize(sh.n[0] * hit.b0 + sh.n[1] * hit.b1 + sh.n[2] * hit.b2);
  if (!front) n = -n;
  if (!(dot(n, ng) > 0.f) || !is_finite(n)) n = ng;
  const Vec3 view = -dir;
  const float n_dot_v = std::max(dot(n, view), 0.f);
  const Vec3 origin_out = offset_ray_origin(p, ng);   // leaving on the incoming side
  const Vec3 origin_in = offset_ray_origin(p, -ng);   // entering the surface (refraction)

  const float opaque = 1.f - mat.transmission;
  const Vec3 diffuse_albedo = mat.base_color * ((1.f - mat.metallic) * opaque);
  const Vec3 f0 = lerp(Vec3(0.04f, 0.04f, 0.04f), mat.base_color, mat.metallic);
  const float r = std::max(mat.roughness, 0.02f);
  const float shininess = std::min(2.f / (r * r * r * r) - 2.f, 1.0e4f);
  const float spec_norm = (shininess + 8.f) / (8.f * kPi);

  Vec3 color = mat.emission;
  std::uint32_t shadow_bits = 0;
  const std::uint32_t path_key = hash_combine(key, path);

  // Direct light with shadow rays (none for a fully transmissive surface: its direct BRDF is zero).
  const auto& lights = scene.lights();
  const std::size_t light_count = opaque > 0.f ? lights.size() : 0;
  for (std::size_t li = 0; li < light_count; ++li) {
    const Light& L = lights[li];
    Vec3 to_light;
    float dist = kInf;
    if (L.kind == LightKind::kSun) {
      to_light = -L.direction;
    } else {
      const Vec3 d = L.position - p;
      dist = length(d);
      if (!(dist > 0.f)) continue;
      to_light = d / dist;
    }
    const float n_dot_l = dot(n, to_light);
    if (n_dot_l <= 0.f || dot(ng, to_light) <= 0.f) continue;  // facing away: no light, no shadow ray
    Vec3 radiance = L.color * L.intensity;
    if (L.kind != LightKind::kSun) radiance = radiance / (dist * dist);
    if (L.kind == LightKind::kSpot) {
      const float c = dot(-to_light, L.direction);
      radiance = radiance * smoothstep(std::cos(L.spot_angle), std::cos(L.spot_angle * 0.85f), c);
    }
    if (max_component(radiance) <= 0.f) continue;
    float visibility = 1.f;
    if (st.shadow_samples > 0) {
      const bool soft = L.radius > 0.f && st.shadow_samples > 1;
      const int ns = soft ? st.shadow_samples : 1;
      int blocked = 0;
      const std::uint32_t skey = hash_combine(path_key, (static_cast<std::uint32_t>(SamplePurpose::kShadow) << 8) +
                                                            static_cast<std::uint32_t>(li));
      Vec3 t, b;
      onb(to_light, &t, &b);
      for (int i = 0; i < ns; ++i) {
        Ray sr;
        sr.origin = origin_out;
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
        if (occluded(sr)) ++blocked;
      }
      if (blocked > 0 && li < 32) shadow_bits |= 1u << li;
      visibility = 1.f - static_cast<float>(blocked) / static_cast<float>(ns);
    }
    if (visibility <= 0.f) continue;
    const Vec3 h = normalize(to_light + view);
    const float spec = spec_norm * std::pow(std::max(dot(n, h), 0.f), shininess);
    const Vec3 brdf = diffuse_albedo * (1.f / kPi) + schlick(f0, std::max(dot(h, view), 0.f)) * (spec * opaque);
    color += brdf * radiance * (n_dot_l * visibility);
  }

  // Ambient light from the environment, occluded by AO rays.
  const Vec3 ambient = scene.environment().mean();
  if (max_component(diffuse_albedo) > 0.f && max_component(ambient) > 0.f) {
    float ao = 1.f;
    if (st.ao_samples > 0) {
      const std::uint32_t akey = hash_combine(path_key, static_cast<std::uint32_t>(SamplePurpose::kAo) << 8);
      int open = 0;
      for (int i = 0; i < st.ao_samples; ++i) {
        Ray ar;
        ar.origin = origin_out;
        ar.dir = cosine_hemisphere(r2_sample(akey, i), n);
        if (dot(ar.dir, ng) <= 0.f) ar.dir = reflect(ar.dir, ng);
        ar.tmax = ctx_.ao_distance;
        ++ctx_.counters.rays_ao;
        ++ctx_.counters.rays_total;
        if (!occluded(ar)) ++open;
      }
      ao = static_cast<float>(open) / static_cast<float>(st.ao_samples);
    }
    color += diffuse_albedo * ambient * ao;
  }

  if (info) {
    info->object = static_cast<std::int32_t>(tri.object);
    info->normal = n;
    info->position = p;
    info->t = hit.t;
    info->shadow_bits = shadow_bits;
  }

  // Secondary rays (Whitted): reflection (mirror or glossy) and refraction with Fresnel.
  if (depth < st.max_depth) {
    float refl_weight_scalar = 0.f;
    Vec3 refl_weight;
    bool do_refr = false;
    float refr_weight = 0.f;
    Vec3 refr_dir;
    if (mat.reflects()) {
      const float gloss = mat.metallic + (1.f - mat.metallic) *
                                             std::min(1.f, std::max(0.f, 1.f - mat.roughness / Material::kReflectRoughness));
      refl_weight = schlick(f0, n_dot_v) * (gloss * opaque);
    }
    if (mat.refracts()) {
      const float eta = front ? 1.f / mat.ior : mat.ior;
      const float fr = fresnel_dielectric(n_dot_v, eta);
      refl_weight_scalar = mat.transmission * fr;
      if (fr < 1.f && refract(dir, n, eta, &refr_dir)) {
        do_refr = true;
        refr_weight = mat.transmission * (1.f - fr);
      } else {
        refl_weight_scalar = mat.transmission;
      }
    }
    const Vec3 total_refl = refl_weight + Vec3(refl_weight_scalar, refl_weight_scalar, refl_weight_scalar);
    if (max_component(total_refl) > 0.f) {
      Vec3 rdir = reflect(dir, n);
      if (dot(rdir, ng) <= 0.f) rdir = reflect(dir, ng);
      const bool glossy = mat.roughness > 1e-3f && !mat.refracts();
      RayKind rk = RayKind::kReflection;
      float rcone = 0.f;
      if (glossy) {
        rk = RayKind::kGlossy;
        rcone = glossy_cone(mat.roughness);
        if (st.env_filter == EnvFilter::kOff) {
          // Point-sampled glossy lobe: one ray in the cone (the filtered path traces the mirror ray and
          // lets the summed-area table average the environment over the cone instead).
          const std::uint32_t gkey = hash_combine(path_key, static_cast<std::uint32_t>(SamplePurpose::kGlossy) << 8);
          Vec3 g = uniform_cone(r2_sample(gkey, 0), rdir, rcone);
          if (dot(g, ng) > 0.f) rdir = g;
        }
      }
      Ray rr;
      rr.origin = origin_out;
      rr.dir = rdir;
      HitInfo sec;
      const Vec3 c = trace(rr, rk, depth + 1, key, path * 3u + 1u, rcone, geom ? &sec : nullptr, nullptr);
      color += c * total_refl;
      if (geom) {
        geom->sec_object[0] = sec.object;
        geom->sec_normal[0] = sec.normal;
        geom->sec_shadow_bits |= sec.shadow_bits;
      }
    }
    if (do_refr && refr_weight > 0.f) {
      Ray tr;
      tr.origin = origin_in;
      tr.dir = refr_dir;
      HitInfo sec;
      const Vec3 c = trace(tr, RayKind::kRefraction, depth + 1, key, path * 3u + 2u, 0.f, geom ? &sec : nullptr,
                           nullptr);
      color += c * mat.base_color * refr_weight;
      if (geom) {
        geom->sec_object[1] = sec.object;
        geom->sec_normal[1] = sec.normal;
        geom->sec_shadow_bits |= sec.shadow_bits << 16 | sec.shadow_bits >> 16;
      }
    }
  }
  return color;
}

}  // namespace

TileContext::TileContext(const Scene& s, const RenderSettings& st, const Camera& c, const CacheConfig& cc)
    : scene(s), settings(st), camera(c), cache(cc) {
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
  out.color = shader.trace(ray, RayKind::kPrimary, 0, key, 1u, 0.f, &info, &out.geom);
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

void FrameBuffers::allocate(int w, int h) {
  width = w;
  height = h;
  const std::size_t n = static_cast<std::size_t>(w) * h;
  color.assign(n * 3, 0.f);
  depth.assign(n, kInf);
  normal.assign(n * 3, 0.f);
  position.assign(n * 3, 0.f);
  object.assign(n, -1);
  kind.assign(n, 0);
}

RenderOutput render_frame(const Scene& scene, const Camera& camera, const RenderSettings& settings, int threads,
                          const MultirateState* previous, const CacheConfig& cache) {
  settings.validate();
  camera.validate();
  cache.validate();
  RenderOutput out;
  const int ts = settings.tile_size;
  const int tx = (camera.width + ts - 1) / ts, ty = (camera.height + ts - 1) / ts;
  const int ntiles = tx * ty;
  out.fb.allocate(camera.width, camera.height);
  out.tiles.resize(ntiles);
  std::vector<Counters> tile_counters(ntiles);
  std::vector<ComparatorHistogram> tile_hist(ntiles);
  const bool use_prev = settings.multirate && settings.adaptive() && previous &&
                        previous->matches(tx, ty, ts, camera.width, camera.height);
  const int k = settings.subgrid();

  parallel_chunks(static_cast<std::size_t>(ntiles), threads, 1, [&](std::size_t begin, std::size_t end) {
    for (std::size_t t = begin; t < end; ++t) {
      const int x0 = static_cast<int>(t % tx) * ts, y0 = static_cast<int>(t / tx) * ts;
      const int w = std::min(ts, camera.width - x0), h = std::min(ts, camera.height - y0);
      int spacing = 1;
      if (settings.adaptive()) {
        spacing = settings.block;
        if (use_prev) spacing = multirate_block(previous->block[t], previous->ratio[t], previous->checks[t], settings);
      }
      TileContext ctx(scene, settings, camera, cache);
      TileStat& stat = out.tiles[t];
      render_tile(ctx, out.fb, x0, y0, w, h, k, spacing, &stat);
      ctx.counters.pixels += static_cast<std::uint64_t>(w) * h;
      ctx.counters.framebuffer_bytes += static_cast<std::uint64_t>(w) * h * kFramebufferPixelBytes;
      ctx.finish();
      stat.rays_total = ctx.counters.rays_total;
      stat.bvh_node_visits = ctx.counters.bvh_node_visits;
      stat.triangle_tests = ctx.counters.triangle_tests;
      stat.cache_misses = ctx.counters.cache_misses;
      tile_counters[t] = ctx.counters;
      tile_hist[t] = ctx.histogram;
    }
  });
  for (int t = 0; t < ntiles; ++t) {
    out.counters += tile_counters[t];
    for (std::size_t i = 0; i < out.histogram.size(); ++i) out.histogram[i] += tile_hist[t][i];
  }
  MultirateState& ms = out.multirate;
  ms.tiles_x = tx; ms.tiles_y = ty; ms.tile_size = ts; ms.width = camera.width; ms.height = camera.height;
  ms.block.resize(ntiles); ms.ratio.resize(ntiles); ms.checks.resize(ntiles);
  for (int t = 0; t < ntiles; ++t) {
    ms.block[t] = out.tiles[t].block;
    ms.ratio[t] = out.tiles[t].similarity_ratio;
    ms.checks[t] = out.tiles[t].similarity_checks;
  }
  return out;
}

}  // namespace sim_core
