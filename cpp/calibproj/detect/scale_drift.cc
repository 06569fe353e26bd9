#include "calibproj/detect/scale_drift.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <tuple>

namespace calibproj::detect {

namespace {

// Kernel widths tried, as shares of the extent of the camera's MSMs; infinity is one
// drift for the whole camera (a far camera's floor spans a few of a relief's
// wavelengths, a zoomed camera's a fraction of one).
constexpr std::array<double, 6> kBandwidths = {0.03, 0.06, 0.12, 0.25, 0.5, std::numeric_limits<double>::infinity()};
// Beyond this many kernel widths a neighbour's weight is taken as 0.
constexpr double kKernelReach = 4.0;

// One MSM's kept scales as a regression of the centre on the squared side.
struct MsmScales {
  cv::Point2d projector;
  double mean_q = 0.0;
  double sxx = 0.0;         // sum (q - mean q)^2
  cv::Point2d sxy{0, 0};    // sum (q - mean q) (c - mean c)
  double syy = 0.0;         // sum |c - mean c|^2
};

std::vector<MsmScales> Regressions(const std::vector<ScaleRecord>& records, const std::vector<double>& side,
                                   const std::vector<cv::Point2d>& projector,
                                   const std::vector<MergedCentre>& centres) {
  double largest = 0.0;
  for (std::size_t k = 0; k < records.size(); ++k) {
    if (records[k].kept) largest = std::max(largest, side[k]);
  }
  std::vector<MsmScales> out(centres.size());
  std::size_t next = 0;
  for (std::size_t i = 0; i < centres.size(); ++i) {
    const auto msm = std::tie(centres[i].array, centres[i].marker);
    while (next < records.size() && std::tie(records[next].array, records[next].marker) < msm) ++next;
    std::vector<std::pair<double, cv::Point2d>> kept;
    for (std::size_t k = next; k < records.size() && std::tie(records[k].array, records[k].marker) == msm; ++k) {
      if (records[k].kept) kept.emplace_back(side[k] * side[k] / (largest * largest), records[k].centre);
    }
    MsmScales& m = out[i];
    m.projector = projector[i];
    if (kept.empty()) continue;
    cv::Point2d mean_c(0, 0);
    for (const auto& [q, c] : kept) {
      m.mean_q += q;
      mean_c += c;
    }
    m.mean_q /= kept.size();
    mean_c *= 1.0 / kept.size();
    for (const auto& [q, c] : kept) {
      const cv::Point2d d = c - mean_c;
      m.sxx += (q - m.mean_q) * (q - m.mean_q);
      m.sxy += (q - m.mean_q) * d;
      m.syy += d.dot(d);
    }
  }
  return out;
}

// The kernel-weighted sums of the informative MSMs' regressions around `at`, leaving
// out `skip` (-1: none).
std::pair<double, cv::Point2d> Pooled(const std::vector<const MsmScales*>& informative, const cv::Point2d& at,
                                      double sigma, int skip) {
  double w = 0.0;
  cv::Point2d v(0, 0);
  const double reach2 = kKernelReach * kKernelReach * sigma * sigma;
  for (int j = 0; j < static_cast<int>(informative.size()); ++j) {
    if (j == skip) continue;
    const MsmScales& m = *informative[j];
    double k = 1.0;
    if (std::isfinite(sigma)) {
      const cv::Point2d d = m.projector - at;
      const double d2 = d.dot(d);
      if (d2 > reach2) continue;
      k = std::exp(-0.5 * d2 / (sigma * sigma));
    }
    w += k * m.sxx;
    v += k * m.sxy;
  }
  return {w, v};
}

// The drift (px for the largest marker) at `at`: the kernel-weighted regressions pooled,
// shrunk towards none by `prior` (a number of MSMs' worth of squared-side spread) where
// few MSMs measure it.
cv::Point2d Drift(const std::vector<const MsmScales*>& informative, const cv::Point2d& at, double sigma, double prior,
                  int skip) {
  const auto [w, v] = Pooled(informative, at, sigma, skip);
  return w + prior > 0.0 ? v * (1.0 / (w + prior)) : cv::Point2d(0.0, 0.0);
}

// The leave-one-out sum of squared disagreement of the scales with the drift of width
// sigma predicting each MSM's from the others.
double HeldOutDisagreement(const std::vector<const MsmScales*>& informative, double sigma, double prior) {
  double sum = 0.0;
  for (int i = 0; i < static_cast<int>(informative.size()); ++i) {
    const MsmScales& m = *informative[i];
    const cv::Point2d s = Drift(informative, m.projector, sigma, prior, i);
    sum += m.syy - 2.0 * s.dot(m.sxy) + s.dot(s) * m.sxx;
  }
  return sum;
}

double Extent(const std::vector<cv::Point2d>& points) {
  double lo_x = points[0].x, hi_x = lo_x, lo_y = points[0].y, hi_y = lo_y;
  for (const cv::Point2d& p : points) {
    lo_x = std::min(lo_x, p.x);
    hi_x = std::max(hi_x, p.x);
    lo_y = std::min(lo_y, p.y);
    hi_y = std::max(hi_y, p.y);
  }
  return std::max({hi_x - lo_x, hi_y - lo_y, 1.0});
}

}  // namespace

void ScaleDriftOptions::Check() const {
  if (min_msms < 2) throw std::invalid_argument("scale drift options: min_msms must be at least 2");
  if (!(min_gain >= 0.0 && min_gain < 1.0)) throw std::invalid_argument("scale drift options: min_gain must be in [0, 1)");
  if (!(prior_msms >= 0.0) || !std::isfinite(prior_msms)) {
    throw std::invalid_argument("scale drift options: prior_msms must be a number >= 0");
  }
}

ScaleDriftResult CorrectScaleDrift(const std::vector<ScaleRecord>& records, const std::vector<double>& side,
                                   const std::vector<cv::Point2d>& projector, std::vector<MergedCentre>* centres,
                                   const ScaleDriftOptions& options) {
  options.Check();
  if (side.size() != records.size() || projector.size() != centres->size()) {
    throw std::invalid_argument("scale drift: one side per record and one projector position per centre needed");
  }
  ScaleDriftResult result;
  if (!options.enabled || centres->empty()) return result;
  const std::vector<MsmScales> msms = Regressions(records, side, projector, *centres);
  std::vector<const MsmScales*> informative;
  std::vector<double> spreads;
  for (const MsmScales& m : msms) {
    if (m.sxx <= 1e-12) continue;
    informative.push_back(&m);
    spreads.push_back(m.sxx);
    result.disagreement_none += m.syy;
  }
  result.msms = static_cast<int>(informative.size());
  result.disagreement_chosen = result.disagreement_none;
  if (result.msms < options.min_msms) return result;

  std::nth_element(spreads.begin(), spreads.begin() + spreads.size() / 2, spreads.end());
  const double prior = options.prior_msms * spreads[spreads.size() / 2];
  const double extent = Extent(projector);
  double best = result.disagreement_none;
  double best_share = 0.0;
  for (double share : kBandwidths) {
    const double held_out = HeldOutDisagreement(informative, share * extent, prior);
    if (held_out < best) {
      best = held_out;
      best_share = share;
    }
  }
  // Noise alone lets one of the widths predict a little: a drift must earn its place.
  if (best > (1.0 - options.min_gain) * result.disagreement_none) return result;
  result.bandwidth = best_share;
  result.disagreement_chosen = best;

  double squares = 0.0;
  for (std::size_t i = 0; i < centres->size(); ++i) {
    MergedCentre& centre = (*centres)[i];
    centre.drift = -msms[i].mean_q * Drift(informative, msms[i].projector, result.bandwidth * extent, prior, -1);
    centre.centre += centre.drift;
    squares += centre.drift.dot(centre.drift);
    ++result.corrected;
  }
  if (result.corrected > 0) result.rms_shift_px = std::sqrt(squares / result.corrected);
  return result;
}

}  // namespace calibproj::detect
