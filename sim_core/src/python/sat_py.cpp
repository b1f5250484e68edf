// Bindings of the summed-area tables: float32 (the hardware's) and float64 (the reference).
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <stdexcept>
#include <string>

#include "sim_core/sat.h"

namespace nb = nanobind;
using namespace nb::literals;

namespace sim_core {
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
void def_table_class(nb::module_& m, const char* name) {
  using Table = SummedAreaTable<T>;
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
  def_table_class<float>(m, "SummedAreaTableF32");
  def_table_class<double>(m, "SummedAreaTableF64");
}

}  // namespace sim_core
