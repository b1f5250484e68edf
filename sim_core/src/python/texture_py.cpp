// Bindings of textures: a NativeTexture is built once from a validated RGBA image (sim_core.Texture does
// the validation) and shared by every scene and material that uses it.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/shared_ptr.h>

#include <cstdint>
#include <memory>
#include <stdexcept>

#include "sim_core/texture.h"

namespace nb = nanobind;
using namespace nb::literals;

namespace sim_core {

void bind_texture(nb::module_& m) {
  nb::class_<Texture>(m, "NativeTexture",
                      "Base-colour texture with its mip pyramid. Build it through sim_core.Texture, which validates.")
      .def_static(
          "from_rgba8",
          [](nb::ndarray<const std::uint8_t, nb::shape<-1, -1, 4>, nb::c_contig, nb::device::cpu> rgba, bool srgb,
             int wrap_u, int wrap_v) {
            nb::gil_scoped_release release;
            return std::make_shared<Texture>(rgba.data(), static_cast<int>(rgba.shape(1)),
                                             static_cast<int>(rgba.shape(0)),
                                             srgb ? TexelFormat::kRgba8Srgb : TexelFormat::kRgba8Linear,
                                             static_cast<TextureWrap>(wrap_u), static_cast<TextureWrap>(wrap_v));
          },
          "rgba"_a, "srgb"_a, "wrap_u"_a, "wrap_v"_a,
          "8-bit RGBA image (H, W, 4), row 0 at the top; srgb: colour channels are sRGB-encoded.")
      .def_static(
          "from_rgba32f",
          [](nb::ndarray<const float, nb::shape<-1, -1, 4>, nb::c_contig, nb::device::cpu> rgba, int wrap_u,
             int wrap_v) {
            nb::gil_scoped_release release;
            return std::make_shared<Texture>(rgba.data(), static_cast<int>(rgba.shape(1)),
                                             static_cast<int>(rgba.shape(0)), TexelFormat::kRgba32F,
                                             static_cast<TextureWrap>(wrap_u), static_cast<TextureWrap>(wrap_v));
          },
          "rgba"_a, "wrap_u"_a, "wrap_v"_a, "Linear float RGBA image (H, W, 4), row 0 at the top.")
      .def(
          "sample",
          [](const Texture& t, float u, float v, float lod) {
            std::uint64_t taps = 0;
            const Rgba s = t.sample(u, v, lod, [&](std::uint64_t) { ++taps; });
            return nb::make_tuple(s.rgb.x, s.rgb.y, s.rgb.z, s.a, taps);
          },
          "u"_a, "v"_a, "lod"_a, "Filtered (r, g, b, a, texel reads) at UV (u, v) and level of detail lod.")
      .def(
          "texel",
          [](const Texture& t, int level, int x, int y) {
            const Rgba s = t.texel(level, x, y);
            return nb::make_tuple(s.rgb.x, s.rgb.y, s.rgb.z, s.a);
          },
          "level"_a, "x"_a, "y"_a, "Decoded linear (r, g, b, a) of one texel of a mip level.")
      .def_prop_ro("width", &Texture::width)
      .def_prop_ro("height", &Texture::height)
      .def_prop_ro("levels", &Texture::levels)
      .def_prop_ro("texel_bytes", &Texture::texel_bytes)
      .def_prop_ro("byte_size", &Texture::byte_size)
      .def_prop_ro("has_alpha", &Texture::has_alpha);
}

}  // namespace sim_core
