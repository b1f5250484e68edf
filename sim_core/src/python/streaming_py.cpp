// Bindings: streaming against per-ray traversal of one batch of rays, with memory-traffic counters.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/tuple.h>

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "sim_core/streaming.h"

namespace nb = nanobind;
using namespace nb::literals;

namespace sim_core {
namespace {

using Rays = nb::ndarray<const float, nb::shape<-1, 3>, nb::c_contig, nb::device::cpu>;

nb::dict traffic_dict(const TraversalTraffic& t) {
  nb::dict d;
  d["rays"] = t.rays;
  d["node_fetches"] = t.node_fetches;
  d["triangle_fetches"] = t.triangle_fetches;
  d["node_bytes"] = t.node_bytes;
  d["triangle_bytes"] = t.triangle_bytes;
  d["scene_dram_bytes"] = t.scene_dram_bytes;
  d["box_tests"] = t.box_tests;
  d["triangle_tests"] = t.triangle_tests;
  d["stream_elements_read"] = t.stream_elements_read;
  d["stream_elements_written"] = t.stream_elements_written;
  d["stream_bytes"] = t.stream_bytes;
  d["interior_streams"] = t.interior_streams;
  d["leaf_streams"] = t.leaf_streams;
  d["interior_stream_rays"] = t.interior_stream_rays;
  d["leaf_stream_rays"] = t.leaf_stream_rays;
  d["culled_at_pop"] = t.culled_at_pop;
  nb::list all, finite;
  for (std::size_t i = 0; i < t.compare_all.size(); ++i) {
    all.append(t.compare_all[i]);
    finite.append(t.compare_finite[i]);
  }
  d["compare_all"] = all;
  d["compare_finite"] = finite;
  return d;
}

}  // namespace

void bind_streaming(nb::module_& m) {
  m.def(
      "traverse_rays",
      [](const Scene& scene, Rays origins, Rays directions, const std::string& mode,
         std::uint32_t cache_size, std::uint32_t cache_line, std::uint32_t cache_ways, std::size_t group_size) {
        const std::size_t n = origins.shape(0);
        if (directions.shape(0) != n) throw std::invalid_argument("origins and directions differ in length");
        std::vector<Ray> rays(n);
        const float* o = origins.data();
        const float* d = directions.data();
        for (std::size_t i = 0; i < n; ++i) {
          rays[i].origin = Vec3(o[3 * i], o[3 * i + 1], o[3 * i + 2]);
          rays[i].dir = Vec3(d[3 * i], d[3 * i + 1], d[3 * i + 2]);
          if (!is_finite(rays[i].origin) || !is_finite(rays[i].dir) ||
              dot(rays[i].dir, rays[i].dir) == 0.f)
            throw std::invalid_argument("ray " + std::to_string(i) + " has a non-finite origin or a bad direction");
        }
        std::vector<Hit> hits(n);
        TraversalTraffic t;
        {
          nb::gil_scoped_release release;
          if (mode == "streaming") {
            t = streaming_traversal(scene, rays.data(), n, hits.data());
          } else if (mode == "per_ray") {
            const CacheConfig cfg{cache_size, cache_line, cache_ways};
            cfg.validate();
            t = per_ray_traversal(scene, rays.data(), n, hits.data(), cfg, group_size);
          } else {
            throw std::invalid_argument("mode must be 'streaming' or 'per_ray'");
          }
        }
        auto* tout = new float[n];
        auto* pout = new std::int64_t[n];
        nb::capsule ot(tout, [](void* p) noexcept { delete[] static_cast<float*>(p); });
        nb::capsule op(pout, [](void* p) noexcept { delete[] static_cast<std::int64_t*>(p); });
        for (std::size_t i = 0; i < n; ++i) {
          tout[i] = hits[i].t;
          pout[i] = hits[i].hit() ? static_cast<std::int64_t>(scene.tri(hits[i].tri).prim) : -1;
        }
        return nb::make_tuple(nb::ndarray<nb::numpy, float, nb::ndim<1>>(tout, {n}, ot),
                              nb::ndarray<nb::numpy, std::int64_t, nb::ndim<1>>(pout, {n}, op), traffic_dict(t));
      },
      "scene"_a, "origins"_a, "directions"_a, "mode"_a = "streaming", "cache_size"_a = 0, "cache_line"_a = 64,
      "cache_ways"_a = 4, "group_size"_a = 0,
      "Closest hits of a ray batch by streaming or per-ray traversal, with fetch and byte counters.");
}

}  // namespace sim_core
