#include "calibproj/detect/resolution_limit.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

namespace calibproj::detect {

namespace {

// Module sizes beyond this many bins share the last one.
constexpr int kMaxBins = 400;

}  // namespace

void ResolutionOptions::Check() const {
  if (!(bin_px > 0.0)) throw std::invalid_argument("resolution options: bin_px must be positive");
  if (min_trials < 1) throw std::invalid_argument("resolution options: min_trials must be at least 1");
  if (!(min_found_share >= 0.0 && min_found_share <= 1.0)) {
    throw std::invalid_argument("resolution options: min_found_share must be in [0, 1]");
  }
}

ResolutionLimit::ResolutionLimit(ResolutionOptions options) : options_(options) {
  options_.Check();
  trials_.assign(kMaxBins, 0);
  found_.assign(kMaxBins, 0);
}

int ResolutionLimit::Bin(double module_px) const {
  return std::clamp(static_cast<int>(std::floor(module_px / options_.bin_px)), 0, kMaxBins - 1);
}

void ResolutionLimit::Record(double module_px, bool found) {
  const int bin = Bin(module_px);
  ++trials_[bin];
  if (found) ++found_[bin];
}

bool ResolutionLimit::Hopeless(double module_px) const {
  for (int bin = Bin(module_px); bin < kMaxBins; ++bin) {
    if (trials_[bin] >= options_.min_trials && found_[bin] < options_.min_found_share * trials_[bin]) return true;
  }
  return false;
}

}  // namespace calibproj::detect
