// nanobind module entry: each concept registers its own bindings (declarations only).
#include <nanobind/nanobind.h>

#include "sim_core/version.h"

namespace nb = nanobind;

namespace sim_core {
void register_scene(nb::module_& m);
void register_render(nb::module_& m);
}  // namespace sim_core
void bind_energy_model(nb::module_& m);  // energy model part: cache model, comparator, SAT
void bind_ssim(nb::module_& m);          // image metric: SSIM as scikit-image

NB_MODULE(_core, m) {
  m.doc() = "render-budget native simulator core";
  m.attr("__version__") = sim_core::kVersion;
  sim_core::register_scene(m);
  sim_core::register_render(m);
  bind_energy_model(m);
  bind_ssim(m);
}
