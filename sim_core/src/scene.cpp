#include "sim_core/scene.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

namespace sim_core {

namespace {

// Material table (at least one entry: the default material when none is given).
std::vector<Material> read_materials(const float* materials, std::size_t material_count, std::size_t texture_count) {
  std::vector<Material> out(std::max<std::size_t>(material_count, 1));
  for (std::size_t m = 0; m < material_count; ++m) {
    const float* f = materials + m * kMaterialFields;
    for (int k = 0; k < kMaterialFields; ++k)
      if (!std::isfinite(f[k])) throw std::invalid_argument("material values must be finite");
    Material& mat = out[m];
    mat.base_color = {f[0], f[1], f[2]};
    mat.metallic = f[3]; mat.roughness = f[4]; mat.transmission = f[5]; mat.ior = f[6];
    mat.emission = {f[7], f[8], f[9]};
    mat.alpha = f[10];
    const int mode = static_cast<int>(f[11]);
    if (mode < 0 || mode > 2 || static_cast<float>(mode) != f[11])
      throw std::invalid_argument("material alpha mode must be 0 (opaque), 1 (clip) or 2 (hashed)");
    mat.alpha_mode = static_cast<AlphaMode>(mode);
    mat.alpha_cutoff = f[12];
    const float tex = f[13];
    if (tex != std::floor(tex) || tex < -1.f || tex >= static_cast<float>(texture_count))
      throw std::invalid_argument("material texture index out of range");
    mat.base_color_texture = static_cast<std::int32_t>(tex);
    if (mat.ior < 1.f) throw std::invalid_argument("material ior must be >= 1");
    if (mat.alpha < 0.f || mat.alpha > 1.f) throw std::invalid_argument("material alpha must be in [0, 1]");
  }
  return out;
}

std::vector<Light> read_lights(const float* lights, std::size_t light_count) {
  std::vector<Light> out(light_count);
  for (std::size_t l = 0; l < light_count; ++l) {
    const float* f = lights + l * kLightFields;
    for (int k = 0; k < kLightFields; ++k)
      if (!std::isfinite(f[k])) throw std::invalid_argument("light values must be finite");
    const int kind = static_cast<int>(f[0]);
    if (kind < 0 || kind > 3 || static_cast<float>(kind) != f[0])
      throw std::invalid_argument("light kind must be 0 (point), 1 (spot), 2 (sun) or 3 (area)");
    Light& L = out[l];
    L.kind = static_cast<LightKind>(kind);
    L.position = {f[1], f[2], f[3]};
    if (length(Vec3(f[4], f[5], f[6])) == 0.f) throw std::invalid_argument("light direction must be non-zero");
    L.direction = normalize(Vec3(f[4], f[5], f[6]));
    L.color = {f[7], f[8], f[9]};
    L.intensity = f[10]; L.radius = f[11]; L.spot_angle = f[12]; L.spot_blend = f[13];
    if (L.intensity < 0.f || L.radius < 0.f || L.spot_angle < 0.f || L.spot_blend < 0.f)
      throw std::invalid_argument("light intensity, radius, spot angle and blend must be >= 0");
    if (L.kind != LightKind::kArea) continue;
    const int shape = static_cast<int>(f[14]);
    if (shape < 0 || shape > 1 || static_cast<float>(shape) != f[14])
      throw std::invalid_argument("area light shape must be 0 (rectangle) or 1 (ellipse)");
    L.shape = static_cast<AreaShape>(shape);
    L.size_u = f[15]; L.size_v = f[16];
    if (!(L.size_u > 0.f && L.size_v > 0.f))
      throw std::invalid_argument("area light sizes must be > 0 (a zero-size area light emits from no surface)");
    // Local X orthogonalised against the emitting direction; local Y completes the frame.
    const Vec3 u(f[17], f[18], f[19]);
    const Vec3 ortho = u - L.direction * dot(u, L.direction);
    if (!(length(ortho) > 1e-6f * std::max(length(u), 1e-30f)))
      throw std::invalid_argument("area light axis_u must be non-zero and not parallel to its direction");
    L.axis_u = normalize(ortho);
    L.axis_v = cross(L.axis_u, L.direction);
  }
  return out;
}

// Triangle records in input order, and the bounds of their vertices.
std::vector<TriRecord> read_triangles(const float* positions, std::size_t vertex_count,
                                      const std::uint32_t* triangles, std::size_t triangle_count,
                                      const std::int64_t* prim_ids, const std::uint32_t* material_ids,
                                      const std::uint32_t* object_ids, std::size_t material_table_size, Vec3* lo,
                                      Vec3* hi) {
  std::vector<TriRecord> recs(triangle_count);
  *lo = Vec3(kInf, kInf, kInf);
  *hi = Vec3(-kInf, -kInf, -kInf);
  for (std::size_t i = 0; i < triangle_count; ++i) {
    TriRecord& r = recs[i];
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t vi = triangles[3 * i + k];
      if (vi >= vertex_count) throw std::invalid_argument("triangle index out of range");
      for (int c = 0; c < 3; ++c) r.v[3 * k + c] = positions[3 * vi + c];
      const Vec3 p(r.v[3 * k], r.v[3 * k + 1], r.v[3 * k + 2]);
      *lo = vmin(*lo, p); *hi = vmax(*hi, p);
    }
    r.prim = static_cast<std::uint32_t>(prim_ids ? prim_ids[i] : static_cast<std::int64_t>(i));
    r.material = material_ids ? material_ids[i] : 0u;
    r.object = object_ids ? object_ids[i] : 0u;
    if (r.material >= material_table_size) throw std::invalid_argument("material id out of range");
  }
  return recs;
}

}  // namespace

