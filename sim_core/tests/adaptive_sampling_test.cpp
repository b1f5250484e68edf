// Adaptive sampling: with a similarity test nothing passes, every adaptive mode traces every sample and
// equals its full-rate mode bit for bit; the similarity test's rules; multi-rate block sizes with hysteresis.
#include <cstdint>

#include "sim_core/adaptive_sampling.h"

#include "check.h"
#include "tracer_fixture.h"

using namespace sim_core;

namespace {

void check_exact_at_full_rate(const Scene& s) {
  const Camera cam = test::make_camera();
  const CacheConfig cache = test::kCache;
  RenderSettings st = test::make_settings();
  st.normal_threshold_deg = -1.f;  // nothing is similar
  for (int block : {2, 3, 4}) {
    RenderSettings ref = st, adaptive = st;
    ref.mode = SamplingMode::kOneSpp;
    adaptive.mode = SamplingMode::kUndersample;
    adaptive.block = block;
    const RenderOutput a = render_frame(s, cam, ref, 2, nullptr, cache);
    const RenderOutput b = render_frame(s, cam, adaptive, 2, nullptr, cache);
    CHECK(a.fb.color == b.fb.color && a.fb.depth == b.fb.depth);
    CHECK(b.counters.samples_interpolated == 0 && b.counters.samples_traced == a.counters.samples_traced);
    ref.mode = SamplingMode::kFsaa;
    ref.block = block;
    adaptive.mode = SamplingMode::kSupersample;
    const RenderOutput c = render_frame(s, cam, ref, 2, nullptr, cache);
    const RenderOutput d = render_frame(s, cam, adaptive, 2, nullptr, cache);
    CHECK(c.fb.color == d.fb.color && d.counters.samples_interpolated == 0);
  }
}

void check_similarity() {
  SampleGeometry a, b;
  a.object = b.object = 3;
  a.normal = b.normal = Vec3(0.f, 0.f, 1.f);
  const float cos20 = 0.9396926f;
  CHECK(similar(a, b, cos20));
  CHECK(!similar(a, b, 2.f));  // a negative angle threshold: nothing is similar
  b.normal = normalize(Vec3(0.f, 1.f, 1.f));  // 45 degrees apart
  CHECK(!similar(a, b, cos20));
  b.normal = a.normal;
  b.shadow_bits = 1;
  CHECK(!similar(a, b, cos20));
  b.shadow_bits = 0;
  b.sec_object[0] = 2;  // a reflection ray that hit something else
  CHECK(!similar(a, b, cos20));
  b.sec_object[0] = a.sec_object[0];
  b.object = 4;
  CHECK(!similar(a, b, cos20));
  a.object = b.object = -1;  // two environment samples
  a.normal = Vec3(1.f, 0.f, 0.f);
  CHECK(similar(a, b, cos20));
}

void check_multirate_block() {
  RenderSettings st;
  st.multirate_low = 0.5f;
  st.multirate_high = 0.85f;
  CHECK(multirate_block(2, 0.9f, 10, st) == 3);   // similar enough: coarser
  CHECK(multirate_block(4, 0.9f, 10, st) == 4);   // already the coarsest
  CHECK(multirate_block(3, 0.4f, 10, st) == 2);   // too dissimilar: finer
  CHECK(multirate_block(2, 0.4f, 10, st) == 2);   // already the finest
  CHECK(multirate_block(3, 0.7f, 10, st) == 3);   // between the thresholds: kept
  CHECK(multirate_block(3, 0.f, 0, st) == 3);     // no check ran: the ratio means nothing
  CHECK(multirate_block(9, 0.7f, 10, st) == 4);   // clamped to 2..4
}

}  // namespace

int main() {
  check_exact_at_full_rate(test::make_scene());
  check_similarity();
  check_multirate_block();
  return check_exit_code();
}
