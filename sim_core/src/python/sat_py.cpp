// Bindings: summed-area tables (float32 and float64 reference) and the glossy environment filter.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <cmath>
#include <stdexcept>
#include <string>

#include "sim_core/env_filter.h"
#include "sim_core/sat.h"

namespace nb = nanobind;
using namespace nb::literals;

namespace {

using Image = nb::ndarray<const float, nb::c_contig, nb::device::cpu>;
using IntRows = nb::ndarray<const std::int64_t, nb::ndim<2>, nb::c_contig, nb::device::cpu>;

void image_shape(const Image& img, int* w, int* h, int* c) {
  if (img.ndim() == 2) { *h = static_cast<int>(img.shape(0)); *w = static_cast<int>(img.shape(1)); *c = 1; }
  else if (img.ndim() == 3) {
    *h = static_cast<int>(img.shape(0)); *w = static_cast<int>(img.shape(1)); *c = static_cast<int>(img.shape(2));
  } else {
    throw std::invalid_argument("image must be (H, W) or (H, W, C) float32");
  }
}

template <typename T>
void bind_table(nb::module_& m, const char* name) {
  using Table = sim_core::SummedAreaTable<T>;
  nb::class_<Table>(m, name)
      .def("__init__",
           [](Table* self, Image img, int order, bool offset) {
             int w = 0, h = 0, c = 0;
             image_shape(img, &w, &h, &c);
             new (self) Table(img.data(), w, h, c, order, offset);
           },
           "image"_a, "order"_a = 1, "offset"_a = true)
      .def_prop_ro("width", &Table::width)
      .def_prop_ro("height", &Table::height)
      .def_prop_ro("channels", &Table::channels)
      .def_prop_ro("order", &Table::order)
      .def_prop_ro("offset", &Table::offset)
      .def("max_abs", &Table::max_abs)
      .def_prop_ro("size_bytes", &Table::size_bytes)
      .def("box_sums",
           [](const Table& t, IntRows rects) {
             if (rects.shape(1) != 4) throw std::invalid_argument("rects must be (N, 4): x0, y0, x1, y1");
             const std::size_t n = rects.shape(0);
             const int c = t.channels();
             auto* out = new double[n * c];
             nb::capsule owner(out, [](void* p) noexcept { delete[] static_cast<double*>(p); });
             const std::int64_t* r = rects.data();
             for (std::size_t i = 0; i < n; ++i)
               t.box_sum(static_cast<int>(r[4 * i]), static_cast<int>(r[4 * i + 1]), static_cast<int>(r[4 * i + 2]),
                         static_cast<int>(r[4 * i + 3]), out + i * c);
             return nb::ndarray<nb::numpy, double, nb::ndim<2>>(out, {n, static_cast<std::size_t>(c)}, owner);
           },
           "rects"_a, "Sums of the original image over [x0, x1) x [y0, y1) for each row (first-order table).")
      .def("bartlett_sums",
           [](const Table& t, IntRows rows) {
             if (rows.shape(1) != 4) throw std::invalid_argument("rows must be (N, 4): cx, cy, rx, ry");
             const std::size_t n = rows.shape(0);
             const int c = t.channels();
             auto* out = new double[n * c];
             nb::capsule owner(out, [](void* p) noexcept { delete[] static_cast<double*>(p); });
             const std::int64_t* r = rows.data();
             for (std::size_t i = 0; i < n; ++i)
               t.bartlett_sum(static_cast<int>(r[4 * i]), static_cast<int>(r[4 * i + 1]), static_cast<int>(r[4 * i + 2]),
                              static_cast<int>(r[4 * i + 3]), out + i * c);
             return nb::ndarray<nb::numpy, double, nb::ndim<2>>(out, {n, static_cast<std::size_t>(c)}, owner);
           },
           "rows"_a,
           "Triangle-weighted sums (weights (rx-|dx|)(ry-|dy|)) of the original image (second-order table).");
}

}  // namespace

void bind_sat(nb::module_& m) {
  bind_table<float>(m, "SummedAreaTableF32");
  bind_table<double>(m, "SummedAreaTableF64");

  nb::class_<sim_core::EnvironmentFilter>(m, "EnvironmentFilter")
      .def("__init__",
           [](sim_core::EnvironmentFilter* self, nb::ndarray<const float, nb::ndim<3>, nb::c_contig, nb::device::cpu> rgb,
              int order, int table_bits) {
             if (rgb.shape(2) != 3) throw std::invalid_argument("environment map must be (H, W, 3) float32");
             new (self) sim_core::EnvironmentFilter(rgb.data(), static_cast<int>(rgb.shape(1)),
                                                    static_cast<int>(rgb.shape(0)), order, table_bits);
           },
           "rgb"_a, "order"_a = 1, "table_bits"_a = 0)
      .def_prop_ro("table_bits", &sim_core::EnvironmentFilter::table_bits)
      .def_prop_ro("width", &sim_core::EnvironmentFilter::width)
      .def_prop_ro("height", &sim_core::EnvironmentFilter::height)
      .def_prop_ro("order", &sim_core::EnvironmentFilter::order)
      .def("lookup",
           [](const sim_core::EnvironmentFilter& f, nb::ndarray<const float, nb::ndim<2>, nb::c_contig, nb::device::cpu> dirs,
              float cone_half_angle) {
             if (dirs.shape(1) != 3) throw std::invalid_argument("directions must be (N, 3) float32");
             const std::size_t n = dirs.shape(0);
             auto* out = new float[n * 3];
             nb::capsule owner(out, [](void* p) noexcept { delete[] static_cast<float*>(p); });
             const float* d = dirs.data();
             for (std::size_t i = 0; i < n; ++i) {
               const sim_core::Vec3 v = f.lookup(sim_core::Vec3(d[3 * i], d[3 * i + 1], d[3 * i + 2]), cone_half_angle);
               out[3 * i] = v.x; out[3 * i + 1] = v.y; out[3 * i + 2] = v.z;
             }
             return nb::ndarray<nb::numpy, float, nb::ndim<2>>(out, {n, 3}, owner);
           },
           "directions"_a, "cone_half_angle"_a,
           "Mean radiance over each direction's cone footprint (box or Bartlett, by the filter's order).");
  m.attr("ENV_FILTER_MAX_CONE_HALF_ANGLE") = sim_core::EnvironmentFilter::kMaxConeHalfAngle;
}