Scene::Scene(const float* positions, std::size_t vertex_count, const std::uint32_t* triangles,
             std::size_t triangle_count, const std::int64_t* prim_ids, const float* normals,
             const std::uint32_t* material_ids, const std::uint32_t* object_ids, const float* materials,
             std::size_t material_count, const float* lights, std::size_t light_count, Environment env,
             const float* uvs, std::vector<std::shared_ptr<const Texture>> textures)
    : textures_(std::move(textures)), env_(std::move(env)) {
  if (triangle_count == 0) throw std::invalid_argument("scene has no triangles");
  if (vertex_count == 0) throw std::invalid_argument("scene has no vertices");
  if (light_count > static_cast<std::size_t>(kMaxLights))
    throw std::invalid_argument("at most " + std::to_string(kMaxLights) + " lights are supported");
  for (std::size_t i = 0; i < vertex_count * 3; ++i)
    if (!std::isfinite(positions[i])) throw std::invalid_argument("vertex positions must be finite");

  for (const auto& t : textures_)
    if (!t) throw std::invalid_argument("texture list holds a null texture");
  std::uint64_t base = 0;
  for (const auto& t : textures_) {
    texture_bases_.push_back(base);
    base += (t->byte_size() + 4095u) / 4096u * 4096u;  // page-aligned, one after another
  }
  if (uvs)
    for (std::size_t i = 0; i < vertex_count * 2; ++i)
      if (!std::isfinite(uvs[i])) throw std::invalid_argument("texture coordinates must be finite");
  materials_ = read_materials(materials, material_count, textures_.size());
  for (Material& m : materials_) {
    has_refraction_ |= m.refracts();
    has_reflection_ |= m.reflects();
    has_emission_ |= max_component(m.emission) > 0.f;
    has_textures_ |= m.base_color_texture >= 0;
    // Model only what a scene needs: a cut-out material whose alpha can never drop below the threshold
    // (opaque texture, alpha 1) costs no alpha tests.
    const bool texture_alpha = m.base_color_texture >= 0 && texture(m.base_color_texture).has_alpha();
    if (m.alpha_mode == AlphaMode::kClip) m.cuts_out = m.alpha < m.alpha_cutoff || texture_alpha;
    if (m.alpha_mode == AlphaMode::kHashed) m.cuts_out = m.alpha < 1.f || texture_alpha;
    has_cutouts_ |= m.cuts_out;
  }
  lights_ = read_lights(lights, light_count);
  for (const EnvironmentLight& e : env_.lights()) {
    if (lights_.size() >= static_cast<std::size_t>(kMaxLights)) break;
    Light sun;
    sun.kind = LightKind::kSun;
    sun.direction = -e.direction;
    sun.color = e.irradiance;
    sun.intensity = 1.f;
    sun.radius = e.angular_radius;
    sun.environment = true;
    lights_.push_back(sun);
  }
  std::vector<TriRecord> recs = read_triangles(positions, vertex_count, triangles, triangle_count, prim_ids,
                                               material_ids, object_ids, materials_.size(), &lo_, &hi_);
  std::vector<std::uint32_t> order;
  bvh_ = build_bvh(recs, &order);
  tris_ = std::move(recs);
  bvh4_ = collapse_bvh4(bvh_, tris_);
  // Shading normals in leaf order (unit; the geometric normal where a vertex normal is missing or zero).
  shading_.resize(triangle_count);
  for (std::size_t i = 0; i < triangle_count; ++i) {
    const std::size_t src = order[i];
    TriShading& s = shading_[i];
    const Vec3 ng = geometric_normal(static_cast<std::uint32_t>(i));
    s.ng = ng;
    for (int k = 0; k < 3; ++k) {
      if (normals) {
        const std::uint32_t vi = triangles[3 * src + k];
        Vec3 n(normals[3 * vi], normals[3 * vi + 1], normals[3 * vi + 2]);
        const float len = length(n);
        s.n[k] = (std::isfinite(len) && len > 0.f) ? n / len : ng;
      } else {
        s.n[k] = ng;
      }
    }
  }
  if (uvs) {
    texcoords_.resize(triangle_count);
    for (std::size_t i = 0; i < triangle_count; ++i) {
      const std::size_t src = order[i];
      TriTexcoord& tc = texcoords_[i];
      for (int k = 0; k < 3; ++k) {
        const std::uint32_t vi = triangles[3 * src + k];
        tc.uv[2 * k] = uvs[2 * vi];
        tc.uv[2 * k + 1] = uvs[2 * vi + 1];
      }
      // Areas in double (small triangles far from the origin); a zero UV area gives -inf (finest level).
      const double du1 = double(tc.uv[2]) - tc.uv[0], dv1 = double(tc.uv[3]) - tc.uv[1];
      const double du2 = double(tc.uv[4]) - tc.uv[0], dv2 = double(tc.uv[5]) - tc.uv[1];
      const double uv_area = std::fabs(du1 * dv2 - du2 * dv1);
      const float* v = tris_[i].v;
      const double e1[3] = {double(v[3]) - v[0], double(v[4]) - v[1], double(v[5]) - v[2]};
      const double e2[3] = {double(v[6]) - v[0], double(v[7]) - v[1], double(v[8]) - v[2]};
      const double cx = e1[1] * e2[2] - e1[2] * e2[1], cy = e1[2] * e2[0] - e1[0] * e2[2],
                   cz = e1[0] * e2[1] - e1[1] * e2[0];
      const double world_area = std::sqrt(cx * cx + cy * cy + cz * cz);
      tc.lod_bias = static_cast<float>(0.5 * std::log2(uv_area / world_area));
    }
  }
}

