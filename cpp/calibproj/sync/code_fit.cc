#include "calibproj/sync/code_fit.h"

#include <ceres/ceres.h>

#include <Eigen/Cholesky>
#include <Eigen/Core>

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>

#include "calibproj/common/limits.h"

namespace calibproj::sync {

namespace {

// Bounds of the fit's grid and iterations, far above the defaults (50 offsets, 50
// exposures, 50 iterations), so that a bad option cannot make it loop without limit.
constexpr int kMaxOffsetSteps = 100'000;
constexpr int kMaxExposureSteps = 5'000;
constexpr int kMaxFitIterations = 10'000;
// Points of the (offset, exposure) grid at most: the search keeps each signal's cost at
// every point (8 bytes each).
constexpr double kMaxGridPoints = 2'000'000;

// A starting map that places the windows on camera frames an int can count, and
// windows inside the timeline.
void CheckFitInputs(const std::vector<double>& signal, const LightTimeline& timeline,
                    const std::vector<FrameWindow>& windows, const FrameMap& initial) {
  if (signal.size() > static_cast<std::size_t>(limits::kMaxFrames)) {
    throw std::invalid_argument("code fit: the signal has more than " + std::to_string(limits::kMaxFrames) + " frames");
  }
  limits::RequireInRange(initial.offset, -limits::kMaxFrames, limits::kMaxFrames, "code fit: map offset");
  limits::RequireInRange(initial.rate, 1e-3, 1e3, "code fit: map rate");
  limits::RequireInRange(initial.exposure, 0.0, limits::kMaxFrames, "code fit: map exposure");
  for (const FrameWindow& window : windows) {
    if (window.begin < 0 || window.end > timeline.frame_count() || window.begin >= window.end) {
      throw std::invalid_argument("code fit: window of frames " + std::to_string(window.begin) + ".." +
                                  std::to_string(window.end - 1) + " outside the projector's " +
                                  std::to_string(timeline.frame_count()) + " frames");
    }
  }
}

void Require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument("code fit options: " + message);
}

struct Sample {
  int frame;
  double value;
  double tau = 0.0;  // position in its window, -1 (first sample) .. 1 (last)
};

// Black level and contrast of a window, each a + slope * tau when the gain drifts.
using Levels = std::array<double, 4>;  // a, a_slope, b, b_slope

// Frames of one window that stay inside it for every offset and exposure searched.
std::vector<Sample> WindowSamples(const std::vector<double>& signal, const FrameWindow& window, const FrameMap& map,
                                  const CodeFitOptions& options) {
  const double first = map.offset + options.offset_range + map.rate * window.begin;
  const double longest = options.fixed_exposure > 0.0 ? options.fixed_exposure : options.max_exposure;
  const double last = map.offset - options.offset_range - longest + map.rate * window.end;
  std::vector<Sample> samples;
  const int begin = std::max(0, static_cast<int>(std::ceil(first)));
  const int end = std::min(static_cast<int>(signal.size()) - 1, static_cast<int>(std::floor(last)));
  const double centre = 0.5 * (begin + end), half = std::max(0.5 * (end - begin), 1.0);
  for (int j = begin; j <= end; ++j) {
    if (!std::isnan(signal[j])) samples.push_back({j, signal[j], (j - centre) / half});
  }
  return samples;
}

// The sums of a window's samples that no offset or exposure changes.
struct WindowSums {
  double count = 0.0, tau = 0.0, tau_tau = 0.0;  // sums of 1, tau, tau^2
  double value = 0.0, tau_value = 0.0, value_value = 0.0;

  explicit WindowSums(const std::vector<Sample>& samples) {
    for (const Sample& s : samples) {
      count += 1.0;
      tau += s.tau;
      tau_tau += s.tau * s.tau;
      value += s.value;
      tau_value += s.tau * s.value;
      value_value += s.value * s.value;
    }
  }
};

// The light W_j each sample saw at one (offset, exposure), and what the fit's normal
// equations take from it alone. Signals measured on the same frames (the bands of one
// camera's frames) share it: the light is looked up once, the fit is then solved per
// signal from its own values.
class Prediction {
 public:
  Prediction(const LightTimeline& timeline, bool gain_drift) : timeline_(timeline), gain_drift_(gain_drift) {}

