// Bindings of the glossy environment filter (summed-area tables over an equirectangular map).
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <stdexcept>

#include "sim_core/env_filter.h"

namespace nb = nanobind;
using namespace nb::literals;

namespace sim_core {

void bind_env_filter(nb::module_& m) {
  nb::class_<EnvironmentFilter>(m, "EnvironmentFilter")
      .def("__init__",
           [](EnvironmentFilter* self, nb::ndarray<const float, nb::ndim<3>, nb::c_contig, nb::device::cpu> rgb,
              int order, int table_bits) {
             if (rgb.shape(2) != 3) throw std::invalid_argument("environment map must be (H, W, 3) float32");
             new (self) EnvironmentFilter(rgb.data(), static_cast<int>(rgb.shape(1)),
                                                    static_cast<int>(rgb.shape(0)), order, table_bits);
           },
           "rgb"_a, "order"_a = 1, "table_bits"_a = 0)
      .def_prop_ro("table_bits", &EnvironmentFilter::table_bits)
      .def_prop_ro("width", &EnvironmentFilter::width)
      .def_prop_ro("height", &EnvironmentFilter::height)
      .def_prop_ro("order", &EnvironmentFilter::order)
      .def("lookup",
           [](const EnvironmentFilter& f, nb::ndarray<const float, nb::ndim<2>, nb::c_contig, nb::device::cpu> dirs,
              float cone_half_angle) {
             if (dirs.shape(1) != 3) throw std::invalid_argument("directions must be (N, 3) float32");
             const std::size_t n = dirs.shape(0);
             auto* out = new float[n * 3];
             nb::capsule owner(out, [](void* p) noexcept { delete[] static_cast<float*>(p); });
             const float* d = dirs.data();
             for (std::size_t i = 0; i < n; ++i) {
               const Vec3 v = f.lookup(Vec3(d[3 * i], d[3 * i + 1], d[3 * i + 2]), cone_half_angle);
               out[3 * i] = v.x; out[3 * i + 1] = v.y; out[3 * i + 2] = v.z;
             }
             return nb::ndarray<nb::numpy, float, nb::ndim<2>>(out, {n, 3}, owner);
           },
           "directions"_a, "cone_half_angle"_a,
           "Mean radiance over each direction's cone footprint (box or Bartlett, by the filter's order).");
  m.attr("ENV_FILTER_MAX_CONE_HALF_ANGLE") = EnvironmentFilter::kMaxConeHalfAngle;
}

}  // namespace sim_core
