#include "sim_core/texture.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <stdexcept>

namespace sim_core {
namespace {

constexpr int kTile = 4;  // texels per tile edge in the modelled address layout

float srgb_to_linear(float c) {
  return c <= 0.04045f ? c / 12.92f : std::pow((c + 0.055f) / 1.055f, 2.4f);
}
float linear_to_srgb(float c) {
  return c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.f / 2.4f) - 0.055f;
}
const std::array<float, 256>& srgb_table() {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) t[static_cast<std::size_t>(i)] = srgb_to_linear(static_cast<float>(i) / 255.f);
    return t;
  }();
  return table;
}
std::uint8_t encode8(float linear, bool srgb) {
  const float c = std::min(1.f, std::max(0.f, linear));
  return static_cast<std::uint8_t>(std::lround((srgb ? linear_to_srgb(c) : c) * 255.f));
}

}  // namespace

float reduce_coordinate(float u, TextureWrap wrap) {
  if (!(std::fabs(u) <= 3.0e38f)) return 0.f;  // NaN or infinite: a defined texel, never UB
  switch (wrap) {
    case TextureWrap::kRepeat: return u - std::floor(u);
    case TextureWrap::kMirror: return u - 2.f * std::floor(0.5f * u);  // [0, 2): period of the mirror
    case TextureWrap::kClamp: break;
  }
  return std::min(2.f, std::max(-1.f, u));
}

int wrap_texel(int x, int n, TextureWrap wrap) {
  switch (wrap) {
    case TextureWrap::kRepeat: {
      const int r = x % n;
      return r < 0 ? r + n : r;
    }
    case TextureWrap::kMirror: {
      const int period = 2 * n;
      int r = x % period;
      if (r < 0) r += period;
      return r < n ? r : period - 1 - r;
    }
    case TextureWrap::kClamp: break;
  }
  return std::min(n - 1, std::max(0, x));
}

