// The frame driver: identical images, depths, counters and comparator histograms for any thread count in
// every sampling mode; finite non-negative colours; per-tile statistics (every counter and the comparator
// histogram) that add up to the frame's; a multi-rate frame that takes the previous frame's state.
#include <array>
#include <cmath>
#include <cstdint>

#include "sim_core/render.h"

#include "check.h"
#include "tracer_fixture.h"

using namespace sim_core;

namespace {

bool same(const RenderOutput& a, const RenderOutput& b) {
  bool counters_equal = true;
  const Counters& ca = a.counters;
  const Counters& cb = b.counters;
#define SIM_CORE_EQUAL(name) counters_equal = counters_equal && ca.name == cb.name;
  SIM_CORE_COUNTERS(SIM_CORE_EQUAL)
#undef SIM_CORE_EQUAL
  return a.fb.color == b.fb.color && a.fb.depth == b.fb.depth && a.fb.kind == b.fb.kind && counters_equal &&
         a.histogram == b.histogram;
}

void check_tile_sums(const RenderOutput& o) {
  std::uint64_t rays = 0, nodes = 0, tris = 0, misses = 0, pixels = 0;
  for (const TileStat& t : o.tiles) {
    rays += t.rays_total;
    nodes += t.bvh_node_visits;
    tris += t.triangle_tests;
    misses += t.cache_misses;
    pixels += static_cast<std::uint64_t>(t.width) * t.height;
  }
  CHECK(rays == o.counters.rays_total && nodes == o.counters.bvh_node_visits);
  CHECK(tris == o.counters.triangle_tests && misses == o.counters.cache_misses);
  CHECK(pixels == o.counters.pixels && pixels == static_cast<std::uint64_t>(o.fb.width) * o.fb.height);
  Counters sum;  // every counter and the comparator histogram of the tiles add up to the frame's
  ComparatorHistogram hist{};
  for (const TileStat& t : o.tiles) {
    sum += t.counters;
    for (std::size_t i = 0; i < hist.size(); ++i) hist[i] += t.histogram[i];
    CHECK(t.counters.rays_total == t.rays_total && t.counters.cache_misses == t.cache_misses);
  }
#define SIM_CORE_SUMS(name) CHECK(sum.name == o.counters.name);
  SIM_CORE_COUNTERS(SIM_CORE_SUMS)
#undef SIM_CORE_SUMS
  CHECK(hist == o.histogram);
}

// The window [x, x + w) x [y, y + h) of `cam`'s frame.
Camera window_of(const Camera& cam, int x, int y, int w, int h) {
  Camera win = cam;
  win.crop_x = x;
  win.crop_y = y;
  win.width = w;
  win.height = h;
  win.full_width = cam.width;
  win.full_height = cam.height;
  return win;
}

// Whether a window's pixels are the whole frame's there, bit for bit.
bool same_pixels(const RenderOutput& part, const RenderOutput& whole, int frame_width, int x, int y, int w,
                 int h) {
  bool same = part.fb.color.size() == static_cast<std::size_t>(w * h * 3);
  for (int j = 0; same && j < h; ++j)
    for (int i = 0; i < w * 3; ++i)
      same = same && part.fb.color[static_cast<std::size_t>(j * w * 3 + i)] ==
                         whole.fb.color[static_cast<std::size_t>(((y + j) * frame_width + x) * 3 + i)];
  return same;
}

void check_render(const Scene& s) {
  const Camera cam = test::make_camera();
  const CacheConfig cache = test::kCache;
  RenderSettings st = test::make_settings();
  for (int mode = 0; mode < 4; ++mode) {
    st.mode = static_cast<SamplingMode>(mode);
    const RenderOutput a = render_frame(s, cam, st, 1, nullptr, cache);
    const RenderOutput b = render_frame(s, cam, st, 2, nullptr, cache);
    CHECK(same(a, b));
    for (float c : a.fb.color) CHECK(std::isfinite(c) && c >= 0.f);
    check_tile_sums(a);
    CHECK(a.tiles.size() == 5u * 4u);  // 40 x 30 pixels in 8-pixel tiles
  }
  // Multi-rate: a second frame uses the first frame's state.
  RenderSettings mr = st;
  mr.mode = SamplingMode::kUndersample;
  mr.multirate = true;
  const RenderOutput f0 = render_frame(s, cam, mr, 2, nullptr, cache);
  const RenderOutput f1 = render_frame(s, cam, mr, 2, &f0.multirate, cache);
  CHECK(f1.multirate.block.size() == f0.multirate.block.size());
  CHECK(f0.multirate.matches(5, 4, 8, cam.width, cam.height));
}

// A window of the frame (on its tile grid: in the middle, and on two of its edges) has the frame's pixels
// and per-tile counters in every mode with sub-samples and AO, its apron only the resolve's reach: fewer
// rays than the whole tiles around it.
void check_windows(const Scene& s) {
  const Camera cam = test::make_camera(40, 30);
  RenderSettings st = test::make_settings();  // 8-pixel tiles, AO
  for (int mode = 0; mode < 4; ++mode)
    for (int block : {2, 3}) {
      st.mode = static_cast<SamplingMode>(mode);
      st.block = block;
      const RenderOutput whole = render_frame(s, cam, st, 2, nullptr, test::kCache);
      const int wx = 8, wy = 8, ww = 16, wh = 8;
      for (const auto& [x, y, w, h] : {std::array<int, 4>{wx, wy, ww, wh}, std::array<int, 4>{0, 16, 40, 14}}) {
        const RenderOutput part = render_frame(s, window_of(cam, x, y, w, h), st, 2, nullptr, test::kCache);
        CHECK(same_pixels(part, whole, cam.width, x, y, w, h));
        std::uint64_t rays = 0, ring = 0;  // the window's tiles' rays; those of the whole tiles around it
        for (const TileStat& t : whole.tiles) {
          const bool inside = t.x0 >= x && t.x0 < x + w && t.y0 >= y && t.y0 < y + h;
          const bool near = t.x0 >= x - 8 && t.x0 < x + w + 8 && t.y0 >= y - 8 && t.y0 < y + h + 8;
          (inside ? rays : ring) += inside || near ? t.rays_total : 0;
        }
        CHECK(part.counters.rays_total == rays);
        CHECK(part.apron_rays > 0 && part.apron_rays < ring);
      }
    }
}

// A window off the tile grid keeps the frame's grid: the frame's pixels in every mode (the adaptive ones
// too), its tiles the frame's cut at its edges, the whole ones with the frame's counters, the cut ones
// with no more rays than the frame's tiles (fewer in all).
void check_windows_off_the_grid(const Scene& s) {
  const Camera cam = test::make_camera(40, 30);
  RenderSettings st = test::make_settings();  // 8-pixel tiles, AO
  for (int mode = 0; mode < 4; ++mode)
    for (int block : {2, 3}) {
      st.mode = static_cast<SamplingMode>(mode);
      st.block = block;
      const RenderOutput whole = render_frame(s, cam, st, 2, nullptr, test::kCache);
      for (const auto& [x, y, w, h] : {std::array<int, 4>{5, 3, 17, 11}, std::array<int, 4>{3, 10, 37, 20}}) {
        const RenderOutput part = render_frame(s, window_of(cam, x, y, w, h), st, 2, nullptr, test::kCache);
        CHECK(same_pixels(part, whole, cam.width, x, y, w, h));
        check_tile_sums(part);
        const int cols = (x + w + 7) / 8 - x / 8, rows = (y + h + 7) / 8 - y / 8;
        std::uint64_t cut_rays = 0, frame_rays = 0;  // the cut tiles' rays; the frame's tiles there
        CHECK(part.tiles.size() == static_cast<std::size_t>(cols * rows));
        for (const TileStat& t : part.tiles) {
          const int fx = x + t.x0, fy = y + t.y0;  // the tile in the frame's pixels
          const TileStat& f = whole.tiles[static_cast<std::size_t>(fy / 8 * 5 + fx / 8)];
          CHECK(t.x0 >= 0 && t.y0 >= 0 && t.x0 + t.width <= w && t.y0 + t.height <= h);
          if (fx == f.x0 && fy == f.y0 && t.width == f.width && t.height == f.height) {
            CHECK(t.rays_total == f.rays_total && t.counters.cache_misses == f.counters.cache_misses);
            CHECK(t.histogram == f.histogram);
          } else {  // only the reference cells holding its part: never more (adaptively, maybe all)
            CHECK(t.rays_total <= f.rays_total);
            cut_rays += t.rays_total;
            frame_rays += f.rays_total;
          }
        }
        CHECK(cut_rays < frame_rays);
      }
    }
}

}  // namespace

int main() {
  check_render(test::make_scene());
  check_windows(test::make_scene());
  check_windows_off_the_grid(test::make_scene());
  return check_exit_code();
}