  // `sums` are those of `windows`, of any of the signals: the terms without values are
  // alike for all of them.
  void Evaluate(const std::vector<std::vector<Sample>>& windows, const std::vector<WindowSums>& sums,
                const FrameMap& map) {
    const double duration = map.ProjectorExposure();
    windows_.resize(windows.size());
    for (std::size_t k = 0; k < windows.size(); ++k) {
      Window& window = windows_[k];
      window.light.resize(windows[k].size());
      for (std::size_t i = 0; i < windows[k].size(); ++i) {
        window.light[i] = timeline_.Average(map.ProjectorTime(windows[k][i].frame), duration);
      }
      if (gain_drift_) {
        SumDrift(windows[k], sums[k], &window);
      } else {
        SumLinear(&window);
      }
    }
  }

  // Sum of squares of the best fit to `windows` (the samples evaluated, with one
  // signal's values).
  double Cost(const std::vector<std::vector<Sample>>& windows, const std::vector<WindowSums>& sums) const {
    double total = 0.0;
    for (std::size_t k = 0; k < windows.size(); ++k) {
      total += gain_drift_ ? DriftCost(windows_[k], windows[k], sums[k]) : LinearCost(windows_[k], windows[k], sums[k]);
    }
    return total;
  }

 private:
  struct Window {
    std::vector<double> light;
    double w_sum = 0, tw_sum = 0, t_tw = 0, w_w = 0, w_tw = 0, tw_tw = 0;
    Eigen::LDLT<Eigen::Matrix4d> solver;
    bool solvable = false;
  };

  // (a + a' tau) + (b + b' tau) W: a camera adjusting its gain during the code scales
  // both levels alike. The normal equations of the basis (1, tau, W, tau W): what does
  // not depend on W comes from the window's sums.
  static void SumDrift(const std::vector<Sample>& samples, const WindowSums& sums, Window* window) {
    double w_sum = 0, tw_sum = 0, t_tw = 0, w_w = 0, w_tw = 0, tw_tw = 0;
    for (std::size_t i = 0; i < samples.size(); ++i) {
      const double w = window->light[i];
      const double tw = samples[i].tau * w;
      w_sum += w;
      tw_sum += tw;
      t_tw += samples[i].tau * tw;
      w_w += w * w;
      w_tw += w * tw;
      tw_tw += tw * tw;
    }
    window->w_sum = w_sum, window->tw_sum = tw_sum, window->t_tw = t_tw;
    window->w_w = w_w, window->w_tw = w_tw, window->tw_tw = tw_tw;
    Eigen::Matrix4d normal;
    normal << sums.count, sums.tau, w_sum, tw_sum,  //
        sums.tau, sums.tau_tau, tw_sum, t_tw,       //
        w_sum, tw_sum, w_w, w_tw,                   //
        tw_sum, t_tw, w_tw, tw_tw;
    window->solver.compute(normal);
    window->solvable = window->solver.info() == Eigen::Success && window->solver.rcond() > 1e-12;
  }

  static double DriftCost(const Window& window, const std::vector<Sample>& samples, const WindowSums& sums) {
    if (!window.solvable) return std::numeric_limits<double>::infinity();
    double w_value = 0, tw_value = 0;
    for (std::size_t i = 0; i < samples.size(); ++i) {
      const double w = window.light[i];
      w_value += w * samples[i].value;
      tw_value += samples[i].tau * w * samples[i].value;
    }
    const Eigen::Vector4d right(sums.value, sums.tau_value, w_value, tw_value);
    const Eigen::Vector4d theta = window.solver.solve(right);
    return std::max(0.0, sums.value_value - theta.dot(right));
  }

