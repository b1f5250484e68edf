// Bindings of stereo rendering by reprojection: render_stereo.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include "render_py.h"
#include "sim_core/stereo.h"

namespace nb = nanobind;
using namespace nb::literals;

namespace sim_core {

void bind_stereo(nb::module_& m) {
  m.def(
      "render_stereo",
      [](const Scene& scene, CameraFrame left, CameraFrame right, float vfov, int width, int height,
         const RenderSettings& settings, int threads, const MultirateState* previous, std::uint32_t cache_size,
         std::uint32_t cache_line, std::uint32_t cache_ways, std::uint32_t texture_cache_size,
         std::uint32_t texture_cache_line, std::uint32_t texture_cache_ways, int bvh_width, bool log_rays) {
        const Camera cl = camera_from_frame(left, vfov, width, height);
        const Camera cr = camera_from_frame(right, vfov, width, height);
        const CacheConfig cc{cache_size, cache_line, cache_ways};
        const CacheConfig tc{texture_cache_size, texture_cache_line, texture_cache_ways};
        const TraceOptions trace = trace_options(bvh_width, log_rays);
        StereoOutput out;
        {
          nb::gil_scoped_release release;
          out = render_stereo(scene, cl, cr, settings, threads, previous, cc, trace, tc);
        }
        nb::dict d;
        d["left"] = render_output_dict(out.left, trace);
        d["right"] = render_output_dict(out.right, trace);
        d["reuse_ratio"] = out.reuse_ratio;
        d["holes"] = out.holes;
        d["silhouettes"] = out.silhouettes;
        d["depth_mismatches"] = out.depth_mismatches;
        return d;
      },
      "scene"_a, "left"_a, "right"_a, "vfov"_a, "width"_a, "height"_a, "settings"_a, "threads"_a,
      "previous"_a.none(), "cache_size"_a, "cache_line"_a, "cache_ways"_a, "texture_cache_size"_a,
      "texture_cache_line"_a, "texture_cache_ways"_a, "bvh_width"_a = 4, "log_rays"_a = false,
      "Renders the left eye, reprojects it into the right eye and traces only the bad pixels.");
}

}  // namespace sim_core
