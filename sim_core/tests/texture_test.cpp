// Textures: bilinear filtering and mip levels against a direct computation from the texels, sRGB decoding
// before filtering, trilinear blending, the three wrap modes, and the hard cases (grazing footprints,
// degenerate UVs, huge or NaN coordinates) that must saturate, never produce NaN or read out of range.
#include <cmath>
#include <limits>
#include <stdexcept>
#include <vector>

#include "sim_core/texture.h"

#include "check.h"

using namespace sim_core;

namespace {

bool near(float a, float b, float tol = 1e-5f) { return std::fabs(a - b) <= tol; }

// A float texture whose texel (x, y) holds (x + 10 y, x * y, 1 + x - y, alpha).
std::vector<float> ramp(int w, int h, float alpha = 1.f) {
  std::vector<float> p;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) p.insert(p.end(), {float(x + 10 * y), float(x * y), float(1 + x - y), alpha});
  return p;
}

// Bilinear weights of the reference: continuous texel coordinates, clamp-to-edge, computed directly.
float direct_bilinear(const std::vector<float>& p, int w, int h, float u, float v, int c) {
  const float x = u * w - 0.5f, y = (1.f - v) * h - 0.5f;
  const int x0 = int(std::floor(x)), y0 = int(std::floor(y));
  const float fx = x - x0, fy = y - y0;
  auto t = [&](int xi, int yi) {
    xi = std::min(w - 1, std::max(0, xi));
    yi = std::min(h - 1, std::max(0, yi));
    return p[(std::size_t(yi) * w + xi) * 4 + c];
  };
  return (1 - fx) * (1 - fy) * t(x0, y0) + fx * (1 - fy) * t(x0 + 1, y0) + (1 - fx) * fy * t(x0, y0 + 1) +
         fx * fy * t(x0 + 1, y0 + 1);
}

void check_bilinear_against_direct() {
  const int w = 5, h = 3;
  const std::vector<float> p = ramp(w, h);
  const Texture tex(p.data(), w, h, TexelFormat::kRgba32F, TextureWrap::kClamp, TextureWrap::kClamp);
  CHECK(tex.levels() == 3);  // 5x3, 2x1, 1x1
  for (float u : {0.05f, 0.31f, 0.5f, 0.77f, 0.95f})
    for (float v : {0.1f, 0.42f, 0.9f}) {
      int taps = 0;
      const Rgba s = tex.sample(u, v, 0.f, [&](std::uint64_t off) { ++taps; CHECK(off < tex.byte_size()); });
      CHECK(taps == 4);
      CHECK(near(s.rgb.x, direct_bilinear(p, w, h, u, v, 0), 1e-4f));
      CHECK(near(s.rgb.y, direct_bilinear(p, w, h, u, v, 1), 1e-4f));
      CHECK(near(s.rgb.z, direct_bilinear(p, w, h, u, v, 2), 1e-4f));
    }
  // A texel centre returns the texel (v = 1 is the top row).
  const Rgba c = tex.sample((2 + 0.5f) / w, 1.f - (1 + 0.5f) / h, 0.f);
  CHECK(near(c.rgb.x, 12.f) && near(c.rgb.y, 2.f) && near(c.rgb.z, 2.f));
}

