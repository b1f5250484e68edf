// Bindings: mean SSIM of two float32 or float64 (H, W) or (H, W, C) C-contiguous images, GIL released.
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <limits>
#include <stdexcept>

#include "sim_core/ssim.h"

namespace nb = nanobind;
using namespace nb::literals;

namespace sim_core {
namespace {

template <typename T>
using Image = nb::ndarray<const T, nb::c_contig, nb::device::cpu>;

template <typename T>
double ssim_binding(Image<T> x, Image<T> y, double data_range, bool gaussian, int threads) {
  if (x.ndim() != y.ndim() || (x.ndim() != 2 && x.ndim() != 3))
    throw std::invalid_argument("images must both be (H, W) or (H, W, C)");
  for (std::size_t i = 0; i < x.ndim(); ++i)
    if (x.shape(i) != y.shape(i)) throw std::invalid_argument("images differ in shape");
  for (std::size_t i = 0; i < x.ndim(); ++i)
    if (x.shape(i) > static_cast<std::size_t>(std::numeric_limits<int>::max()))
      throw std::invalid_argument("image dimension too large");
  const int h = static_cast<int>(x.shape(0));
  const int w = static_cast<int>(x.shape(1));
  const int c = x.ndim() == 3 ? static_cast<int>(x.shape(2)) : 1;
  SsimOptions opt;
  opt.data_range = data_range;
  opt.gaussian = gaussian;
  opt.threads = threads;
  const T* xp = x.data();
  const T* yp = y.data();
  nb::gil_scoped_release release;
  return ssim_mean(xp, yp, h, w, c, opt);
}

}  // namespace

void bind_ssim(nb::module_& m) {
  const char* doc =
      "Mean SSIM as skimage.metrics.structural_similarity (7x7 box with sample covariance, or 11-tap "
      "Gaussian sigma 1.5 with population covariance; border of half a window cropped; channels "
      "averaged). NaN or Inf input gives NaN. threads=0: all cores.";
  m.def("ssim_mean", &ssim_binding<double>, "x"_a, "y"_a, "data_range"_a = 1.0, "gaussian"_a = false,
        "threads"_a = 0, doc);
  m.def("ssim_mean", &ssim_binding<float>, "x"_a, "y"_a, "data_range"_a = 1.0, "gaussian"_a = false,
        "threads"_a = 0, doc);
}

}  // namespace sim_core