void Scene::uv_at(std::uint32_t i, float b0, float b1, float b2, float* u, float* v) const {
  if (texcoords_.empty()) { *u = 0.f; *v = 0.f; return; }
  const float* t = texcoords_[i].uv;
  *u = t[0] * b0 + t[2] * b1 + t[4] * b2;
  *v = t[1] * b0 + t[3] * b1 + t[5] * b2;
}

Vec3 Scene::geometric_normal(std::uint32_t i) const {
  const float* v = tris_[i].v;
  const Vec3 a(v[0], v[1], v[2]), b(v[3], v[4], v[5]), c(v[6], v[7], v[8]);
  // Edges in double: far from the origin float edges of small triangles lose most of their bits.
  const double e1[3] = {double(b.x) - a.x, double(b.y) - a.y, double(b.z) - a.z};
  const double e2[3] = {double(c.x) - a.x, double(c.y) - a.y, double(c.z) - a.z};
  double n[3] = {e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]};
  const double len = std::sqrt(n[0] * n[0] + n[1] * n[1] + n[2] * n[2]);
  if (!(len > 0.0)) return Vec3(0.f, 0.f, 1.f);
  return Vec3(static_cast<float>(n[0] / len), static_cast<float>(n[1] / len), static_cast<float>(n[2] / len));
}

namespace {

// Ray i of a batch; false when it cannot be traced (non-finite, zero direction, NaN or negative tmax).
bool batch_ray(const float* origins, const float* directions, const float* tmax, std::size_t i, Ray* r) {
  r->origin = Vec3(origins[3 * i], origins[3 * i + 1], origins[3 * i + 2]);
  r->dir = Vec3(directions[3 * i], directions[3 * i + 1], directions[3 * i + 2]);
  r->tmax = tmax ? tmax[i] : kInf;
  return is_finite(r->origin) && is_finite(r->dir) && dot(r->dir, r->dir) != 0.f && r->tmax >= 0.f;
}

void check_width(int bvh_width) {
  if (bvh_width != 2 && bvh_width != 4) throw std::invalid_argument("bvh_width must be 2 or 4");
}

}  // namespace

void Scene::intersect_many(const float* origins, const float* directions, std::size_t n, float* t_out,
                           std::int64_t* prim_out, int threads, int bvh_width, const float* tmax) const {
  check_width(bvh_width);
  parallel_chunks(n, threads, 4096, [&](std::size_t begin, std::size_t end) {
    for (std::size_t i = begin; i < end; ++i) {
      Ray r;
      if (!batch_ray(origins, directions, tmax, i, &r)) {
        t_out[i] = kInf;
        prim_out[i] = -1;
        continue;
      }
      const Hit h = bvh_width == 4 ? closest(r) : closest_binary(r);
      t_out[i] = h.t;
      prim_out[i] = h.hit() ? static_cast<std::int64_t>(tris_[h.tri].prim) : -1;
    }
  });
}

void Scene::occluded_many(const float* origins, const float* directions, const float* tmax, std::size_t n,
                          std::uint8_t* occluded_out, int threads, int bvh_width) const {
  check_width(bvh_width);
  parallel_chunks(n, threads, 4096, [&](std::size_t begin, std::size_t end) {
    NullRecorder rec;
    for (std::size_t i = begin; i < end; ++i) {
      Ray r;
      occluded_out[i] = batch_ray(origins, directions, tmax, i, &r) &&
                        (bvh_width == 4 ? occluded(r, rec) : occluded_binary(r, rec));
    }
  });
}

std::size_t Scene::environment_light_count() const {
  std::size_t n = 0;
  for (const Light& L : lights_) n += L.environment ? 1u : 0u;
  return n;
}

}  // namespace sim_core
