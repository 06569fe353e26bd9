#pragma once
// Synchronisation of one camera with the projection sequence from the start and end
// light codes found in its per-frame brightness signal.
//
// Each code is located coarsely by normalised cross-correlation over candidate rates
// (code_search.h) and to a fraction of a frame by a fit of the exposure-integrated
// light (code_fit.h). The two positions give the rate (so 29.97 fps cameras and clock
// drift are handled) and the offset; a final fit over both code windows refines the
// offset, rate and exposure together.

#include <string>
#include <vector>

#include "calibproj/sync/code_fit.h"
#include "calibproj/sync/code_search.h"
#include "calibproj/sync/frame_map.h"
#include "calibproj/sync/light_timeline.h"
#include "calibproj/sync/readout.h"

namespace calibproj::sync {

struct SyncOptions {
  CodeSearchOptions search;
  CodeFitOptions fit;
  // Normalised cross-correlation a code must reach to count as found.
  double min_correlation = 0.8;
  // Largest relative difference between the rate the two codes give and the nominal
  // rate (video fps / projector fps) before they count as disagreeing.
  double max_rate_deviation = 0.01;
  // Projector frames of known light (reference frames) used on either side of a code.
  int context_before = 30;
  int context_after = 6;
  // Shifts searched past the best one before an incremental search accepts it.
  int guard_samples = 4;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

// Where one code was found.
struct CodeLocation {
  double correlation = -1.0;  // best coarse correlation
  double frame = 0.0;         // camera frame where the code's first projector frame starts
  double uncertainty = 0.0;   // half-width of the equally good positions, camera frames
  FrameMap map;               // local fit (rate as searched)
  FrameMap window_map;        // covers every exposure window that fits (same rate)
  double rms = 0.0;           // fit residual RMS as a fraction of the code's contrast
  bool sharp = false;
};

struct SyncResult {
  FrameMap map;
  // Covers the exposure window of every map that fits the codes as well: the map to
  // decide which frames are clean.
  FrameMap window_map;
  CodeLocation start, end;
  double offset_uncertainty = 0.0;  // camera frames
  double rate_uncertainty = 0.0;    // camera frames per projector frame
  bool sharp = false;
  double rms = 0.0;  // joint fit residual as a fraction of the contrast
  // Rolling-shutter readout from bands of the image (readout.h), when measured; `map`
  // is then the first row's (the frame timestamp's) and `window_map` covers every row.
  ReadoutEstimate readout;
};

// The code's window of known light in the sequence.
FrameWindow CodeWindow(const LightTimeline& timeline, const LightCode& code, const SyncOptions& options);

// Locates one code in signal shifts [first_shift, end_shift) (-1: to the end) with the
// rate searched around `nominal_rate`. Throws std::runtime_error naming `source` and
// `what` ("start"/"end"), with the best correlation seen, when the code is not found.
CodeLocation LocateCode(const std::vector<double>& signal, const LightTimeline& timeline, const LightCode& code,
                        double nominal_rate, const SyncOptions& options, const std::string& source,
                        const std::string& what, int first_shift = 0, int end_shift = -1);

// Refines a coarse match of one code (from LocateCode or a CodeTracker) at the
// nominal rate: within one code window the rate is poorly determined (the coarse
// search's best candidate rate mostly follows the noise), across both codes it is not.
CodeLocation FitCode(const std::vector<double>& signal, const LightTimeline& timeline, const LightCode& code,
                     const CodeMatch& match, double nominal_rate, const SyncOptions& options);

// Full synchronisation from both codes. `signal[j]` is the mean brightness of camera
// frame j (NaN where not measured); `nominal_rate` = video fps / projector fps.
// Throws std::runtime_error naming `source` when a code is not found or the two
// codes disagree with each other or with the nominal rate.
SyncResult Synchronise(const std::vector<double>& signal, const LightTimeline& timeline, const LightCode& start,
                       const LightCode& end, double nominal_rate, const SyncOptions& options,
                       const std::string& source);

// Synchronisation from an already located start code: the end code is searched where
// the start code and the nominal rate put it, within max_rate_deviation.
SyncResult SynchroniseFromStart(const std::vector<double>& signal, const LightTimeline& timeline,
                                const LightCode& start, const LightCode& end, const CodeLocation& start_location,
                                double nominal_rate, const SyncOptions& options, const std::string& source);

}  // namespace calibproj::sync
