#include "calibproj/sync/code_search.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include "calibproj/common/limits.h"

namespace calibproj::sync {

namespace {

// Bounds of the search's work, far above the defaults (5 rates x 4 phases), so that a
// bad option cannot make it loop or allocate without limit.
constexpr int kMaxCandidateRates = 10'000;
constexpr int kMaxPhases = 1'000;
constexpr double kMaxTemplateSamples = 1e8;
// Camera fps / projector fps: a 1000 fps camera of a 1 fps projector, or the reverse.
constexpr double kMinNominalRate = 1e-3;
constexpr double kMaxNominalRate = 1e3;

void Require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument("code search options: " + message);
}

CodeTemplate MakeTemplate(const LightTimeline& timeline, const FrameWindow& window, double rate, double phase,
                          double exposure) {
  CodeTemplate t{rate, phase, {}, 0.0};
  const double duration = exposure / rate;
  for (int i = 0;; ++i) {
    const double start = window.begin + (i + phase) / rate;
    if (start + duration > window.end) break;
    t.values.push_back(timeline.Average(start, duration));
  }
  if (t.values.empty()) return t;
  double mean = 0.0;
  for (double v : t.values) mean += v;
  mean /= static_cast<double>(t.values.size());
  for (double& v : t.values) {
    v -= mean;
    t.norm += v * v;
  }
  t.norm = std::sqrt(t.norm);
  return t;
}

// Sets the template's values to `values` minus their mean, and its norm.
void Recentre(const std::vector<double>& values, CodeTemplate* t) {
  double mean = 0.0;
  for (double v : values) mean += v;
  mean /= static_cast<double>(values.size());
  t->values.resize(values.size());
  t->norm = 0.0;
  for (std::size_t i = 0; i < values.size(); ++i) {
    t->values[i] = values[i] - mean;
    t->norm += t->values[i] * t->values[i];
  }
  t->norm = std::sqrt(t->norm);
}

// Candidate rates, the nominal one first and then outwards: when several explain the
// signal equally well (a code seen without a frame across a light change), the search
// keeps the one closest to the nominal rate.
std::vector<double> CandidateRates(double nominal_rate, const CodeSearchOptions& options) {
  const int steps = static_cast<int>(std::floor(options.rate_search / options.rate_step + 1e-9));
  std::vector<double> rates{nominal_rate};
  for (int s = 1; s <= steps; ++s) {
    rates.push_back(nominal_rate * (1.0 - s * options.rate_step));
    rates.push_back(nominal_rate * (1.0 + s * options.rate_step));
  }
  return rates;
}

// Correlations closer than this count as equal (their order is then the rates' order).
constexpr double kCorrelationTie = 1e-9;

// Prefix sums of the signal, its square and its unmeasured (NaN) samples.
struct SignalSums {
  std::vector<double> sum, squares;
  std::vector<int> missing;

  explicit SignalSums(const std::vector<double>& signal, int end) {
    sum.assign(end + 1, 0.0);
    squares.assign(end + 1, 0.0);
    missing.assign(end + 1, 0);
    for (int j = 0; j < end; ++j) {
      const double v = signal[j];
      const bool nan = std::isnan(v);
      sum[j + 1] = sum[j] + (nan ? 0.0 : v);
      squares[j + 1] = squares[j] + (nan ? 0.0 : v * v);
      missing[j + 1] = missing[j] + (nan ? 1 : 0);
    }
  }
};

double Correlation(const std::vector<double>& signal, const SignalSums& sums, const CodeTemplate& t, int shift) {
  const int n = static_cast<int>(t.values.size());
  const double sum = sums.sum[shift + n] - sums.sum[shift];
  const double squares = sums.squares[shift + n] - sums.squares[shift];
  const double variance = squares - sum * sum / n;
  if (!(variance > 1e-12) || !(t.norm > 0.0)) return 0.0;
  double dot = 0.0;
  for (int i = 0; i < n; ++i) dot += signal[shift + i] * t.values[i];
  return dot / (std::sqrt(variance) * t.norm);
}

// The same over the measured samples only (the template centred on those).
double CorrelationWithGaps(const std::vector<double>& signal, const CodeTemplate& t, int shift) {
  double n = 0, st = 0, stt = 0, ss = 0, sss = 0, sst = 0;
  for (std::size_t i = 0; i < t.values.size(); ++i) {
    const double v = signal[shift + i];
    if (std::isnan(v)) continue;
    const double u = t.values[i];
    n += 1;
    st += u;
    stt += u * u;
    ss += v;
    sss += v * v;
    sst += v * u;
  }
  if (n < 2) return 0.0;
  const double template_variance = stt - st * st / n;
  const double signal_variance = sss - ss * ss / n;
  if (!(signal_variance > 1e-12) || !(template_variance > 1e-12)) return 0.0;
  return (sst - st * ss / n) / std::sqrt(signal_variance * template_variance);
}

}  // namespace

void CodeSearchOptions::Check() const {
  Require(rate_search >= 0.0 && rate_search < 0.5, "rate_search must be in [0, 0.5)");
  Require(rate_step > 0.0, "rate_step must be positive");
  Require(rate_search <= kMaxCandidateRates * rate_step,
          "rate_step is too small for rate_search (more than " + std::to_string(kMaxCandidateRates) +
              " candidate rates)");
  Require(phases >= 1 && phases <= kMaxPhases, "phases must be in [1, " + std::to_string(kMaxPhases) + "]");
  Require(exposure > 0.0 && exposure <= 1.0, "exposure must be in (0, 1] camera frames");
  Require(max_missing_share >= 0.0 && max_missing_share < 0.9, "max_missing_share must be in [0, 0.9)");
  Require(detrend_frames >= 0 && detrend_frames <= 1000, "detrend_frames must be in [0, 1000]");
}

