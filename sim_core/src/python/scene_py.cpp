// Bindings of the native scene: construction from validated arrays and batched closest-hit queries.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/shared_ptr.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/unique_ptr.h>
#include <nanobind/stl/vector.h>

#include <memory>
#include <optional>
#include <stdexcept>
#include <vector>

#include "sim_core/scene.h"

namespace nb = nanobind;
using namespace nb::literals;

namespace sim_core {

template <class T, int C>
using Arr2 = nb::ndarray<const T, nb::shape<-1, C>, nb::c_contig, nb::device::cpu>;
template <class T>
using Arr1 = nb::ndarray<const T, nb::shape<-1>, nb::c_contig, nb::device::cpu>;

namespace {

std::unique_ptr<Scene> make_scene(Arr2<float, 3> positions, Arr2<std::uint32_t, 3> triangles,
                                  Arr1<std::int64_t> prim_ids, std::optional<Arr2<float, 3>> normals,
                                  Arr1<std::uint32_t> material_ids, Arr1<std::uint32_t> object_ids,
                                  Arr2<float, kMaterialFields> materials, Arr2<float, kLightFields> lights,
                                  Arr1<float> env_color,
                                  std::optional<nb::ndarray<const float, nb::shape<-1, -1, 3>, nb::c_contig,
                                                            nb::device::cpu>> env_map,
                                  std::optional<Arr2<float, 2>> uvs,
                                  std::vector<std::shared_ptr<Texture>> textures, float env_rotation) {
  const std::size_t t = triangles.shape(0);
  if (prim_ids.shape(0) != t || material_ids.shape(0) != t || object_ids.shape(0) != t)
    throw std::invalid_argument("prim_ids, material_ids and object_ids need one entry per triangle");
  if (normals && normals->shape(0) != positions.shape(0))
    throw std::invalid_argument("normals need one entry per vertex");
  if (uvs && uvs->shape(0) != positions.shape(0))
    throw std::invalid_argument("uvs need one entry per vertex");
  std::vector<std::shared_ptr<const Texture>> shared(textures.begin(), textures.end());
  if (env_color.shape(0) != 3) throw std::invalid_argument("environment colour needs 3 components");
  Environment env = env_map
      ? Environment(env_map->data(), static_cast<int>(env_map->shape(1)), static_cast<int>(env_map->shape(0)),
                    env_rotation)
      : Environment(Vec3(env_color(0), env_color(1), env_color(2)));
  nb::gil_scoped_release release;
  return std::make_unique<Scene>(positions.data(), positions.shape(0), triangles.data(), t, prim_ids.data(),
                                 normals ? normals->data() : nullptr, material_ids.data(), object_ids.data(),
                                 materials.data(), materials.shape(0), lights.data(), lights.shape(0),
                                 std::move(env), uvs ? uvs->data() : nullptr, std::move(shared));
}

// A new 1-D numpy array of n elements owned by Python (freed with its last reference), filled through data().
template <class T>
class NumpyVector {
 public:
  explicit NumpyVector(std::size_t n)
      : n_(n), data_(new T[n > 0 ? n : 1]), owner_(data_, [](void* p) noexcept { delete[] static_cast<T*>(p); }) {}
  T* data() { return data_; }
  nb::ndarray<nb::numpy, T, nb::ndim<1>> array() const { return {data_, {n_}, owner_}; }