void check_mip_levels_and_trilinear() {
  const int w = 8, h = 4;
  const std::vector<float> p = ramp(w, h, 0.5f);
  const Texture tex(p.data(), w, h, TexelFormat::kRgba32F, TextureWrap::kRepeat, TextureWrap::kRepeat);
  CHECK(tex.levels() == 4);  // 8x4, 4x2, 2x1, 1x1
  CHECK(tex.level_width(1) == 4 && tex.level_height(1) == 2 && tex.level_width(3) == 1);
  // Level 1 texel (1, 1) is the mean of level-0 texels (2..3, 2..3).
  double sum = 0;
  for (int y = 2; y < 4; ++y)
    for (int x = 2; x < 4; ++x) sum += p[(std::size_t(y) * w + x) * 4];
  CHECK(near(tex.texel(1, 1, 1).rgb.x, float(sum / 4)));
  // The top level is the mean of the whole image (power-of-two sizes: exact box pyramid).
  double all = 0;
  for (int i = 0; i < w * h; ++i) all += p[std::size_t(i) * 4 + 1];
  CHECK(near(tex.texel(3, 0, 0).rgb.y, float(all / (w * h)), 1e-4f));
  CHECK(near(tex.texel(3, 0, 0).a, 0.5f) && tex.has_alpha());
  // A fractional level blends the two bilinear lookups (8 texel reads).
  int taps = 0;
  const Rgba tri = tex.sample(0.3f, 0.6f, 1.25f, [&](std::uint64_t) { ++taps; });
  const Rgba l1 = tex.sample(0.3f, 0.6f, 1.f), l2 = tex.sample(0.3f, 0.6f, 2.f);
  CHECK(taps == 8);
  CHECK(near(tri.rgb.x, 0.75f * l1.rgb.x + 0.25f * l2.rgb.x, 1e-4f));
}

void check_srgb_decoded_before_filtering() {
  // 2x1 sRGB texture: black and white. Filtering happens on linear values: halfway is 0.5, not 0.214.
  const std::uint8_t px[8] = {0, 0, 0, 255, 255, 255, 255, 255};
  const Texture tex(px, 2, 1, TexelFormat::kRgba8Srgb, TextureWrap::kClamp, TextureWrap::kClamp);
  CHECK(tex.texel_bytes() == 4 && !tex.has_alpha());
  const Rgba mid = tex.sample(0.5f, 0.5f, 0.f);
  CHECK(near(mid.rgb.x, 0.5f, 1e-6f));
  // The mip level stores the linear mean re-encoded: 188 in sRGB decodes to 0.5029.
  CHECK(near(tex.texel(1, 0, 0).rgb.x, 0.5029f, 5e-4f));
  const std::uint8_t grey[4] = {128, 128, 128, 255};
  const Texture g(grey, 1, 1, TexelFormat::kRgba8Srgb, TextureWrap::kRepeat, TextureWrap::kRepeat);
  CHECK(near(g.sample(0.2f, 0.7f, 0.f).rgb.y, 0.2158605f, 1e-5f));
  const Texture lin(grey, 1, 1, TexelFormat::kRgba8Linear, TextureWrap::kRepeat, TextureWrap::kRepeat);
  CHECK(near(lin.sample(0.2f, 0.7f, 0.f).rgb.y, 128.f / 255.f, 1e-6f));
}

void check_wrap_modes() {
  const int w = 4, h = 4;
  const std::vector<float> p = ramp(w, h);
  const Texture rep(p.data(), w, h, TexelFormat::kRgba32F, TextureWrap::kRepeat, TextureWrap::kRepeat);
  const Texture clamp(p.data(), w, h, TexelFormat::kRgba32F, TextureWrap::kClamp, TextureWrap::kClamp);
  const Texture mir(p.data(), w, h, TexelFormat::kRgba32F, TextureWrap::kMirror, TextureWrap::kMirror);
  CHECK(near(rep.sample(1.3f, 2.4f, 0.f).rgb.x, rep.sample(0.3f, 0.4f, 0.f).rgb.x, 1e-4f));
  CHECK(near(rep.sample(-0.7f, -0.6f, 0.f).rgb.x, rep.sample(0.3f, 0.4f, 0.f).rgb.x, 1e-4f));
  CHECK(near(clamp.sample(7.f, 0.5f, 0.f).rgb.x, clamp.sample(1.f, 0.5f, 0.f).rgb.x));
  CHECK(near(clamp.sample(-3.f, 0.5f, 0.f).rgb.x, clamp.sample(0.f, 0.5f, 0.f).rgb.x));
  CHECK(near(mir.sample(1.3f, 0.4f, 0.f).rgb.x, mir.sample(0.7f, 0.4f, 0.f).rgb.x, 1e-4f));
  CHECK(near(mir.sample(-0.2f, 0.4f, 0.f).rgb.x, mir.sample(0.2f, 0.4f, 0.f).rgb.x, 1e-4f));
  CHECK(wrap_texel(-1, 4, TextureWrap::kRepeat) == 3 && wrap_texel(4, 4, TextureWrap::kMirror) == 3);
  CHECK(wrap_texel(-1, 4, TextureWrap::kMirror) == 0 && wrap_texel(9, 4, TextureWrap::kClamp) == 3);
}