  // a + b W, constant levels.
  static void SumLinear(Window* window) {
    double sw = 0, sww = 0;
    for (const double w : window->light) {
      sw += w;
      sww += w * w;
    }
    window->w_sum = sw, window->w_w = sww;
  }

  static double LinearCost(const Window& window, const std::vector<Sample>& samples, const WindowSums& sums) {
    double swm = 0;
    for (std::size_t i = 0; i < samples.size(); ++i) swm += window.light[i] * samples[i].value;
    const double n = static_cast<double>(samples.size()), sw = window.w_sum, sww = window.w_w;
    const double sm = sums.value, smm = sums.value_value;
    const double denominator = n * sww - sw * sw;
    const double b = denominator > 1e-12 * n * n ? (n * swm - sw * sm) / denominator : 0.0;
    const double a = (sm - b * sw) / n;
    return std::max(0.0, smm - a * sm - b * swm);
  }

  const LightTimeline& timeline_;
  bool gain_drift_;
  std::vector<Window> windows_;
};

double SampleVariance(const std::vector<std::vector<Sample>>& windows) {
  double total = 0.0;
  for (const auto& samples : windows) {
    double mean = 0.0;
    for (const Sample& s : samples) mean += s.value;
    mean /= static_cast<double>(samples.size());
    for (const Sample& s : samples) total += (s.value - mean) * (s.value - mean);
  }
  return total;
}

// Residual (a + a' tau) + (b + b' tau) * W_j - value_j of one camera frame, with
// analytic derivatives with respect to (offset, rate, exposure) and the levels.
class SampleCost : public ceres::SizedCostFunction<1, 3, 4> {
 public:
  SampleCost(const LightTimeline& timeline, Sample sample) : timeline_(timeline), sample_(sample) {}

  bool Evaluate(double const* const* parameters, double* residual, double** jacobians) const override {
    const double offset = parameters[0][0], rate = parameters[0][1], exposure = parameters[0][2];
    const double a = parameters[1][0] + parameters[1][1] * sample_.tau;
    const double b = parameters[1][2] + parameters[1][3] * sample_.tau;
    const double t = (sample_.frame - offset) / rate;
    const double duration = exposure / rate;
    const double w = timeline_.Average(t, duration);
    residual[0] = a + b * w - sample_.value;
    // A step that moves the exposure onto frames of unknown light: Ceres rejects it. The
    // ends of the exposure are checked with the cost alone too: a step accepted on its
    // cost whose Jacobian then fails ends the solve (with an error on stderr).
    const double level_start = timeline_.LevelAt(t), level_end = timeline_.LevelAt(t + duration);
    if (!std::isfinite(residual[0]) || !std::isfinite(level_start) || !std::isfinite(level_end)) return false;
    if (jacobians == nullptr) return true;
    if (jacobians[0] != nullptr) {
      const double dw_dt = (level_end - level_start) / duration;
      const double dw_dduration = (level_end - w) / duration;
      jacobians[0][0] = b * dw_dt * (-1.0 / rate);
      jacobians[0][1] = b * (dw_dt * (-t / rate) + dw_dduration * (-duration / rate));
      jacobians[0][2] = b * dw_dduration / rate;
    }
    if (jacobians[1] != nullptr) {
      jacobians[1][0] = 1.0;
      jacobians[1][1] = sample_.tau;
      jacobians[1][2] = w;
      jacobians[1][3] = sample_.tau * w;
    }
    return true;
  }

