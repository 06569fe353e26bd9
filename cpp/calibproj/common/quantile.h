#pragma once
// Order statistics of a sample, without sorting it all.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <vector>

namespace calibproj {

// The value below which a `share` in [0, 1] of `values` lie (nearest rank); the
// values are reordered. Undefined for an empty sample.
inline double Quantile(std::vector<double>& values, double share) {
  const size_t k = std::min(values.size() - 1, static_cast<size_t>(share * static_cast<double>(values.size())));
  std::nth_element(values.begin(), values.begin() + static_cast<std::ptrdiff_t>(k), values.end());
  return values[k];
}

// The quantile of the chi-square distribution with `dof` degrees of freedom at the
// standard normal quantile `z` (3.09: 99.9 %), by the Wilson-Hilferty cube-root
// approximation: within 1 % from 10 degrees of freedom on.
inline double ChiSquareQuantile(int dof, double z) {
  const double k = static_cast<double>(std::max(dof, 1));
  const double spread = 2.0 / (9.0 * k);
  const double root = 1.0 - spread + z * std::sqrt(spread);
  return k * root * root * root;
}

}  // namespace calibproj
