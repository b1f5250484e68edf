// nanobind module entry: each concept binds itself in <concept>_py.cpp (declarations only here), in the
// order the generated stub (_core.pyi) lists them.
#include <nanobind/nanobind.h>

#include "sim_core/version.h"

namespace nb = nanobind;

namespace sim_core {
void bind_texture(nb::module_& m);     // NativeTexture: a base-colour image with its mip pyramid
void bind_scene(nb::module_& m);       // NativeScene: construction, intersect, traversal statistics
void bind_settings(nb::module_& m);    // NativeRenderSettings
void bind_render(nb::module_& m);      // MultirateState, render_frame
void bind_stereo(nb::module_& m);      // render_stereo
void bind_cache(nb::module_& m);       // CacheConfig, CacheModel
void bind_comparator(nb::module_& m);  // COMPARATOR_BITS, comparator_chain_lengths
void bind_sat(nb::module_& m);         // SummedAreaTableF32 / F64
void bind_env_filter(nb::module_& m);  // EnvironmentFilter
void bind_streaming(nb::module_& m);   // traverse_rays: streaming against per-ray traversal
void bind_ssim(nb::module_& m);        // ssim_mean
}  // namespace sim_core

NB_MODULE(_core, m) {
  m.doc() = "render-budget native simulator core";
  m.attr("__version__") = sim_core::kVersion;
  sim_core::bind_texture(m);
  sim_core::bind_scene(m);
  sim_core::bind_settings(m);
  sim_core::bind_render(m);
  sim_core::bind_stereo(m);
  sim_core::bind_cache(m);
  sim_core::bind_comparator(m);
  sim_core::bind_sat(m);
  sim_core::bind_env_filter(m);
  sim_core::bind_streaming(m);
  sim_core::bind_ssim(m);
}
