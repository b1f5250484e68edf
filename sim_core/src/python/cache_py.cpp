// Bindings of the cache model: CacheConfig (a hardware profile's node/triangle cache) and CacheModel.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>

#include "sim_core/cache.h"

namespace nb = nanobind;
using namespace nb::literals;

namespace sim_core {

void bind_cache(nb::module_& m) {
  nb::class_<CacheConfig>(m, "CacheConfig")
      .def("__init__",
           [](CacheConfig* self, std::uint32_t size_bytes, std::uint32_t line_bytes, std::uint32_t ways) {
             new (self) CacheConfig{size_bytes, line_bytes, ways};
             self->validate();
           },
           "size_bytes"_a, "line_bytes"_a = 64, "ways"_a = 4)
      .def_rw("size_bytes", &CacheConfig::size_bytes)
      .def_rw("line_bytes", &CacheConfig::line_bytes)
      .def_rw("ways", &CacheConfig::ways)
      .def("__repr__", [](const CacheConfig& c) {
        return "CacheConfig(size_bytes=" + std::to_string(c.size_bytes) + ", line_bytes=" +
               std::to_string(c.line_bytes) + ", ways=" + std::to_string(c.ways) + ")";
      });

  nb::class_<CacheModel>(m, "CacheModel")
      .def(nb::init<const CacheConfig&>(), "config"_a)
      .def("access", &CacheModel::access, "address"_a, "bytes"_a)
      .def("access_many",
           [](CacheModel& c, nb::ndarray<const std::uint64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu> addr,
              std::uint32_t bytes) {
             const std::uint64_t* a = addr.data();
             for (std::size_t i = 0; i < addr.shape(0); ++i) c.access(a[i], bytes);
           },
           "addresses"_a, "bytes"_a)
      .def("reset", &CacheModel::reset)
      .def_prop_ro("accesses", [](const CacheModel& c) { return c.stats().accesses; })
      .def_prop_ro("misses", [](const CacheModel& c) { return c.stats().misses; })
      .def_prop_ro("dram_bytes", [](const CacheModel& c) { return c.stats().dram_bytes; });
}

}  // namespace sim_core
