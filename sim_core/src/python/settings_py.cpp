// Bindings of the native render settings (built and validated through sim_core.RenderSettings).
#include <nanobind/nanobind.h>

#include "sim_core/settings.h"

namespace nb = nanobind;

namespace sim_core {

void bind_settings(nb::module_& m) {
  nb::class_<RenderSettings>(m, "NativeRenderSettings",
                             "Native render settings; build them through sim_core.RenderSettings.")
      .def(nb::init<>())
      .def_prop_rw("mode", [](const RenderSettings& s) { return static_cast<int>(s.mode); },
                   [](RenderSettings& s, int v) { s.mode = static_cast<SamplingMode>(v); })
      .def_rw("block", &RenderSettings::block)
      .def_rw("normal_threshold_deg", &RenderSettings::normal_threshold_deg)
      .def_rw("max_depth", &RenderSettings::max_depth)
      .def_rw("shadow_samples", &RenderSettings::shadow_samples)
      .def_rw("resolution_scale", &RenderSettings::resolution_scale)
      .def_prop_rw("env_filter", [](const RenderSettings& s) { return static_cast<int>(s.env_filter); },
                   [](RenderSettings& s, int v) { s.env_filter = static_cast<EnvFilter>(v); })
      .def_rw("ao_samples", &RenderSettings::ao_samples)
      .def_rw("ao_distance", &RenderSettings::ao_distance)
      .def_rw("multirate", &RenderSettings::multirate)
      .def_rw("multirate_low", &RenderSettings::multirate_low)
      .def_rw("multirate_high", &RenderSettings::multirate_high)
      .def_rw("tile_size", &RenderSettings::tile_size)
      .def("validate", &RenderSettings::validate);
}

}  // namespace sim_core
