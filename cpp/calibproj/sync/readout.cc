#include "calibproj/sync/readout.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>

namespace calibproj::sync {

namespace {

// Sharp bands needed, and the share of the image height their centres must span.
constexpr int kMinBands = 3;
constexpr int kMaxBands = 64;
constexpr double kMinSpread = 0.3;
// Bands whose offsets that fit span more than this (camera frames, half-width) saw no
// light change sharply enough to place them.
constexpr double kMaxBandUncertainty = 0.25;
// ... and bands whose light codes fit worse than this (residual RMS over contrast) do
// not show them (a code seen cleanly fits to about 0.002, through automatic exposure,
// compression and a textured floor to about 0.1).
constexpr double kMaxBandRms = 0.15;

// Readouts tried across the feasible range when bounding the first row's offset.
constexpr int kRangeSamples = 65;

double Median(std::vector<double> values) {
  const auto middle = values.begin() + static_cast<std::ptrdiff_t>(values.size() / 2);
  std::nth_element(values.begin(), middle, values.end());
  return *middle;
}

// The first-row offsets o that put every band inside its interval at readout r:
// o in [max(offset + r row - half_width), min(offset + r row + half_width)].
std::pair<double, double> FirstRowOffsets(const std::vector<BandInterval>& bands, double r) {
  double low = -std::numeric_limits<double>::infinity(), high = std::numeric_limits<double>::infinity();
  for (const BandInterval& band : bands) {
    low = std::max(low, band.offset + r * band.row - band.half_width);
    high = std::min(high, band.offset + r * band.row + band.half_width);
  }
  return {low, high};
}

// A uniform interval's standard deviation from its half-width.
double UniformSigma(double half_width) { return half_width / std::sqrt(3.0); }

// Widens the estimate to the range of readouts (and first-row offsets) that every
// band's interval allows, and moves a line fit outside that range to its middle.
void BoundByIntervals(const std::vector<BandInterval>& intervals, ReadoutEstimate* estimate) {
  double low = 0.0, high = 0.0;
  if (!FeasibleReadouts(intervals, &low, &high)) return;
  estimate->bounded = true;
  estimate->readout_low = low;
  estimate->readout_high = high;
  if (estimate->readout < low || estimate->readout > high) {
    estimate->readout = 0.5 * (low + high);
    const auto [first_low, first_high] = FirstRowOffsets(intervals, estimate->readout);
    estimate->first_row_offset = 0.5 * (first_low + first_high);
  }
  estimate->readout_sigma = std::max(estimate->readout_sigma, UniformSigma(0.5 * (high - low)));
  double first_low = std::numeric_limits<double>::infinity(), first_high = -first_low;
  for (int k = 0; k < kRangeSamples; ++k) {
    const double r = low + (high - low) * k / (kRangeSamples - 1);
    const auto [a, b] = FirstRowOffsets(intervals, r);
    if (a > b) continue;
    first_low = std::min(first_low, a);
    first_high = std::max(first_high, b);
  }
  if (first_low <= first_high) {
    estimate->offset_sigma = std::max(estimate->offset_sigma, UniformSigma(0.5 * (first_high - first_low)));
  }
}

}  // namespace

bool FeasibleReadouts(const std::vector<BandInterval>& bands, double* low, double* high) {
  // Some o meets every interval iff for every pair (a, b):
  // offset_a + r row_a - half_a <= offset_b + r row_b + half_b, i.e.
  // r (row_a - row_b) <= offset_b - offset_a + half_a + half_b.
  double lower = -std::numeric_limits<double>::infinity(), upper = std::numeric_limits<double>::infinity();
  for (const BandInterval& a : bands) {
    for (const BandInterval& b : bands) {
      const double slope = a.row - b.row;
      const double bound = b.offset - a.offset + a.half_width + b.half_width;
      if (slope > 0.0) {
        upper = std::min(upper, bound / slope);
      } else if (slope < 0.0) {
        lower = std::max(lower, bound / slope);
      } else if (bound < 0.0) {
        return false;
      }
    }
  }
  if (!(lower <= upper) || !std::isfinite(lower) || !std::isfinite(upper)) return false;
  *low = lower;
  *high = upper;
  return true;
}

// The estimate from one code window at the map's rate.
ReadoutEstimate EstimateInWindow(const std::vector<std::vector<double>>& band_signals, const LightTimeline& timeline,
                                 const FrameWindow& window, const FrameMap& map, const CodeFitOptions& options) {
  const std::vector<FrameWindow> windows{window};
  ReadoutEstimate estimate;
  const int bands = static_cast<int>(band_signals.size());
  // The whole frame's offset lies near its middle row's: bands reach up to a readout
  // (at most a frame) to either side of it.
  CodeFitOptions band_options = options;
  band_options.offset_range = options.offset_range + 1.0;
  std::vector<double> rows, offsets, weights, exposures;
  std::vector<BandInterval> intervals;  // every band that shows the codes
  const std::vector<std::optional<CodeFit>> fits =
      FitCodeWindowsOfSignals(band_signals, timeline, windows, map, false, band_options);
  for (int b = 0; b < bands; ++b) {
    // Too few measured frames in this band's windows: it gives nothing.
    if (!fits[b]) continue;
    const CodeFit& fit = *fits[b];
    // The half-width of the offsets that fit as a uniform interval's sigma, and
    // never below the fit's grid.
    const double sigma = std::max(fit.offset_uncertainty / std::sqrt(3.0), options.offset_step / std::sqrt(12.0));
    BandFit band{(b + 0.5) / bands, fit.map.offset, sigma, fit.rms, false};
    // A band that sees little of the projection (walls, the image's edge) fits noise.
    const bool shows_codes = fit.contrast > 0.0 && fit.rms <= kMaxBandRms;
    band.used = shows_codes && fit.offset_uncertainty <= kMaxBandUncertainty;
    estimate.bands.push_back(band);
    // An interval cut by the offsets searched bounds nothing.
    if (shows_codes && fit.offset_uncertainty < band_options.offset_range) {
      intervals.push_back({band.row, fit.map.offset, fit.offset_uncertainty});
    }
    if (!band.used) continue;
    rows.push_back((b + 0.5) / bands);
    offsets.push_back(fit.map.offset);
    weights.push_back(1.0 / (sigma * sigma));
    exposures.push_back(fit.map.exposure);
  }
  if (!intervals.empty()) {
    double sum = 0.0;
    for (const BandInterval& band : intervals) sum += band.row;
    estimate.signal_row = sum / static_cast<double>(intervals.size());
  }
  const int n = static_cast<int>(rows.size());
  if (n < kMinBands || rows.back() - rows.front() < kMinSpread) return estimate;
  // Weighted least-squares line offset = intercept + slope * row.
  double sw = 0, mean_row = 0, mean_offset = 0;
  for (int i = 0; i < n; ++i) {
    sw += weights[i];
    mean_row += weights[i] * rows[i];
    mean_offset += weights[i] * offsets[i];
  }
  mean_row /= sw;
  mean_offset /= sw;
  double srr = 0, sro = 0;
  for (int i = 0; i < n; ++i) {
    srr += weights[i] * (rows[i] - mean_row) * (rows[i] - mean_row);
    sro += weights[i] * (rows[i] - mean_row) * (offsets[i] - mean_offset);
  }
  const double slope = sro / srr;
  const double intercept = mean_offset - slope * mean_row;
  double chi2 = 0;
  for (int i = 0; i < n; ++i) {
    const double r = offsets[i] - intercept - slope * rows[i];
    chi2 += weights[i] * r * r;
  }
  // Bands scattered beyond their own uncertainty widen the result accordingly.
  const double dispersion = std::max(1.0, chi2 / std::max(n - 2, 1));
  estimate.valid = true;
  estimate.readout = -slope;
  estimate.readout_sigma = std::sqrt(dispersion / srr);
  estimate.first_row_offset = intercept;
  estimate.offset_sigma = std::sqrt(dispersion * (1.0 / sw + mean_row * mean_row / srr));
  estimate.exposure = Median(exposures);
  estimate.bands_used = n;
  BoundByIntervals(intervals, &estimate);
  return estimate;
}

ReadoutEstimate EstimateReadout(const std::vector<std::vector<double>>& band_signals, const LightTimeline& timeline,
                                const std::vector<FrameWindow>& windows, const FrameMap& map,
                                const CodeFitOptions& options) {
  // One code fit per band and window: as many bands as the ingest measures at most.
  if (band_signals.size() > static_cast<std::size_t>(kMaxBands)) {
    throw std::invalid_argument("readout: at most " + std::to_string(kMaxBands) + " bands, got " +
                                std::to_string(band_signals.size()));
  }
  // Each code window on its own, at the whole frame's rate; that rate is biased by the
  // rolling shutter (its box model fits codes seen at different phases differently),
  // so two windows give the first row's rate from where each puts its code.
  std::vector<ReadoutEstimate> estimates;
  std::vector<double> anchors;  // projector time of each window's centre
  ReadoutEstimate first;        // the first window's, valid or not (its band fits)
  for (std::size_t w = 0; w < windows.size(); ++w) {
    ReadoutEstimate e = EstimateInWindow(band_signals, timeline, windows[w], map, options);
    if (w == 0) first = e;
    if (!e.valid) continue;
    estimates.push_back(std::move(e));
    anchors.push_back(0.5 * (windows[w].begin + windows[w].end));
  }
  if (estimates.empty()) return first;
  ReadoutEstimate combined = estimates.front();
  if (estimates.size() == 1) return combined;
  double weights = 0.0, readout = 0.0;
  for (const ReadoutEstimate& e : estimates) {
    const double w = 1.0 / (e.readout_sigma * e.readout_sigma);
    weights += w;
    readout += w * e.readout;
  }
  combined.readout = readout / weights;
  combined.readout_sigma = std::sqrt(1.0 / weights);
  // Both windows' ranges hold: their intersection bounds the readout.
  combined.bounded = true;
  combined.readout_low = -std::numeric_limits<double>::infinity();
  combined.readout_high = std::numeric_limits<double>::infinity();
  for (const ReadoutEstimate& e : estimates) {
    combined.bounded = combined.bounded && e.bounded;
    combined.readout_low = std::max(combined.readout_low, e.readout_low);
    combined.readout_high = std::min(combined.readout_high, e.readout_high);
  }
  combined.bounded = combined.bounded && combined.readout_low <= combined.readout_high;
  if (combined.bounded) {
    const double low = combined.readout_low, high = combined.readout_high;
    if (combined.readout < low || combined.readout > high) combined.readout = 0.5 * (low + high);
    combined.readout_sigma = std::max(combined.readout_sigma, UniformSigma(0.5 * (high - low)));
  } else {
    combined.readout_low = combined.readout_high = 0.0;
  }
  const ReadoutEstimate& last = estimates.back();
  const double first_position = combined.first_row_offset + map.rate * anchors.front();
  const double last_position = last.first_row_offset + map.rate * anchors.back();
  combined.rate = (last_position - first_position) / (anchors.back() - anchors.front());
  combined.first_row_offset = first_position - combined.rate * anchors.front();
  return combined;
}

bool Applicable(const ReadoutEstimate& readout, double sigmas, double max_sigma) {
  return readout.valid && readout.readout > sigmas * readout.readout_sigma && readout.readout > 0.02 &&
         readout.readout <= kMaxReadoutFrames && readout.readout_sigma <= max_sigma;
}

FrameMap CoverRows(const FrameMap& window_map, const ReadoutEstimate& readout, double sigmas) {
  if (!readout.valid) return window_map;
  // Exposure windows of frame j, relative to j (camera frames): [-offset, -offset + exposure].
  const double margin = sigmas * (readout.offset_sigma + readout.readout_sigma);
  const double start = std::min(-window_map.offset, -readout.first_row_offset - margin);
  const double end = std::max(-window_map.offset + window_map.exposure,
                              -readout.first_row_offset + std::max(readout.readout, 0.0) + readout.exposure + margin);
  return FrameMap{-start, window_map.rate, end - start};
}

}  // namespace calibproj::sync
