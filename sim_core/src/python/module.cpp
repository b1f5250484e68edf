// nanobind module entry: each concept registers its own bindings (declarations only).
#include <nanobind/nanobind.h>

#include "sim_core/version.h"

namespace nb = nanobind;

NB_MODULE(_core, m) {
  m.doc() = "render-budget native simulator core";
  m.attr("__version__") = sim_core::kVersion;
}