 private:
  const LightTimeline& timeline_;
  Sample sample_;
};

std::vector<double> ExposureGrid(const CodeFitOptions& options) {
  if (options.fixed_exposure > 0.0) return {options.fixed_exposure};
  std::vector<double> exposures;
  for (int e = 0; e < options.exposure_steps; ++e) {
    const double share = options.exposure_steps > 1 ? static_cast<double>(e) / (options.exposure_steps - 1) : 1.0;
    exposures.push_back(options.min_exposure + share * (options.max_exposure - options.min_exposure));
  }
  return exposures;
}

// The set of (offset, exposure) that fit as well as the best one.
struct FeasibleSet {
  FrameMap best;            // lowest cost found
  double offset_low = 0.0;  // offsets of the set
  double offset_high = 0.0;
  double exposure_low = 0.0;  // exposures of the set
  double exposure_high = 0.0;
  double latest_end = 0.0;  // largest exposure - offset in the set (end of the latest window)
};

// The cost of one signal's windows over (offset, exposure) at a fixed rate.
class CostSurface {
 public:
  CostSurface(const LightTimeline& timeline, const std::vector<std::vector<Sample>>& windows, double rate,
              bool gain_drift)
      : windows_(windows), rate_(rate), prediction_(timeline, gain_drift) {
    for (const auto& samples : windows_) sums_.emplace_back(samples);
  }

  double operator()(double offset, double exposure) const {
    prediction_.Evaluate(windows_, sums_, FrameMap{offset, rate_, exposure});
    return prediction_.Cost(windows_, sums_);
  }

  // The cost of this surface from a prediction evaluated on the same frames.
  double CostOf(const Prediction& prediction) const { return prediction.Cost(windows_, sums_); }

  // Whether `other` holds the same frames at the same places in their windows: one
  // prediction then serves both.
  bool SameFrames(const CostSurface& other) const {
    if (windows_.size() != other.windows_.size()) return false;
    for (std::size_t k = 0; k < windows_.size(); ++k) {
      const auto& mine = windows_[k];
      const auto& theirs = other.windows_[k];
      if (mine.size() != theirs.size()) return false;
      for (std::size_t i = 0; i < mine.size(); ++i) {
        if (mine[i].frame != theirs[i].frame || mine[i].tau != theirs[i].tau) return false;
      }
    }
    return true;
  }

  const std::vector<std::vector<Sample>>& windows() const { return windows_; }
  const std::vector<WindowSums>& sums() const { return sums_; }

  // Minimum over offsets in [low, high] (golden-section search).
  std::pair<double, double> MinimiseOffset(double low, double high, double exposure) const {
    constexpr double kInverseGolden = 0.6180339887498949;
    constexpr int kIterations = 24;
    double a = low, b = high;
    // Each step keeps one inner point, and its cost, for the next.
    double x1 = b - kInverseGolden * (b - a), x2 = a + kInverseGolden * (b - a);
    double f1 = (*this)(x1, exposure), f2 = (*this)(x2, exposure);
    for (int i = 0; i < kIterations; ++i) {
      if (f1 <= f2) {
        b = x2, x2 = x1, f2 = f1;
        x1 = b - kInverseGolden * (b - a);
        f1 = (*this)(x1, exposure);
      } else {
        a = x1, x1 = x2, f1 = f2;
        x2 = a + kInverseGolden * (b - a);
        f2 = (*this)(x2, exposure);
      }
    }
    const double offset = 0.5 * (a + b);
    return {offset, (*this)(offset, exposure)};
  }

  // Last offset from `inside` towards `outside` whose cost stays under `threshold`.
  double Boundary(double inside, double outside, double exposure, double threshold) const {
    constexpr int kIterations = 16;
    for (int i = 0; i < kIterations; ++i) {
      const double middle = 0.5 * (inside + outside);
      ((*this)(middle, exposure) <= threshold ? inside : outside) = middle;
    }
    return inside;
  }

 private:
  const std::vector<std::vector<Sample>>& windows_;
  std::vector<WindowSums> sums_;
  double rate_;
  mutable Prediction prediction_;  // scratch of operator()
};

// The offsets and exposures searched around an initial map.
struct Grid {
  Grid(const FrameMap& initial, const CodeFitOptions& options)
      : initial(initial),
        step(options.offset_step),
        offsets(2 * static_cast<int>(std::round(options.offset_range / options.offset_step)) + 1),
        exposures(ExposureGrid(options)) {}

  double OffsetAt(int i) const { return initial.offset + (i - offsets / 2) * step; }

