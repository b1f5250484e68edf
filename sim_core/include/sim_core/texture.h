// Base-colour textures: an RGBA image with its mip pyramid (built once, box-filtered in linear light),
// sampled with trilinear filtering at a level of detail chosen from the ray footprint (a ray cone,
// Akenine-Moeller et al., "Texture Level of Detail Strategies for Real-Time Ray Tracing", Ray Tracing
// Gems ch. 20). Every texel the filter reads is reported to a tap (the tile's texture-cache model).
//
// Storage keeps the input's encoding, as a GPU's texture formats do: 8-bit RGBA (sRGB-encoded or linear,
// 4 bytes a texel, decoded to linear through a 256-entry table before filtering, like an *_SRGB format)
// or 32-bit float RGBA (16 bytes). Keeping 8 bits makes memory and the modelled texel traffic what a
// GPU would move; decoding before filtering keeps the filter in linear light. Mip levels of 8-bit images
// are computed from the float average of the finer level and re-encoded (rounded) once.
//
// Conventions: image row 0 is the top; UVs follow Blender (v up, (0, 0) at the image's bottom-left), so
// texel column = u * width, texel row = (1 - v) * height.
#pragma once
#include <cstdint>
#include <vector>

#include "sim_core/math.h"

namespace sim_core {

// Base of the texture address space the texture-cache model sees (textures follow one another from here).
inline constexpr std::uint64_t kTextureBaseAddress = 0x400000000ull;

enum class TexelFormat : int { kRgba8Srgb = 0, kRgba8Linear = 1, kRgba32F = 2 };
enum class TextureWrap : int { kRepeat = 0, kClamp = 1, kMirror = 2 };

struct Rgba {
  Vec3 rgb;
  float a = 1.f;
};

class Texture {
 public:
  // pixels: height * width * 4 values, row 0 at the top; std::uint8_t for the 8-bit formats, float for
  // kRgba32F (finite; the Python side clamps). Throws std::invalid_argument on bad sizes or values.
  Texture(const void* pixels, int width, int height, TexelFormat format, TextureWrap wrap_u, TextureWrap wrap_v);

  // Filtered linear RGBA at (u, v) and level of detail `lod` (log2 of the footprint in level-0 texels;
  // clamped to the pyramid, NaN counts as 0): bilinear at an integer level, trilinear between two.
  // tap(byte_offset) is called once for every texel read, with its byte offset in a 4x4-texel tiled
  // layout of all levels (what a texture cache would fetch).
  template <class Tap>
  Rgba sample(float u, float v, float lod, Tap&& tap) const;
  Rgba sample(float u, float v, float lod) const {
    return sample(u, v, lod, [](std::uint64_t) {});
  }
  // Linear RGBA of one texel (level, column, row), no wrapping.
  Rgba texel(int level, int x, int y) const;

  int width() const { return levels_[0].width; }
  int height() const { return levels_[0].height; }
  int levels() const { return static_cast<int>(levels_.size()); }
  int level_width(int level) const { return levels_[level].width; }
  int level_height(int level) const { return levels_[level].height; }
  TexelFormat format() const { return format_; }
  TextureWrap wrap_u() const { return wrap_u_; }
  TextureWrap wrap_v() const { return wrap_v_; }
  std::uint32_t texel_bytes() const { return format_ == TexelFormat::kRgba32F ? 16u : 4u; }
  // Bytes of all levels in the tiled layout (the texture's footprint in the address space).
  std::uint64_t byte_size() const { return byte_size_; }
  // True when some texel's alpha is below 1 (the texture can cut a surface out).
  bool has_alpha() const { return has_alpha_; }

 private:
  struct Level {
    int width, height;
    std::size_t first;         // index of its first texel in the storage (row-major)
    std::uint64_t byte_base;   // byte offset of the level in the tiled layout
  };
  TexelFormat format_;
  TextureWrap wrap_u_, wrap_v_;
  std::vector<Level> levels_;
  std::vector<std::uint8_t> bytes_;  // 8-bit formats: 4 per texel
  std::vector<float> floats_;        // kRgba32F: 4 per texel
  std::uint64_t byte_size_ = 0;
  bool has_alpha_ = false;

  Rgba fetch(const Level& l, int x, int y) const;
  std::uint64_t tiled_offset(const Level& l, int x, int y) const;
  template <class Tap>
  Rgba bilinear(int level, float u, float v, Tap& tap) const;
};

// Texel coordinate of continuous coordinate x (in texels) wrapped into [0, n): repeat, clamp or mirror.
int wrap_texel(int x, int n, TextureWrap wrap);
// u reduced to a range where u * size fits an int without changing the wrapped result (NaN -> 0).
float reduce_coordinate(float u, TextureWrap wrap);

// Level of detail of a ray-cone footprint (RT Gems ch. 20, eq. 34): lod = 0.5 log2(texels per unit of UV
// area of the triangle over its world area, times width * height) + log2(cone width / |cos incidence|).
// log2_uv_to_world = 0.5 * log2(uv area / world area) of the triangle (Scene precomputes it). Grazing
// rays and degenerate UVs give +-inf or NaN, which sample() clamps to the pyramid; never throws.
inline float texture_lod(float log2_uv_to_world, int width, int height, float cone_width, float cos_incidence) {
  const float c = std::fabs(cos_incidence);
  return log2_uv_to_world + 0.5f * std::log2(static_cast<float>(width) * static_cast<float>(height)) +
         std::log2(cone_width) - std::log2(c);
}

// ---- implementation of the templates ----

template <class Tap>
Rgba Texture::bilinear(int level, float u, float v, Tap& tap) const {
  const Level& l = levels_[static_cast<std::size_t>(level)];
  const float x = reduce_coordinate(u, wrap_u_) * static_cast<float>(l.width) - 0.5f;
  const float y = (1.f - reduce_coordinate(v, wrap_v_)) * static_cast<float>(l.height) - 0.5f;
  const float fx0 = std::floor(x), fy0 = std::floor(y);
  const float fx = x - fx0, fy = y - fy0;
  const int x0 = static_cast<int>(fx0), y0 = static_cast<int>(fy0);
  const int xs[2] = {wrap_texel(x0, l.width, wrap_u_), wrap_texel(x0 + 1, l.width, wrap_u_)};
  const int ys[2] = {wrap_texel(y0, l.height, wrap_v_), wrap_texel(y0 + 1, l.height, wrap_v_)};
  const float wx[2] = {1.f - fx, fx}, wy[2] = {1.f - fy, fy};
  Rgba out;
  out.a = 0.f;
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 2; ++i) {
      tap(tiled_offset(l, xs[i], ys[j]));
      const Rgba t = fetch(l, xs[i], ys[j]);
      const float w = wx[i] * wy[j];
      out.rgb += t.rgb * w;
      out.a += t.a * w;
    }
  return out;
}

template <class Tap>
Rgba Texture::sample(float u, float v, float lod, Tap&& tap) const {
  const float top = static_cast<float>(levels_.size() - 1);
  float level = lod > 0.f ? lod : 0.f;  // NaN -> 0
  if (level > top) level = top;
  const float base = std::floor(level);
  const float frac = level - base;
  const int l0 = static_cast<int>(base);
  const Rgba a = bilinear(l0, u, v, tap);
  if (!(frac > 0.f)) return a;
  const Rgba b = bilinear(l0 + 1, u, v, tap);
  Rgba out;
  out.rgb = lerp(a.rgb, b.rgb, frac);
  out.a = a.a + (b.a - a.a) * frac;
  return out;
}

}  // namespace sim_core
