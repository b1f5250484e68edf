// Bindings of the frame renderer: render_frame, its multi-rate state, and the conversions the stereo
// bindings share (render_py.h).
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/string.h>

#include <cstring>
#include <stdexcept>
#include <vector>

#include "render_py.h"
#include "sim_core/render.h"

namespace nb = nanobind;
using namespace nb::literals;

namespace sim_core {
namespace {

template <class T>
nb::object to_numpy(const std::vector<T>& v, std::initializer_list<std::size_t> shape) {
  T* data = new T[v.empty() ? 1 : v.size()];
  if (!v.empty()) std::memcpy(data, v.data(), v.size() * sizeof(T));
  nb::capsule owner(data, [](void* p) noexcept { delete[] static_cast<T*>(p); });
  return nb::cast(nb::ndarray<nb::numpy, T>(data, shape.size(), shape.begin(), owner));
}

}  // namespace

Camera camera_from_frame(CameraFrame frame, float vfov, int width, int height) {
  Camera c;
  c.position = Vec3(frame(0, 0), frame(0, 1), frame(0, 2));
  c.right = Vec3(frame(1, 0), frame(1, 1), frame(1, 2));
  c.up = Vec3(frame(2, 0), frame(2, 1), frame(2, 2));
  c.forward = Vec3(frame(3, 0), frame(3, 1), frame(3, 2));
  c.vfov = vfov;
  c.width = width;
  c.height = height;
  c.validate();
  return c;
}

TraceOptions trace_options(int bvh_width, bool log_rays) {
  TraceOptions t;
  t.bvh_width = bvh_width;
  t.log_rays = log_rays;
  t.validate();
  return t;
}

nb::dict render_output_dict(const RenderOutput& o, const TraceOptions& trace) {
  nb::dict d;
  const std::size_t h = static_cast<std::size_t>(o.fb.height), w = static_cast<std::size_t>(o.fb.width);
  d["image"] = to_numpy(o.fb.color, {h, w, 3});
  d["depth"] = to_numpy(o.fb.depth, {h, w});
  d["normal"] = to_numpy(o.fb.normal, {h, w, 3});
  d["position"] = to_numpy(o.fb.position, {h, w, 3});
  d["object_id"] = to_numpy(o.fb.object, {h, w});
  d["sample_kind"] = to_numpy(o.fb.kind, {h, w});
  nb::dict counters;
  o.counters.for_each([&](const char* name, std::uint64_t v) { counters[name] = v; });
  d["counters"] = counters;
  d["apron_rays"] = o.apron_rays;
  std::vector<std::uint64_t> hist(o.histogram.begin(), o.histogram.end());
  d["comparator_histogram"] = to_numpy(hist, {hist.size()});
  nb::list tiles;
  for (const TileStat& t : o.tiles) {
    nb::dict td;
    td["x0"] = t.x0; td["y0"] = t.y0; td["width"] = t.width; td["height"] = t.height;
    td["block"] = t.block;
    td["samples_traced"] = t.samples_traced;
    td["samples_interpolated"] = t.samples_interpolated;
    td["samples_reused"] = t.samples_reused;
    td["similarity_checks"] = t.similarity_checks;
    td["similarity_passed"] = t.similarity_passed;
    td["similarity_ratio"] = t.similarity_ratio;
    td["rays_total"] = t.rays_total;
    td["bvh_node_visits"] = t.bvh_node_visits;
    td["triangle_tests"] = t.triangle_tests;
    td["cache_misses"] = t.cache_misses;
    nb::dict tile_counters;
    t.counters.for_each([&](const char* name, std::uint64_t v) { tile_counters[name] = v; });
    td["counters"] = tile_counters;
    std::vector<std::uint64_t> tile_hist(t.histogram.begin(), t.histogram.end());
    td["comparator_histogram"] = to_numpy(tile_hist, {tile_hist.size()});
    tiles.append(td);
  }
  d["tile_stats"] = tiles;
  d["multirate_state"] = nb::cast(o.multirate);
  if (trace.log_rays) {
    const std::size_t n = o.rays.size();
    std::vector<float> origins(3 * n), directions(3 * n), tmax(n);
    std::vector<std::uint8_t> kind(n);
    for (std::size_t i = 0; i < n; ++i) {
      const Ray& r = o.rays[i].ray;
      origins[3 * i] = r.origin.x; origins[3 * i + 1] = r.origin.y; origins[3 * i + 2] = r.origin.z;
      directions[3 * i] = r.dir.x; directions[3 * i + 1] = r.dir.y; directions[3 * i + 2] = r.dir.z;
      tmax[i] = r.tmax;
      kind[i] = static_cast<std::uint8_t>(o.rays[i].kind);
    }
    nb::dict rays;
    rays["origins"] = to_numpy(origins, {n, 3});
    rays["directions"] = to_numpy(directions, {n, 3});
    rays["tmax"] = to_numpy(tmax, {n});
    rays["kind"] = to_numpy(kind, {n});
    d["rays"] = rays;
  }
  return d;
}

void bind_render(nb::module_& m) {
  nb::class_<MultirateState>(m, "MultirateState",
                             "Per-tile block sizes and similarity ratios of a frame; pass to the next frame.")
      .def_ro("tiles_x", &MultirateState::tiles_x)
      .def_ro("tiles_y", &MultirateState::tiles_y)
      .def_ro("tile_size", &MultirateState::tile_size)
      .def_ro("width", &MultirateState::width)
      .def_ro("height", &MultirateState::height)
      .def_prop_ro("block", [](const MultirateState& s) {
        return to_numpy(s.block, {static_cast<std::size_t>(s.tiles_y), static_cast<std::size_t>(s.tiles_x)});
      })
      .def_prop_ro("ratio", [](const MultirateState& s) {
        return to_numpy(s.ratio, {static_cast<std::size_t>(s.tiles_y), static_cast<std::size_t>(s.tiles_x)});
      });

  m.def(
      "render_frame",
      [](const Scene& scene, CameraFrame frame, float vfov, int width, int height, const RenderSettings& settings,
         int threads, const MultirateState* previous, std::uint32_t cache_size, std::uint32_t cache_line,
         std::uint32_t cache_ways, std::uint32_t texture_cache_size, std::uint32_t texture_cache_line,
         std::uint32_t texture_cache_ways, int bvh_width, bool log_rays, int crop_x, int crop_y, int full_width,
         int full_height) {
        Camera cam = camera_from_frame(frame, vfov, width, height);
        cam.crop_x = crop_x;
        cam.crop_y = crop_y;
        cam.full_width = full_width;
        cam.full_height = full_height;
        cam.validate();
        const TraceOptions trace = trace_options(bvh_width, log_rays);
        const CacheConfig cc{cache_size, cache_line, cache_ways};
        const CacheConfig tc{texture_cache_size, texture_cache_line, texture_cache_ways};
        RenderOutput out;
        {
          nb::gil_scoped_release release;
          out = render_frame(scene, cam, settings, threads, previous, cc, trace, tc);
        }
        return render_output_dict(out, trace);
      },
      "scene"_a, "frame"_a, "vfov"_a, "width"_a, "height"_a, "settings"_a, "threads"_a, "previous"_a.none(),
      "cache_size"_a, "cache_line"_a, "cache_ways"_a, "texture_cache_size"_a, "texture_cache_line"_a,
      "texture_cache_ways"_a, "bvh_width"_a = 4, "log_rays"_a = false, "crop_x"_a = 0, "crop_y"_a = 0,
      "full_width"_a = 0, "full_height"_a = 0,
      "Renders one frame, or the width x height window at (crop_x, crop_y) of a full_width x full_height\n"
      "frame. frame rows: position, right, up, forward (unit) of the camera. bvh_width 2: the binary\n"
      "reference walk; log_rays: also return every traced ray (\"rays\").");
  m.def("window_apron_pixels", &window_apron_pixels, "settings"_a, "ambient"_a,
        "Pixels beyond each edge of a window that render_frame traces for the resolve pass (0: none).");
}

}  // namespace sim_core