  FrameMap initial;
  double step;
  int offsets;
  std::vector<double> exposures;
};

// One surface's cost at every point of the grid.
class GridCosts {
 public:
  explicit GridCosts(const Grid& grid) : offsets_(grid.offsets), costs_(grid.exposures.size() * grid.offsets) {}

  double& at(std::size_t exposure, int offset) { return costs_[exposure * offsets_ + offset]; }
  double at(std::size_t exposure, int offset) const { return costs_[exposure * offsets_ + offset]; }

  // The first offset index of lowest cost at one exposure, and that cost.
  std::pair<int, double> Minimum(std::size_t exposure) const {
    int index = 0;
    double lowest = std::numeric_limits<double>::infinity();
    for (int i = 0; i < offsets_; ++i) {
      if (at(exposure, i) < lowest) lowest = at(exposure, i), index = i;
    }
    return {index, lowest};
  }

 private:
  int offsets_;
  std::vector<double> costs_;
};

// Every surface's cost over the grid. Surfaces on the same frames as the first share
// its prediction: this scan is most of a fit's work, and the light each frame saw is the
// same for every band of a frame.
std::vector<GridCosts> ScanGrid(const LightTimeline& timeline, const std::vector<const CostSurface*>& surfaces,
                                const Grid& grid, bool gain_drift) {
  std::vector<GridCosts> costs(surfaces.size(), GridCosts(grid));
  Prediction prediction(timeline, gain_drift);
  const CostSurface& first = *surfaces.front();
  for (std::size_t e = 0; e < grid.exposures.size(); ++e) {
    for (int i = 0; i < grid.offsets; ++i) {
      prediction.Evaluate(first.windows(), first.sums(),
                          FrameMap{grid.OffsetAt(i), grid.initial.rate, grid.exposures[e]});
      for (std::size_t s = 0; s < surfaces.size(); ++s) costs[s].at(e, i) = surfaces[s]->CostOf(prediction);
    }
  }
  return costs;
}

// From `start` (inside the set) along the grid's offsets in `direction`: the last offset
// whose cost stays under `threshold` and the first beyond it (a step past the grid's
// end when the set reaches it).
std::pair<double, double> LastInside(const Grid& grid, const GridCosts& costs, std::size_t exposure, double start,
                                     int direction, double threshold) {
  // The first grid offset strictly beyond `start`.
  const double position = (start - grid.OffsetAt(0)) / grid.step;
  int i = static_cast<int>(direction < 0 ? std::ceil(position) - 1 : std::floor(position) + 1);
  i = std::clamp(i, -1, grid.offsets);
  double inside = start;
  while (i >= 0 && i < grid.offsets && costs.at(exposure, i) <= threshold) {
    inside = grid.OffsetAt(i);
    i += direction;
  }
  return {inside, grid.OffsetAt(i)};
}

// Profiles the cost over offsets for every exposure of the grid, then bounds the set
// of points within the tolerance of the best: on each feasible exposure, the offsets
// are followed outwards on the grid and the edges located by bisection.
FeasibleSet ExploreCost(const CostSurface& cost, const Grid& grid, const GridCosts& costs,
                        const CodeFitOptions& options) {
  const std::vector<std::vector<Sample>>& windows = cost.windows();
  const FrameMap& initial = grid.initial;
  const std::vector<double>& exposures = grid.exposures;
  std::vector<double> best_offset(exposures.size()), best_cost(exposures.size());
  FeasibleSet set;
  double minimum = std::numeric_limits<double>::infinity();
  for (std::size_t e = 0; e < exposures.size(); ++e) {
    const auto [best_index, lowest] = costs.Minimum(e);
    const auto [offset, refined] = cost.MinimiseOffset(grid.OffsetAt(std::max(best_index - 1, 0)),
                                                       grid.OffsetAt(std::min(best_index + 1, grid.offsets - 1)),
                                                       exposures[e]);
    best_offset[e] = refined <= lowest ? offset : grid.OffsetAt(best_index);
    best_cost[e] = std::min(refined, lowest);
    if (best_cost[e] < minimum) {
      minimum = best_cost[e];
      set.best = FrameMap{best_offset[e], initial.rate, exposures[e]};
    }
  }
  int samples = 0;
  for (const auto& w : windows) samples += static_cast<int>(w.size());
  const int parameters = 2 + (options.gain_drift ? 4 : 2) * static_cast<int>(windows.size());
  const double noise_variance = minimum / std::max(1, samples - parameters);
  const double threshold = minimum + std::max(options.feasible_chi2 * noise_variance,
                                              options.plateau_tolerance * std::max(SampleVariance(windows), 1e-300));
  set.offset_low = set.exposure_low = set.latest_end = std::numeric_limits<double>::infinity();
  set.offset_high = set.exposure_high = -set.offset_low;
  set.latest_end = -set.offset_low;
  for (std::size_t e = 0; e < exposures.size(); ++e) {
    if (best_cost[e] > threshold) continue;
    const double exposure = exposures[e];
    const auto [low_inside, low_outside] = LastInside(grid, costs, e, best_offset[e], -1, threshold);
    const auto [high_inside, high_outside] = LastInside(grid, costs, e, best_offset[e], +1, threshold);
    const double low = cost.Boundary(low_inside, low_outside, exposure, threshold);
    const double high = cost.Boundary(high_inside, high_outside, exposure, threshold);
    set.offset_low = std::min(set.offset_low, low);
    set.offset_high = std::max(set.offset_high, high);
    set.exposure_low = std::min(set.exposure_low, exposure);
    set.exposure_high = std::max(set.exposure_high, exposure);
    set.latest_end = std::max(set.latest_end, exposure - low);
  }
  return set;
}

// Least-squares refinement of (offset, rate, exposure) and each window's (a, b).
FrameMap Refine(const LightTimeline& timeline, const std::vector<std::vector<Sample>>& windows, const FrameMap& start,
                bool fit_rate, const CodeFitOptions& options, double* rms, double* contrast) {
  double map[3] = {start.offset, start.rate, start.exposure};
  std::vector<Levels> levels(windows.size(), {0.0, 0.0, 1.0, 0.0});
  ceres::Problem problem;
  problem.AddParameterBlock(map, 3);
  for (std::size_t w = 0; w < windows.size(); ++w) {
    // Start (a, b) at the window's darkest and brightest samples.
    double low = std::numeric_limits<double>::infinity(), high = -low;
    for (const Sample& s : windows[w]) {
      low = std::min(low, s.value);
      high = std::max(high, s.value);
    }
    levels[w] = {low, 0.0, high - low, 0.0};
    for (const Sample& s : windows[w]) {
      problem.AddResidualBlock(new SampleCost(timeline, s), nullptr, map, levels[w].data());
    }
    if (!options.gain_drift) problem.SetManifold(levels[w].data(), new ceres::SubsetManifold(4, {1, 3}));
  }
  std::vector<int> constant;
  if (!fit_rate) constant.push_back(1);
  if (options.fixed_exposure > 0.0) constant.push_back(2);
  if (!constant.empty()) problem.SetManifold(map, new ceres::SubsetManifold(3, constant));
  if (options.fixed_exposure <= 0.0) {
    problem.SetParameterLowerBound(map, 2, options.min_exposure);
    problem.SetParameterUpperBound(map, 2, options.max_exposure);
  }
  ceres::Solver::Options solver;
  solver.linear_solver_type = ceres::DENSE_QR;
  solver.max_num_iterations = options.max_iterations;
  solver.num_threads = 1;
  solver.logging_type = ceres::SILENT;
  int samples = 0;
  *contrast = std::numeric_limits<double>::infinity();
  for (std::size_t w = 0; w < windows.size(); ++w) samples += static_cast<int>(windows[w].size());
  // A start whose exposures reach frames of unknown light cannot be refined (Ceres would
  // log the failed evaluation): it is returned as it is, with an infinite residual. The
  // Jacobian is evaluated too: it needs the light at both ends of every exposure.
  double cost = 0.0;
  ceres::CRSMatrix jacobian;
  if (!problem.Evaluate(ceres::Problem::EvaluateOptions(), &cost, nullptr, nullptr, &jacobian) ||
      !std::isfinite(cost)) {
    *rms = std::numeric_limits<double>::infinity();
    for (const auto& level : levels) *contrast = std::min(*contrast, level[2]);
    return start;
  }
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);
  for (const auto& level : levels) *contrast = std::min(*contrast, level[2]);
  *rms = std::sqrt(2.0 * summary.final_cost / samples) / std::max(std::abs(*contrast), 1e-12);
  return FrameMap{map[0], map[1], map[2]};
}

