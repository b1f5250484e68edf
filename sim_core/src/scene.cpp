#include "sim_core/scene.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

namespace sim_core {

namespace {

// Material table (at least one entry: the default material when none is given).
std::vector<Material> read_materials(const float* materials, std::size_t material_count) {
  std::vector<Material> out(std::max<std::size_t>(material_count, 1));
  for (std::size_t m = 0; m < material_count; ++m) {
    const float* f = materials + m * kMaterialFields;
    Material& mat = out[m];
    mat.base_color = {f[0], f[1], f[2]};
    mat.metallic = f[3]; mat.roughness = f[4]; mat.transmission = f[5]; mat.ior = f[6];
    mat.emission = {f[7], f[8], f[9]};
    for (int k = 0; k < kMaterialFields; ++k)
      if (!std::isfinite(f[k])) throw std::invalid_argument("material values must be finite");
    if (mat.ior < 1.f) throw std::invalid_argument("material ior must be >= 1");
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
    if (kind < 0 || kind > 2) throw std::invalid_argument("light kind must be 0 (point), 1 (spot) or 2 (sun)");
    Light& L = out[l];
    L.kind = static_cast<LightKind>(kind);
    L.position = {f[1], f[2], f[3]};
    L.direction = normalize(Vec3(f[4], f[5], f[6]));
    L.color = {f[7], f[8], f[9]};
    L.intensity = f[10]; L.radius = f[11]; L.spot_angle = f[12];
    if (length(Vec3(f[4], f[5], f[6])) == 0.f) throw std::invalid_argument("light direction must be non-zero");
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
             std::size_t material_count, const float* lights, std::size_t light_count, Environment env)
    : env_(std::move(env)) {
  if (triangle_count == 0) throw std::invalid_argument("scene has no triangles");
  if (vertex_count == 0) throw std::invalid_argument("scene has no vertices");
  if (light_count > static_cast<std::size_t>(kMaxLights))
    throw std::invalid_argument("at most " + std::to_string(kMaxLights) + " lights are supported");
  for (std::size_t i = 0; i < vertex_count * 3; ++i)
    if (!std::isfinite(positions[i])) throw std::invalid_argument("vertex positions must be finite");

  materials_ = read_materials(materials, material_count);
  for (const Material& m : materials_) {
    has_refraction_ |= m.refracts();
    has_reflection_ |= m.reflects();
    has_emission_ |= max_component(m.emission) > 0.f;
  }
  lights_ = read_lights(lights, light_count);
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

}  // namespace sim_core