void check_hard_cases() {
  const int w = 16, h = 8;
  const std::vector<float> p = ramp(w, h);
  const Texture tex(p.data(), w, h, TexelFormat::kRgba32F, TextureWrap::kRepeat, TextureWrap::kClamp);
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  const Rgba top = tex.texel(tex.levels() - 1, 0, 0);
  // Grazing ray: |cos| -> 0 makes the footprint infinite; the lookup saturates at the 1x1 level.
  const float grazing = texture_lod(0.f, w, h, 0.01f, 0.f);
  CHECK(std::isinf(grazing) && grazing > 0.f);
  const Rgba g = tex.sample(0.4f, 0.4f, grazing);
  CHECK(near(g.rgb.x, top.rgb.x, 1e-4f));
  // Degenerate UVs (zero UV area): lod -inf, the finest level; NaN lod also reads the finest level.
  const float degenerate = texture_lod(-inf, w, h, 0.01f, 1.f);
  CHECK(near(tex.sample(0.4f, 0.4f, degenerate).rgb.x, tex.sample(0.4f, 0.4f, 0.f).rgb.x));
  CHECK(near(tex.sample(0.4f, 0.4f, nan).rgb.x, tex.sample(0.4f, 0.4f, 0.f).rgb.x));
  CHECK(std::isnan(texture_lod(-inf, w, h, 0.01f, 0.f)));  // -inf + inf: sample() still copes
  // Huge, infinite and NaN coordinates give finite texels of the texture.
  for (float u : {1e30f, -1e30f, inf, -inf, nan})
    for (float lod : {0.f, 2.5f, nan, inf}) {
      const Rgba s = tex.sample(u, u, lod, [&](std::uint64_t off) { CHECK(off < tex.byte_size()); });
      CHECK(std::isfinite(s.rgb.x) && std::isfinite(s.rgb.y) && std::isfinite(s.rgb.z) && std::isfinite(s.a));
    }
  // Bad inputs are rejected.
  bool threw = false;
  const float bad[4] = {nan, 0.f, 0.f, 1.f};
  try { Texture t(bad, 1, 1, TexelFormat::kRgba32F, TextureWrap::kRepeat, TextureWrap::kRepeat); }
  catch (const std::invalid_argument&) { threw = true; }
  CHECK(threw);
  threw = false;
  try { Texture t(p.data(), 0, 4, TexelFormat::kRgba32F, TextureWrap::kRepeat, TextureWrap::kRepeat); }
  catch (const std::invalid_argument&) { threw = true; }
  CHECK(threw);
}

void check_tiled_addresses() {
  // 8-bit 8x8: a 2x2 quad inside one 4x4 tile touches one 64-byte line; every offset is in range and
  // distinct texels have distinct offsets.
  std::vector<std::uint8_t> px(8 * 8 * 4, 200);
  const Texture tex(px.data(), 8, 8, TexelFormat::kRgba8Linear, TextureWrap::kRepeat, TextureWrap::kRepeat);
  std::vector<std::uint64_t> offs;
  tex.sample(1.5f / 8.f, 1.f - 1.5f / 8.f, 0.f, [&](std::uint64_t o) { offs.push_back(o); });
  CHECK(offs.size() == 4);
  for (std::uint64_t o : offs) CHECK(o / 64 == offs[0] / 64);
  std::uint64_t total = 0;
  for (int l = 0; l < tex.levels(); ++l) total += std::uint64_t((tex.level_width(l) + 3) / 4) * ((tex.level_height(l) + 3) / 4) * 64;
  CHECK(tex.byte_size() == total);
}

}  // namespace

int main() {
  check_bilinear_against_direct();
  check_mip_levels_and_trilinear();
  check_srgb_decoded_before_filtering();
  check_wrap_modes();
  check_hard_cases();
  check_tiled_addresses();
  return check_exit_code();
}