std::vector<double> Detrended(const std::vector<double>& values, int half_window) {
  const int n = static_cast<int>(values.size());
  if (half_window <= 0) return values;
  std::vector<double> sum(n + 1, 0.0);
  std::vector<int> count(n + 1, 0);
  for (int j = 0; j < n; ++j) {
    const bool measured = !std::isnan(values[j]);
    sum[j + 1] = sum[j] + (measured ? values[j] : 0.0);
    count[j + 1] = count[j] + (measured ? 1 : 0);
  }
  std::vector<double> out(n);
  for (int j = 0; j < n; ++j) {
    const int lo = std::max(0, j - half_window), hi = std::min(n, j + half_window + 1);
    const int measured = count[hi] - count[lo];
    out[j] = measured > 0 ? values[j] - (sum[hi] - sum[lo]) / measured : values[j];
  }
  return out;
}

std::vector<CodeTemplate> MakeCodeTemplates(const LightTimeline& timeline, const FrameWindow& window,
                                            double nominal_rate, const CodeSearchOptions& options) {
  options.Check();
  if (!(nominal_rate >= kMinNominalRate && nominal_rate <= kMaxNominalRate)) {
    throw std::invalid_argument("code search: the nominal rate (camera fps / projector fps) must be in [" +
                                limits::Number(kMinNominalRate) + ", " + limits::Number(kMaxNominalRate) +
                                "], got " + limits::Number(nominal_rate));
  }
  const double rates = 2.0 * std::floor(options.rate_search / options.rate_step + 1e-9) + 1.0;
  if (window.size() * nominal_rate * rates * options.phases > kMaxTemplateSamples) {
    throw std::invalid_argument("code search: a code window of " + std::to_string(window.size()) +
                                " frames at this rate, rate_search, rate_step and phases needs templates of more "
                                "than " + limits::Number(kMaxTemplateSamples) + " samples");
  }
  std::vector<CodeTemplate> templates;
  for (double rate : CandidateRates(nominal_rate, options)) {
    for (int p = 0; p < options.phases; ++p) {
      CodeTemplate t = MakeTemplate(timeline, window, rate, static_cast<double>(p) / options.phases, options.exposure);
      if (t.values.size() < 2) continue;
      if (options.detrend_frames > 0) Recentre(Detrended(t.values, options.detrend_frames), &t);
      templates.push_back(std::move(t));
    }
  }
  return templates;
}

CodeMatch SearchCode(const std::vector<double>& raw, const std::vector<CodeTemplate>& templates,
                     const FrameWindow& window, double exposure, double max_missing_share, int first_shift,
                     int end_shift, int detrend_frames) {
  const std::vector<double> signal = Detrended(raw, detrend_frames);
  const int end = static_cast<int>(signal.size());
  const int shift_limit = end_shift < 0 ? end : end_shift;
  const SignalSums sums(signal, end);
  CodeMatch best;
  for (const CodeTemplate& t : templates) {
    const int n = static_cast<int>(t.values.size());
    for (int shift = std::max(first_shift, 0); shift < shift_limit && shift + n <= end; ++shift) {
      const int missing = sums.missing[shift + n] - sums.missing[shift];
      if (missing > max_missing_share * n) continue;
      const double correlation =
          missing == 0 ? Correlation(signal, sums, t, shift) : CorrelationWithGaps(signal, t, shift);
      if (correlation > best.correlation + kCorrelationTie) {
        best.correlation = correlation;
        // Sample i = camera frame shift + i starts at window.begin + (i + phase) / rate.
        best.map = FrameMap{shift - t.phase - t.rate * window.begin, t.rate, exposure};
        best.first_sample = shift;
        best.sample_count = n;
      }
    }
  }
  return best;
}

CodeMatch SearchCode(const std::vector<double>& signal, const LightTimeline& timeline, const FrameWindow& window,
                     double nominal_rate, const CodeSearchOptions& options, int first_shift, int end_shift) {
  return SearchCode(signal, MakeCodeTemplates(timeline, window, nominal_rate, options), window, options.exposure,
                    options.max_missing_share, first_shift, end_shift, options.detrend_frames);
}

CodeTracker::CodeTracker(const LightTimeline& timeline, FrameWindow window, double nominal_rate,
                         CodeSearchOptions options, double min_correlation, int guard_samples)
    : window_(window),
      templates_(MakeCodeTemplates(timeline, window, nominal_rate, options)),
      exposure_(options.exposure),
      max_missing_share_(options.max_missing_share),
      detrend_frames_(options.detrend_frames),
      min_correlation_(min_correlation),
      guard_samples_(guard_samples) {
  for (const CodeTemplate& t : templates_) {
    longest_template_ = std::max(longest_template_, static_cast<int>(t.values.size()));
  }
}

bool CodeTracker::Update(const std::vector<double>& signal) {
  if (found_) return true;
  // Shifts where every candidate template fits, each sample's detrending window whole;
  // the next call starts where these end.
  const int complete_shifts = static_cast<int>(signal.size()) - longest_template_ + 1 - detrend_frames_;
  if (complete_shifts <= next_shift_) return false;
  const CodeMatch match = SearchCode(signal, templates_, window_, exposure_, max_missing_share_, next_shift_,
                                     complete_shifts, detrend_frames_);
  if (match.valid() && match.correlation > best_.correlation + kCorrelationTie) best_ = match;
  next_shift_ = complete_shifts;
  found_ = best_.valid() && best_.correlation >= min_correlation_ &&
           next_shift_ > best_.first_sample + guard_samples_;
  return found_;
}

}  // namespace calibproj::sync
