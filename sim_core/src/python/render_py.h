// What the render and stereo bindings share: the camera frame a call passes and a RenderOutput as the dict
// sim_core.render turns into a RenderResult.
#pragma once
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include "sim_core/camera.h"
#include "sim_core/render.h"

namespace sim_core {

// Rows: position, right, up, forward (unit) of the camera.
using CameraFrame = nanobind::ndarray<const float, nanobind::shape<4, 3>, nanobind::c_contig, nanobind::device::cpu>;

Camera camera_from_frame(CameraFrame frame, float vfov, int width, int height);  // validated
// With `trace.log_rays`, the dict also holds "rays": {origins (N, 3), directions (N, 3), tmax (N,), kind (N,)
// uint8 TracedKind}.
nanobind::dict render_output_dict(const RenderOutput& o, const TraceOptions& trace);
TraceOptions trace_options(int bvh_width, bool log_rays);  // validated

}  // namespace sim_core
