// Stereo by reprojection: two coincident eyes reuse every pixel and see the same image; a shifted right eye
// traces its bad pixels and reuses the rest; the G-buffer prefetch is empty when nothing lands.
#include <cstdint>

#include "sim_core/stereo.h"

#include "check.h"
#include "tracer_fixture.h"

using namespace sim_core;

int main() {
  const Scene s = test::make_scene();
  const Camera cam = test::make_camera();
  const CacheConfig cache = test::kCache;
  RenderSettings st = test::make_settings();
  const StereoOutput same_eye = render_stereo(s, cam, cam, st, 2, nullptr, cache);
  CHECK(same_eye.reuse_ratio == 1.0);
  CHECK(same_eye.left.fb.color == same_eye.right.fb.color);
  CHECK(same_eye.holes == 0 && same_eye.right.counters.samples_traced == 0);

  const Camera right = cam.shifted(0.3f);
  const StereoOutput shifted = render_stereo(s, cam, right, st, 2, nullptr, cache);
  const std::uint64_t n = static_cast<std::uint64_t>(cam.width) * cam.height;
  const Counters& rc = shifted.right.counters;
  CHECK(shifted.holes > 0);  // the frame edge the left eye does not see
  CHECK(rc.samples_reused + rc.samples_traced == n);
  CHECK(rc.reprojections == n && rc.pixels == n);
  CHECK(shifted.reuse_ratio > 0.5 && shifted.reuse_ratio < 1.0);
  const StereoOutput again = render_stereo(s, cam, right, st, 1, nullptr, cache);
  CHECK(again.right.fb.color == shifted.right.fb.color && again.right.histogram == shifted.right.histogram);

  CHECK(stereo_prefetch_texels(cam, right, 0, 0, 8, 8, false, kInf, 0.f, false) == 0);
  return check_exit_code();
}