// The samples of `signal` in each window, or an error when a window holds too few.
std::vector<std::vector<Sample>> SamplesOf(const std::vector<double>& signal, const std::vector<FrameWindow>& windows,
                                           const FrameMap& initial, const CodeFitOptions& options,
                                           std::string* error) {
  std::vector<std::vector<Sample>> samples;
  for (const FrameWindow& window : windows) {
    samples.push_back(WindowSamples(signal, window, initial, options));
    if (samples.back().size() < 4) {
      *error = "light code window of projector frames " + std::to_string(window.begin) + ".." +
               std::to_string(window.end - 1) + " holds only " + std::to_string(samples.back().size()) +
               " measured camera frames";
      return {};
    }
  }
  return samples;
}

// The fit of one signal from its surface and its grid scan.
CodeFit FitSurface(const CostSurface& surface, const LightTimeline& timeline, const Grid& grid,
                   const GridCosts& costs, bool fit_rate, const CodeFitOptions& options) {
  const std::vector<std::vector<Sample>>& samples = surface.windows();
  const FeasibleSet set = ExploreCost(surface, grid, costs, options);
  double rms = 0.0, contrast = 0.0;
  const FrameMap refined = Refine(timeline, samples, set.best, fit_rate, options, &rms, &contrast);
  CodeFit fit;
  const double half_width = 0.5 * (set.offset_high - set.offset_low);
  fit.sharp = half_width <= options.offset_step;
  // A narrow set: least squares gives the best point (a result outside the set, a far
  // local minimum, is not taken). A wide one (few or no frames across light changes):
  // its centre, which is off by at most the half-width whatever the truth.
  const bool inside = refined.offset >= set.offset_low - options.offset_step &&
                      refined.offset <= set.offset_high + options.offset_step;
  if (fit.sharp && inside) {
    fit.map = refined;
  } else {
    fit.map = FrameMap{0.5 * (set.offset_low + set.offset_high), refined.rate,
                       0.5 * (set.exposure_low + set.exposure_high)};
  }
  fit.offset_uncertainty =
      std::max(fit.map.offset - set.offset_low, set.offset_high - fit.map.offset) + 0.5 * options.offset_step;
  // Latest start and latest end of any window that fits, with half a step of slack.
  const double slack = 0.5 * options.offset_step;
  fit.window_map = FrameMap{set.offset_high + slack, fit.map.rate, set.latest_end + set.offset_high + 2.0 * slack};
  fit.rms = rms;
  fit.contrast = contrast;
  for (const auto& window : samples) fit.samples += static_cast<int>(window.size());
  return fit;
}

}  // namespace

