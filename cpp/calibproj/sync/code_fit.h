#pragma once
// Sub-frame fit of the frame map to the brightness a camera recorded around light codes.
//
// Model: camera frame j records a_w + b_w * W_j, where W_j is the projector light
// averaged over the frame's exposure [t_j, t_j + exposure / rate), t_j = (j - offset) /
// rate, and (a_w, b_w) are the black level and contrast of code window w (fitted
// separately: brightness may change between the start and the end of a recording;
// with gain_drift each drifts linearly across its window, as the gain of a camera with
// automatic exposure does).
// Frames whose exposure straddles a light change record a blend, which fixes the
// offset to a small fraction of a frame.
//
// Every (offset, exposure) whose cost is within a noise-based tolerance of the best
// explains the signal as well: with few frames across light changes these form a
// valley, and when no frame straddles a change (camera and projector at the same rate,
// short exposure) a plateau. When that set is narrow the fit reports the least-squares
// point; otherwise the centre of the set's offsets, with the half-width as the
// uncertainty. It also reports a conservative map whose exposure window covers the
// window of every point of the set (for picking clean frames).

#include <optional>
#include <vector>

#include "calibproj/sync/frame_map.h"
#include "calibproj/sync/light_timeline.h"

namespace calibproj::sync {

struct CodeFitOptions {
  // Offsets searched around the initial map, +- offset_range camera frames in steps.
  double offset_range = 1.0;
  double offset_step = 0.02;
  // Exposures searched (camera frames), from min_exposure to max_exposure in steps.
  double min_exposure = 0.02;
  double max_exposure = 1.0;
  int exposure_steps = 50;
  // Known exposure (camera frames), or 0 to fit it. Where every light change falls at
  // the same phase of the camera's frames (camera and projector at the same rate, or
  // one a multiple of the other), a frame across a change gives only the share of its
  // exposure on either side: the offset is then fixed only if the exposure is known.
  double fixed_exposure = 0.0;
  // Points whose cost exceeds the best by less than feasible_chi2 times the residual
  // variance per frame (or plateau_tolerance times the signal's variance, whichever is
  // larger) fit as well as the best.
  double feasible_chi2 = 9.0;
  double plateau_tolerance = 1e-6;
  int max_iterations = 50;
  // Black level and contrast of each window drift linearly in time (a camera adjusting
  // its gain during a code); false: constant per window.
  bool gain_drift = true;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

struct CodeFit {
  FrameMap map;
  // Every exposure window that fits lies inside this map's window (same rate).
  FrameMap window_map;
  // Largest offset difference (camera frames) to a point that fits as well.
  double offset_uncertainty = 0.0;
  // The offsets that fit span at most two grid steps (frames straddle light changes).
  bool sharp = false;
  double rms = 0.0;                  // residual RMS as a fraction of the contrast b
  double contrast = 0.0;             // smallest fitted contrast b over the windows
  int samples = 0;
};

// Fits the offset and the exposure (and the rate when `fit_rate`) to the signal over
// the given code windows, starting from `initial` (its rate is kept unless fit_rate).
// Throws std::runtime_error when a window holds fewer than 4 measured frames.
CodeFit FitCodeWindows(const std::vector<double>& signal, const LightTimeline& timeline,
                       const std::vector<FrameWindow>& windows, const FrameMap& initial, bool fit_rate,
                       const CodeFitOptions& options);

// The fit of each of several signals, as FitCodeWindows gives it, or none for a signal
// whose windows hold fewer than 4 measured frames. Signals measured on the same frames
// (the bands of one camera's frames) share the search's predictions of the light, most
// of a fit's work.
std::vector<std::optional<CodeFit>> FitCodeWindowsOfSignals(const std::vector<std::vector<double>>& signals,
                                                            const LightTimeline& timeline,
                                                            const std::vector<FrameWindow>& windows,
                                                            const FrameMap& initial, bool fit_rate,
                                                            const CodeFitOptions& options);

}  // namespace calibproj::sync