 private:
  std::size_t n_;
  T* data_;
  nb::capsule owner_;
};

// Rows of a ray batch; checks that directions (and tmax, when given) match the origins.
std::size_t batch_size(const Arr2<float, 3>& origins, const Arr2<float, 3>& directions,
                       const std::optional<Arr1<float>>& tmax) {
  const std::size_t n = origins.shape(0);
  if (directions.shape(0) != n) throw std::invalid_argument("origins and directions differ in length");
  if (tmax && tmax->shape(0) != n) throw std::invalid_argument("tmax needs one entry per ray");
  return n;
}

}  // namespace

void bind_scene(nb::module_& m) {
  // The traffic model's record sizes (ARCHITECTURE.md, counter meanings).
  m.attr("BVH_NODE_BYTES") = sizeof(Bvh4Node);
  m.attr("BVH_NODE_BOXES") = kBoxesPerNodeStep;
  m.attr("TRIANGLE_RECORD_BYTES") = sizeof(TriRecord);
  nb::class_<Scene>(m, "NativeScene",
                    "Native scene (BVH + shading data). Build it through sim_core.Scene, which validates.")
      .def_static("build", &make_scene, "positions"_a, "triangles"_a, "prim_ids"_a, "normals"_a.none(),
                  "material_ids"_a, "object_ids"_a, "materials"_a, "lights"_a, "env_color"_a,
                  "env_map"_a.none(), "uvs"_a.none(), "textures"_a, "env_rotation"_a)
      .def(
          "intersect",
          [](const Scene& s, Arr2<float, 3> origins, Arr2<float, 3> directions, int threads, int bvh_width,
             std::optional<Arr1<float>> tmax) {
            const std::size_t n = batch_size(origins, directions, tmax);
            NumpyVector<float> t(n);
            NumpyVector<std::int64_t> prim(n);
            {
              nb::gil_scoped_release release;
              s.intersect_many(origins.data(), directions.data(), n, t.data(), prim.data(), threads, bvh_width,
                               tmax ? tmax->data() : nullptr);
            }
            return nb::make_tuple(t.array(), prim.array());
          },
          "origins"_a, "directions"_a, "threads"_a = 1, "bvh_width"_a = 4, "tmax"_a = nb::none(),
          "Closest hits (t, original prim id) within (0, tmax) (default +inf).")
      .def(
          "occluded",
          [](const Scene& s, Arr2<float, 3> origins, Arr2<float, 3> directions, int threads, int bvh_width,
             std::optional<Arr1<float>> tmax) {
            const std::size_t n = batch_size(origins, directions, tmax);
            NumpyVector<bool> hit(n);
            {
              nb::gil_scoped_release release;
              static_assert(sizeof(bool) == sizeof(std::uint8_t), "bool must be one byte");
              s.occluded_many(origins.data(), directions.data(), tmax ? tmax->data() : nullptr, n,
                              reinterpret_cast<std::uint8_t*>(hit.data()), threads, bvh_width);
            }
            return hit.array();
          },
          "origins"_a, "directions"_a, "threads"_a = 1, "bvh_width"_a = 4, "tmax"_a = nb::none(),
          "Any-hit (occlusion) queries within (0, tmax) (default +inf): True where something is hit.")
      .def(
          "traversal_stats",
          [](const Scene& s, Arr2<float, 3> origins, Arr2<float, 3> directions, const std::string& query,
             int bvh_width, std::optional<Arr1<float>> tmax) {
            if (query != "closest" && query != "any") throw std::invalid_argument("query must be 'closest' or 'any'");
            if (bvh_width != 2 && bvh_width != 4) throw std::invalid_argument("bvh_width must be 2 or 4");
            const std::size_t n = batch_size(origins, directions, tmax);
            struct Count {
              std::uint64_t nodes = 0, node_bytes = 0, tris = 0, cmps = 0, hits = 0;
              void node(std::uint32_t, std::uint32_t bytes) { ++nodes; node_bytes += bytes; }
              void tri(std::uint32_t) { ++tris; }
              void compare(float, float) { ++cmps; }
            } c;
            {
              nb::gil_scoped_release release;
              for (std::size_t i = 0; i < n; ++i) {
                Ray r;
                r.origin = Vec3(origins(i, 0), origins(i, 1), origins(i, 2));
                r.dir = Vec3(directions(i, 0), directions(i, 1), directions(i, 2));
                if (tmax) r.tmax = (*tmax)(i);
                const bool any = query == "any";
                const bool h = bvh_width == 4 ? (any ? s.occluded(r, c) : s.closest(r, c).hit())
                                              : (any ? s.occluded_binary(r, c) : s.closest_binary(r, c).hit());
                c.hits += h ? 1 : 0;
              }
            }
            nb::dict d;
            d["node_fetches"] = c.nodes;
            d["node_bytes"] = c.node_bytes;
            d["triangle_tests"] = c.tris;
            d["comparisons"] = c.cmps;
            d["hits"] = c.hits;
            return d;
          },
          "origins"_a, "directions"_a, "query"_a = "closest", "bvh_width"_a = 4, "tmax"_a = nb::none(),
          "What one query per ray reports to the traversal's recorder, summed: node_fetches, node_bytes, "
          "triangle_tests, comparisons (closest-hit distance comparisons), hits.")
      .def_prop_ro("triangle_count", &Scene::triangle_count)
      .def_prop_ro("has_textures", &Scene::has_textures, "Some material samples a base-colour texture.")
      .def_prop_ro("has_cutouts", &Scene::has_cutouts,
                   "Some material can be cut out by its alpha (its hits and shadow rays run alpha tests).")
      .def_prop_ro(
          "environment_lights",
          [](const Scene& s) {
            nb::list out;
            for (const Light& L : s.lights()) {
              if (!L.environment) continue;
              nb::dict d;
              d["direction"] = nb::make_tuple(-L.direction.x, -L.direction.y, -L.direction.z);
              d["irradiance"] = nb::make_tuple(L.color.x, L.color.y, L.color.z);
              d["angular_radius"] = L.radius;
              out.append(d);
            }
            return out;
          },
          "The environment map's suns the shader lights with (after the scene's lights, one shadow bit "
          "each): direction towards the sun, irradiance (W/m^2 per channel), angular radius (radians).")
      .def_prop_ro("bvh_node_count", [](const Scene& s) { return s.bvh().nodes.size(); })
      .def_prop_ro("bvh_depth", [](const Scene& s) { return s.bvh().depth; })
      .def_prop_ro("bvh_leaf_count", [](const Scene& s) { return s.bvh().leaf_count; })
      .def_prop_ro("bounds", [](const Scene& s) {
        const Vec3 lo = s.bounds_lo(), hi = s.bounds_hi();
        return nb::make_tuple(nb::make_tuple(lo.x, lo.y, lo.z), nb::make_tuple(hi.x, hi.y, hi.z));
      });
}

}  // namespace sim_core
