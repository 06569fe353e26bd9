#pragma once
// Rolling-shutter readout from the light codes as horizontal bands of the image see them.
//
// Row y of h starts its exposure readout * y / h camera frames after the first row.
// Each band of rows is fitted as a camera of its own (code_fit.h) at the frame map's
// rate: the band's offset falls linearly with its centre row, offset_b = offset_0 -
// readout * (y_b / h). A line through the bands whose fit is sharp gives the readout,
// the first row's offset (the frame map of the frame's timestamp) and their
// uncertainties. A global shutter gives a readout near 0.
//
// Where the camera's frames keep a few fixed phases to the projector's (25 fps against
// 30), a band sees a light change within a frame only at some rows, and how far into
// its exposure tells the readout only relative to the exposure: with the exposure
// unknown, many readouts explain the codes. Every band that shows the codes bounds its
// offset to the interval of offsets that fit it; the readouts for which one line meets
// every interval are the feasible range, and the reported sigma is never below that
// range's (as a uniform interval's). A known exposure (fixed_exposure) narrows it.

#include <vector>

#include "calibproj/sync/code_fit.h"
#include "calibproj/sync/frame_map.h"
#include "calibproj/sync/light_timeline.h"

namespace calibproj::sync {

// One band's fit.
struct BandFit {
  double row = 0.0;      // centre row of the band, share of the image height
  double offset = 0.0;   // camera frames
  double sigma = 0.0;    // camera frames
  double rms = 0.0;      // fit residual over contrast
  bool used = false;     // sharp and showing the codes
};

struct ReadoutEstimate {
  std::vector<BandFit> bands;    // every band that could be fitted
  bool valid = false;            // enough sharp bands, spread over the image
  double readout = 0.0;          // camera frames from the first row's start to the last's
  double readout_sigma = 0.0;    // 1 sigma, camera frames
  double first_row_offset = 0.0; // offset of the frame map of the first row
  double offset_sigma = 0.0;
  double exposure = 0.0;         // median fitted exposure of the bands, camera frames
  double rate = 0.0;             // the first row's rate, from two code windows (0: not measured)
  bool applied = false;          // the frame map was moved to the first row
  int bands_used = 0;
  // Mean centre row (share of the image height) of the bands that show the codes: the
  // rows a whole-frame fit's offset refers to (0.5 when no band was fitted).
  double signal_row = 0.5;
  // Readouts (camera frames) for which one line meets every band's interval of offsets
  // that fit; bounded = false when the bands gave no such range.
  bool bounded = false;
  double readout_low = 0.0;
  double readout_high = 0.0;
};

// One band's interval of offsets that fit its codes: [offset - half_width, offset +
// half_width] at its centre row (share of the image height).
struct BandInterval {
  double row = 0.0;
  double offset = 0.0;
  double half_width = 0.0;
};

// The readouts r for which some first-row offset o puts every band's offset o - r * row
// inside its interval: false when there is none (bands disagreeing beyond their
// intervals), else the range [*low, *high]. Exact: each pair of bands bounds r linearly.
bool FeasibleReadouts(const std::vector<BandInterval>& bands, double* low, double* high);

// `band_signals[b][j]`: mean luma of band b (rows [b h / B, (b + 1) h / B)) in camera
// frame j, NaN where not measured. `map` is the whole frame's fit. Each window is fitted
// on its own at the map's rate (a rolling shutter biases the whole frame's rate); two
// windows give the first row's rate from where each puts its code, and the readout as
// their weighted mean.
ReadoutEstimate EstimateReadout(const std::vector<std::vector<double>>& band_signals, const LightTimeline& timeline,
                                const std::vector<FrameWindow>& windows, const FrameMap& map,
                                const CodeFitOptions& options);

// A sensor reads all its rows within one frame period: a fit beyond it took one code
// edge for another (measured: 1.06 frames for a true 0.45, on a check projection's
// short codes under room light, floor texture and dropped frames; applied, it moved the
// camera's map by a frame and lost every pattern).
constexpr double kMaxReadoutFrames = 1.0;

// The readout is told apart from 0 (more than `sigmas` standard deviations and a
// fiftieth of a frame), is physically possible (at most kMaxReadoutFrames) and known to
// `max_sigma` camera frames: the first row's offset then replaces the whole frame's. A
// readout known less well is reported, not used.
bool Applicable(const ReadoutEstimate& readout, double sigmas, double max_sigma);

// A map whose exposure window covers both `window_map`'s and every row's exposure under
// `readout` (widened by `sigmas` standard deviations), for picking clean frames.
FrameMap CoverRows(const FrameMap& window_map, const ReadoutEstimate& readout, double sigmas);

}  // namespace calibproj::sync
