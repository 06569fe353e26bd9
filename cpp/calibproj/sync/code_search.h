#pragma once
// Coarse search of a light code in a camera's per-frame brightness signal: normalised
// cross-correlation against the brightness the camera would record, for a grid of
// candidate frame rates and sub-frame phases.
//
// For a candidate rate r (camera frames per projector frame) and phase p, the expected
// signal is the code window's light averaged over an exposure starting at projector
// times window.begin + (i + p) / r, i = 0, 1, ... (what a camera integrating over its
// exposure records, resampled at its own rate). Sliding it over the measured signal
// gives, at the best shift, the frame map up to a fraction of a frame.

#include <vector>

#include "calibproj/sync/frame_map.h"
#include "calibproj/sync/light_timeline.h"

namespace calibproj::sync {

struct CodeSearchOptions {
  // Candidate rates span nominal x (1 +- rate_search) in steps of rate_step (relative).
  // A step of 0.002 keeps the drift across a 100-frame code window under 0.2 frame.
  double rate_search = 0.02;
  double rate_step = 0.002;
  // Sub-frame phases tried per rate.
  int phases = 4;
  // Exposure assumed by the coarse model, in camera frames.
  double exposure = 0.5;
  // Share of a code window's camera frames that may be missing (dropped by the camera)
  // at a shift that is searched; the correlation is taken over the frames present.
  double max_missing_share = 0.25;
  // Signal and templates are compared after subtracting their mean over +- this many
  // camera frames (0: not at all): a camera whose automatic exposure is settling while
  // the code plays adds a slow drift that the code's fast changes stand out from.
  int detrend_frames = 8;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

// The zero-mean expected signal of a code window for one candidate rate and phase.
struct CodeTemplate {
  double rate = 1.0;
  double phase = 0.0;
  std::vector<double> values;
  double norm = 0.0;  // Euclidean norm of values
};

// Every candidate template of a code window.
std::vector<CodeTemplate> MakeCodeTemplates(const LightTimeline& timeline, const FrameWindow& window,
                                            double nominal_rate, const CodeSearchOptions& options);

struct CodeMatch {
  double correlation = -1.0;  // best normalised cross-correlation (-1 .. 1)
  FrameMap map;               // frame map of the best match (exposure as assumed)
  int first_sample = -1;      // first camera frame the match covers
  int sample_count = 0;       // camera frames it covers
  bool valid() const { return first_sample >= 0; }
};

// Searches `window` of `timeline` in `signal` over the candidate rates around
// `nominal_rate`, at shifts (first camera frame of the match) in [first_shift,
// end_shift) (end_shift < 0: every shift); only shifts whose samples all lie in the
// signal, at most max_missing_share of them unmeasured (NaN), count. Returns an
// invalid match when none fits.
CodeMatch SearchCode(const std::vector<double>& signal, const LightTimeline& timeline, const FrameWindow& window,
                     double nominal_rate, const CodeSearchOptions& options, int first_shift = 0,
                     int end_shift = -1);
CodeMatch SearchCode(const std::vector<double>& signal, const std::vector<CodeTemplate>& templates,
                     const FrameWindow& window, double exposure, double max_missing_share, int first_shift = 0,
                     int end_shift = -1, int detrend_frames = 0);

// `values` minus their mean over +- half_window neighbours (the measured ones; NaN
// stays NaN). Samples closer than half_window to the end use the neighbours there are.
std::vector<double> Detrended(const std::vector<double>& values, int half_window);

// Incremental search for one code while a video is being decoded: Update() looks at
// the shifts that became complete since its last call and keeps the best match. The
// code counts as found once the best correlation reaches `min_correlation` and the
// shifts up to `guard_samples` past the best one have been searched, so that a better
// peak cannot follow. Each shift is searched once, whatever the calling pattern.
class CodeTracker {
 public:
  CodeTracker(const LightTimeline& timeline, FrameWindow window, double nominal_rate, CodeSearchOptions options,
              double min_correlation, int guard_samples);

  // Returns true once the code is found.
  bool Update(const std::vector<double>& signal);
  bool found() const { return found_; }
  const CodeMatch& best() const { return best_; }

 private:
  FrameWindow window_;
  std::vector<CodeTemplate> templates_;
  double exposure_;
  double max_missing_share_;
  int detrend_frames_;
  int longest_template_ = 0;
  double min_correlation_;
  int guard_samples_;
  int next_shift_ = 0;
  CodeMatch best_;
  bool found_ = false;
};

}  // namespace calibproj::sync
