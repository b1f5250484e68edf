// Bindings of the native scene: construction from validated arrays and batched closest-hit queries.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/unique_ptr.h>

#include <memory>
#include <optional>
#include <stdexcept>

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
                                                            nb::device::cpu>> env_map) {
  const std::size_t t = triangles.shape(0);
  if (prim_ids.shape(0) != t || material_ids.shape(0) != t || object_ids.shape(0) != t)
    throw std::invalid_argument("prim_ids, material_ids and object_ids need one entry per triangle");
  if (normals && normals->shape(0) != positions.shape(0))
    throw std::invalid_argument("normals need one entry per vertex");
  if (env_color.shape(0) != 3) throw std::invalid_argument("environment colour needs 3 components");
  Environment env = env_map
      ? Environment(env_map->data(), static_cast<int>(env_map->shape(1)), static_cast<int>(env_map->shape(0)))
      : Environment(Vec3(env_color(0), env_color(1), env_color(2)));
  nb::gil_scoped_release release;
  return std::make_unique<Scene>(positions.data(), positions.shape(0), triangles.data(), t, prim_ids.data(),
                                 normals ? normals->data() : nullptr, material_ids.data(), object_ids.data(),
                                 materials.data(), materials.shape(0), lights.data(), lights.shape(0),
                                 std::move(env));
}

}  // namespace

void bind_scene(nb::module_& m) {
  nb::class_<Scene>(m, "NativeScene",
                    "Native scene (BVH + shading data). Build it through sim_core.Scene, which validates.")
      .def_static("build", &make_scene, "positions"_a, "triangles"_a, "prim_ids"_a, "normals"_a.none(),
                  "material_ids"_a, "object_ids"_a, "materials"_a, "lights"_a, "env_color"_a,
                  "env_map"_a.none())
      .def(
          "intersect",
          [](const Scene& s, Arr2<float, 3> origins, Arr2<float, 3> directions, int threads, int bvh_width) {
            if (bvh_width != 2 && bvh_width != 4) throw std::invalid_argument("bvh_width must be 2 or 4");
            const std::size_t n = origins.shape(0);
            if (directions.shape(0) != n) throw std::invalid_argument("origins and directions differ in length");
            float* t = new float[n > 0 ? n : 1];
            std::int64_t* prim = new std::int64_t[n > 0 ? n : 1];
            nb::capsule t_owner(t, [](void* p) noexcept { delete[] static_cast<float*>(p); });
            nb::capsule p_owner(prim, [](void* p) noexcept { delete[] static_cast<std::int64_t*>(p); });
            {
              nb::gil_scoped_release release;
              s.intersect_many(origins.data(), directions.data(), n, t, prim, threads, bvh_width);
            }
            return nb::make_tuple(nb::ndarray<nb::numpy, float, nb::ndim<1>>(t, {n}, t_owner),
                                  nb::ndarray<nb::numpy, std::int64_t, nb::ndim<1>>(prim, {n}, p_owner));
          },
          "origins"_a, "directions"_a, "threads"_a = 1, "bvh_width"_a = 4)
      .def(
          "traversal_stats",
          [](const Scene& s, Arr2<float, 3> origins, Arr2<float, 3> directions) {
            struct Count {
              std::uint64_t nodes = 0, tris = 0, cmps = 0;
              void node(std::uint32_t) { ++nodes; }
              void tri(std::uint32_t) { ++tris; }
              void compare(float, float) { ++cmps; }
            } c;
            const std::size_t n = std::min(origins.shape(0), directions.shape(0));
            {
              nb::gil_scoped_release release;
              for (std::size_t i = 0; i < n; ++i) {
                Ray r;
                r.origin = Vec3(origins(i, 0), origins(i, 1), origins(i, 2));
                r.dir = Vec3(directions(i, 0), directions(i, 1), directions(i, 2));
                s.closest(r, c);
              }
            }
            return nb::make_tuple(c.nodes, c.tris, c.cmps);
          },
          "origins"_a, "directions"_a,
          "Totals of (node fetches, triangle tests, closest-hit comparisons) for closest-hit queries.")
      .def_prop_ro("triangle_count", &Scene::triangle_count)
      .def_prop_ro("bvh_node_count", [](const Scene& s) { return s.bvh().nodes.size(); })
      .def_prop_ro("bvh_depth", [](const Scene& s) { return s.bvh().depth; })
      .def_prop_ro("bvh_leaf_count", [](const Scene& s) { return s.bvh().leaf_count; })
      .def_prop_ro("bounds", [](const Scene& s) {
        const Vec3 lo = s.bounds_lo(), hi = s.bounds_hi();
        return nb::make_tuple(nb::make_tuple(lo.x, lo.y, lo.z), nb::make_tuple(hi.x, hi.y, hi.z));
      });
}

}  // namespace sim_core
