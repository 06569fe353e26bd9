#pragma once
// Order statistics of a sample, without sorting it all.

#include <algorithm>
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

}  // namespace calibproj