void CodeFitOptions::Check() const {
  Require(offset_range > 0.0 && std::isfinite(offset_range), "offset_range must be positive");
  Require(offset_step > 0.0 && offset_step <= offset_range, "offset_step must be in (0, offset_range]");
  Require(offset_range <= kMaxOffsetSteps * offset_step,
          "offset_step is too small for offset_range (more than " + std::to_string(kMaxOffsetSteps) + " offsets)");
  Require(min_exposure > 0.0 && min_exposure <= max_exposure && max_exposure <= 1.0,
          "exposures must satisfy 0 < min_exposure <= max_exposure <= 1");
  Require(exposure_steps >= 1 && exposure_steps <= kMaxExposureSteps,
          "exposure_steps must be in [1, " + std::to_string(kMaxExposureSteps) + "]");
  // The readout's band fits search a frame further.
  const double offsets = 2.0 * std::round((offset_range + 1.0) / offset_step) + 1.0;
  Require(offsets * (fixed_exposure > 0.0 ? 1 : exposure_steps) <= kMaxGridPoints,
          "offset_range / offset_step and exposure_steps make more than 2000000 (offset, exposure) points to "
          "search (with the frame more that a rolling shutter's bands search)");
  Require(fixed_exposure >= 0.0 && std::isfinite(fixed_exposure), "fixed_exposure must be non-negative (0: fit it)");
  Require(feasible_chi2 >= 0.0 && std::isfinite(feasible_chi2), "feasible_chi2 must be non-negative");
  Require(plateau_tolerance >= 0.0 && std::isfinite(plateau_tolerance), "plateau_tolerance must be non-negative");
  Require(max_iterations >= 1 && max_iterations <= kMaxFitIterations,
          "max_iterations must be in [1, " + std::to_string(kMaxFitIterations) + "]");
}

