// Bindings of the compute-on-demand comparator: its width and the chain length of operand pairs.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <stdexcept>

#include "sim_core/comparator.h"

namespace nb = nanobind;
using namespace nb::literals;

namespace sim_core {

void bind_comparator(nb::module_& m) {
  m.attr("COMPARATOR_BITS") = kComparatorBits;
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
            out[i] = comparator_chain_length(a.data()[i], b.data()[i]);
          }
          return nb::ndarray<nb::numpy, std::int32_t, nb::ndim<1>>(out, {n}, owner);
        },
        "a"_a, "b"_a, "Compute-chain length of each pair of non-negative float operands (24-bit comparator).");
}

}  // namespace sim_core
