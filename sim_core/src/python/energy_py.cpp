// Bindings: the cache model and the comparator chain length (the energy model's native pieces).
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>

#include <stdexcept>

#include "sim_core/cache.h"
#include "sim_core/comparator.h"

namespace nb = nanobind;
using namespace nb::literals;

void bind_energy(nb::module_& m) {
  nb::class_<sim_core::CacheConfig>(m, "CacheConfig")
      .def("__init__",
           [](sim_core::CacheConfig* self, std::uint32_t size_bytes, std::uint32_t line_bytes, std::uint32_t ways) {
             new (self) sim_core::CacheConfig{size_bytes, line_bytes, ways};
             self->validate();
           },
           "size_bytes"_a, "line_bytes"_a = 64, "ways"_a = 4)
      .def_rw("size_bytes", &sim_core::CacheConfig::size_bytes)
      .def_rw("line_bytes", &sim_core::CacheConfig::line_bytes)
      .def_rw("ways", &sim_core::CacheConfig::ways)
      .def("__repr__", [](const sim_core::CacheConfig& c) {
        return "CacheConfig(size_bytes=" + std::to_string(c.size_bytes) + ", line_bytes=" +
               std::to_string(c.line_bytes) + ", ways=" + std::to_string(c.ways) + ")";
      });

  nb::class_<sim_core::CacheModel>(m, "CacheModel")
      .def(nb::init<const sim_core::CacheConfig&>(), "config"_a)
      .def("access", &sim_core::CacheModel::access, "address"_a, "bytes"_a)
      .def("access_many",
           [](sim_core::CacheModel& c, nb::ndarray<const std::uint64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu> addr,
              std::uint32_t bytes) {
             const std::uint64_t* a = addr.data();
             for (std::size_t i = 0; i < addr.shape(0); ++i) c.access(a[i], bytes);
           },
           "addresses"_a, "bytes"_a)
      .def("reset", &sim_core::CacheModel::reset)
      .def_prop_ro("accesses", [](const sim_core::CacheModel& c) { return c.stats().accesses; })
      .def_prop_ro("misses", [](const sim_core::CacheModel& c) { return c.stats().misses; })
      .def_prop_ro("dram_bytes", [](const sim_core::CacheModel& c) { return c.stats().dram_bytes; });

  m.attr("COMPARATOR_BITS") = sim_core::kComparatorBits;
  m.def("comparator_chain_lengths",
        [](nb::ndarray<const float, nb::ndim<1>, nb::c_contig, nb::device::cpu> a,
           nb::ndarray<const float, nb::ndim<1>, nb::c_contig, nb::device::cpu> b) {
          if (a.shape(0) != b.shape(0)) throw std::invalid_argument("operand arrays differ in length");
          const std::size_t n = a.shape(0);
          auto* out = new std::int32_t[n];
          nb::capsule owner(out, [](void* p) noexcept { delete[] static_cast<std::int32_t*>(p); });
          for (std::size_t i = 0; i < n; ++i) {
            if (!(a.data()[i] >= 0.f) || !(b.data()[i] >= 0.f))
              throw std::invalid_argument("comparator operands must be non-negative and not NaN");
            out[i] = sim_core::comparator_chain_length(a.data()[i], b.data()[i]);
          }
          return nb::ndarray<nb::numpy, std::int32_t, nb::ndim<1>>(out, {n}, owner);
        },
        "a"_a, "b"_a, "Compute-chain length of each pair of non-negative float operands (24-bit comparator).");
}

void bind_sat(nb::module_& m);
void bind_streaming(nb::module_& m);

// Entry called from module.cpp: registers every binding of the energy-model part.
void bind_energy_model(nb::module_& m) {
  bind_energy(m);
  bind_sat(m);
  bind_streaming(m);
}
