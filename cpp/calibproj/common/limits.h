#pragma once
// Bounds of the counts, sizes and values the library accepts. Past them a bad argument
// (a thread count of 2^31, a rate of 1e300, a step of 1e-300) would allocate or loop
// without limit; far above any real use, they turn such input into
// std::invalid_argument naming it.

#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <string>
#include <type_traits>

namespace calibproj::limits {

constexpr int kMaxThreads = 256;
constexpr int kMaxIterations = 1'000'000;
constexpr int kMaxPoints = 10'000'000;    // points, observations, candidates
constexpr int kMaxFrames = 10'000'000;    // frames of a sequence or a recording
constexpr int kMaxImageSide = 1 << 16;    // pixels
constexpr double kMaxMagnitude = 1e12;    // any option value, in its own unit

inline std::string Number(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.10g", value);
  return buffer;
}

// Throws std::invalid_argument "<what> must be a finite number, got <value>".
inline void RequireFinite(double value, const std::string& what) {
  if (!std::isfinite(value)) throw std::invalid_argument(what + " must be a finite number, got " + Number(value));
}

// Throws std::invalid_argument unless lo <= value <= hi (NaN is outside).
inline void RequireInRange(double value, double lo, double hi, const std::string& what) {
  if (!(value >= lo && value <= hi)) {
    throw std::invalid_argument(what + " must be in [" + Number(lo) + ", " + Number(hi) + "], got " + Number(value));
  }
}

// Checks one option of any arithmetic type: finite and of a magnitude up to
// kMaxMagnitude; bool options are always fine. Run after the options' own checks,
// which name their ranges, as a net for the options those leave unbounded.
struct OptionChecker {
  std::string prefix;  // e.g. "sync option "

  template <typename T>
  void operator()(const char* name, const T& value, const char* /*help*/ = nullptr) const {
    if constexpr (std::is_arithmetic_v<T> && !std::is_same_v<T, bool>) {
      const double number = static_cast<double>(value);
      if (!(std::abs(number) <= kMaxMagnitude)) {
        throw std::invalid_argument(prefix + name + " must be a finite number of magnitude at most " +
                                    Number(kMaxMagnitude) + ", got " + Number(number));
      }
    }
  }
};

}  // namespace calibproj::limits