CodeFit FitCodeWindows(const std::vector<double>& signal, const LightTimeline& timeline,
                       const std::vector<FrameWindow>& windows, const FrameMap& initial, bool fit_rate,
                       const CodeFitOptions& options) {
  options.Check();
  CheckFitInputs(signal, timeline, windows, initial);
  std::string error;
  const std::vector<std::vector<Sample>> samples = SamplesOf(signal, windows, initial, options, &error);
  if (!error.empty()) throw std::runtime_error(error);
  const CostSurface surface(timeline, samples, initial.rate, options.gain_drift);
  const Grid grid(initial, options);
  const std::vector<GridCosts> costs = ScanGrid(timeline, {&surface}, grid, options.gain_drift);
  return FitSurface(surface, timeline, grid, costs.front(), fit_rate, options);
}

std::vector<std::optional<CodeFit>> FitCodeWindowsOfSignals(const std::vector<std::vector<double>>& signals,
                                                            const LightTimeline& timeline,
                                                            const std::vector<FrameWindow>& windows,
                                                            const FrameMap& initial, bool fit_rate,
                                                            const CodeFitOptions& options) {
  options.Check();
  for (const auto& signal : signals) CheckFitInputs(signal, timeline, windows, initial);
  std::vector<std::vector<std::vector<Sample>>> samples(signals.size());
  std::vector<std::unique_ptr<CostSurface>> surfaces(signals.size());
  for (std::size_t s = 0; s < signals.size(); ++s) {
    std::string error;
    samples[s] = SamplesOf(signals[s], windows, initial, options, &error);
    if (error.empty()) surfaces[s] = std::make_unique<CostSurface>(timeline, samples[s], initial.rate, options.gain_drift);
  }
  const Grid grid(initial, options);
  std::vector<std::optional<CodeFit>> fits(signals.size());
  std::vector<bool> done(signals.size(), false);
  for (std::size_t s = 0; s < signals.size(); ++s) {
    if (!surfaces[s] || done[s]) continue;
    // This signal and every later one measured on the same frames, scanned together.
    std::vector<std::size_t> group;
    std::vector<const CostSurface*> members;
    for (std::size_t t = s; t < signals.size(); ++t) {
      if (surfaces[t] && !done[t] && surfaces[t]->SameFrames(*surfaces[s])) {
        group.push_back(t);
        members.push_back(surfaces[t].get());
        done[t] = true;
      }
    }
    const std::vector<GridCosts> costs = ScanGrid(timeline, members, grid, options.gain_drift);
    for (std::size_t m = 0; m < group.size(); ++m) {
      fits[group[m]] = FitSurface(*members[m], timeline, grid, costs[m], fit_rate, options);
    }
  }
  return fits;
}

}  // namespace calibproj::sync