Texture::Texture(const void* pixels, int width, int height, TexelFormat format, TextureWrap wrap_u,
                 TextureWrap wrap_v)
    : format_(format), wrap_u_(wrap_u), wrap_v_(wrap_v) {
  if (width < 1 || height < 1 || width > 65536 || height > 65536)
    throw std::invalid_argument("texture size must be 1..65536 texels a side");
  const int f = static_cast<int>(format);
  if (f < 0 || f > 2) throw std::invalid_argument("texture format must be 0 (sRGB 8-bit), 1 (linear 8-bit) or 2 (float)");
  for (TextureWrap w : {wrap_u, wrap_v})
    if (static_cast<int>(w) < 0 || static_cast<int>(w) > 2)
      throw std::invalid_argument("texture wrap must be 0 (repeat), 1 (clamp) or 2 (mirror)");
  if (!pixels) throw std::invalid_argument("texture has no pixels");

  // Level sizes and where each level starts (storage and tiled byte layout).
  std::size_t texels = 0;
  std::uint64_t bytes = 0;
  for (int w = width, h = height;; w = std::max(1, w / 2), h = std::max(1, h / 2)) {
    levels_.push_back({w, h, texels, bytes});
    texels += static_cast<std::size_t>(w) * static_cast<std::size_t>(h);
    const std::uint64_t tiles = static_cast<std::uint64_t>((w + kTile - 1) / kTile) * ((h + kTile - 1) / kTile);
    bytes += tiles * kTile * kTile * texel_bytes();
    if (w == 1 && h == 1) break;
  }
  byte_size_ = bytes;

  // Level 0 as linear floats (the source of every coarser level), then the pyramid by 2x2 box averages.
  const std::size_t n0 = static_cast<std::size_t>(width) * static_cast<std::size_t>(height);
  std::vector<float> cur(n0 * 4);
  const bool eight = format != TexelFormat::kRgba32F;
  const bool srgb = format == TexelFormat::kRgba8Srgb;
  if (eight) {
    const auto* p = static_cast<const std::uint8_t*>(pixels);
    bytes_.resize(texels * 4);
    std::copy(p, p + n0 * 4, bytes_.begin());
    for (std::size_t i = 0; i < n0 * 4; ++i) {
      const float c = static_cast<float>(p[i]) / 255.f;
      cur[i] = (srgb && i % 4 != 3) ? srgb_table()[p[i]] : c;
    }
  } else {
    const auto* p = static_cast<const float*>(pixels);
    for (std::size_t i = 0; i < n0 * 4; ++i)
      if (!std::isfinite(p[i])) throw std::invalid_argument("texture texels must be finite");
    floats_.resize(texels * 4);
    std::copy(p, p + n0 * 4, floats_.begin());
    cur.assign(p, p + n0 * 4);
  }
  for (std::size_t i = 3; i < n0 * 4; i += 4) has_alpha_ |= cur[i] < 1.f;

  for (std::size_t li = 1; li < levels_.size(); ++li) {
    const Level& src = levels_[li - 1];
    const Level& dst = levels_[li];
    std::vector<float> next(static_cast<std::size_t>(dst.width) * dst.height * 4);
    for (int y = 0; y < dst.height; ++y)
      for (int x = 0; x < dst.width; ++x) {
        // The 2x2 source texels (clamped at an odd edge; a 1-texel-wide source repeats its only column).
        const int xa = std::min(2 * x, src.width - 1), xb = std::min(2 * x + 1, src.width - 1);
        const int ya = std::min(2 * y, src.height - 1), yb = std::min(2 * y + 1, src.height - 1);
        float* o = &next[(static_cast<std::size_t>(y) * dst.width + x) * 4];
        for (int c = 0; c < 4; ++c) {
          auto at = [&](int sx, int sy) { return cur[(static_cast<std::size_t>(sy) * src.width + sx) * 4 + c]; };
          o[c] = 0.25f * (at(xa, ya) + at(xb, ya) + at(xa, yb) + at(xb, yb));
        }
      }
    const std::size_t n = static_cast<std::size_t>(dst.width) * dst.height * 4;
    if (eight) {
      for (std::size_t i = 0; i < n; ++i) bytes_[dst.first * 4 + i] = encode8(next[i], srgb && i % 4 != 3);
    } else {
      std::copy(next.begin(), next.end(), floats_.begin() + static_cast<std::ptrdiff_t>(dst.first * 4));
    }
    cur.swap(next);
  }
}

Rgba Texture::fetch(const Level& l, int x, int y) const {
  const std::size_t i = (l.first + static_cast<std::size_t>(y) * l.width + x) * 4;
  Rgba t;
  if (format_ == TexelFormat::kRgba32F) {
    t.rgb = Vec3(floats_[i], floats_[i + 1], floats_[i + 2]);
    t.a = floats_[i + 3];
  } else if (format_ == TexelFormat::kRgba8Srgb) {
    const auto& table = srgb_table();
    t.rgb = Vec3(table[bytes_[i]], table[bytes_[i + 1]], table[bytes_[i + 2]]);
    t.a = static_cast<float>(bytes_[i + 3]) / 255.f;
  } else {
    t.rgb = Vec3(bytes_[i], bytes_[i + 1], bytes_[i + 2]) * (1.f / 255.f);
    t.a = static_cast<float>(bytes_[i + 3]) / 255.f;
  }
  return t;
}

Rgba Texture::texel(int level, int x, int y) const {
  if (level < 0 || level >= levels()) throw std::invalid_argument("texture level out of range");
  const Level& l = levels_[static_cast<std::size_t>(level)];
  if (x < 0 || y < 0 || x >= l.width || y >= l.height) throw std::invalid_argument("texel out of range");
  return fetch(l, x, y);
}

std::uint64_t Texture::tiled_offset(const Level& l, int x, int y) const {
  const std::uint64_t tiles_x = static_cast<std::uint64_t>((l.width + kTile - 1) / kTile);
  const std::uint64_t tile = static_cast<std::uint64_t>(y / kTile) * tiles_x + static_cast<std::uint64_t>(x / kTile);
  const std::uint64_t within = static_cast<std::uint64_t>((y % kTile) * kTile + x % kTile);
  return l.byte_base + (tile * kTile * kTile + within) * texel_bytes();
}

}  // namespace sim_core
