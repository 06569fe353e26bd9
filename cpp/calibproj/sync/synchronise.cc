#include "calibproj/sync/synchronise.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <stdexcept>

#include "calibproj/common/limits.h"

namespace calibproj::sync {

namespace {

// The inputs every search of a code needs: a valid code inside the timeline and a
// signal of a bounded length.
void CheckSearchInputs(const std::vector<double>& signal, const LightTimeline& timeline, const LightCode& code,
                       const std::string& what) {
  code.Check((what + " light code").c_str());
  if (code.EndFrame() > timeline.frame_count()) {
    throw std::invalid_argument(what + " light code: frames " + std::to_string(code.first_frame) + ".." +
                                std::to_string(code.EndFrame() - 1) + " lie outside the projector's " +
                                std::to_string(timeline.frame_count()) + " frames");
  }
  if (signal.size() > static_cast<std::size_t>(limits::kMaxFrames)) {
    throw std::invalid_argument("signal: more than " + std::to_string(limits::kMaxFrames) + " frames");
  }
}

void Require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument("sync options: " + message);
}

std::string Format(const char* format, double a, double b = 0.0, double c = 0.0) {
  char buffer[256];
  std::snprintf(buffer, sizeof(buffer), format, a, b, c);
  return buffer;
}

CodeLocation FromFit(const CodeFit& fit, const LightCode& code, double correlation) {
  CodeLocation location;
  location.correlation = correlation;
  location.map = fit.map;
  location.window_map = fit.window_map;
  location.frame = fit.map.CameraFrame(code.first_frame);
  location.uncertainty = fit.offset_uncertainty;
  location.rms = fit.rms;
  location.sharp = fit.sharp;
  return location;
}

// Rate and offset through the two code positions; throws when they disagree with the
// nominal rate.
FrameMap MapThroughCodes(const CodeLocation& start_location, const CodeLocation& end_location, const LightCode& start,
                         const LightCode& end, double nominal_rate, const SyncOptions& options,
                         const std::string& source) {
  const double distance = end.first_frame - start.first_frame;
  const double rate = (end_location.frame - start_location.frame) / distance;
  const double deviation = rate / nominal_rate - 1.0;
  if (!(std::abs(deviation) <= options.max_rate_deviation)) {
    throw std::runtime_error(
        source + ": the start and end light codes disagree: they are " +
        Format("%.1f camera frames apart where the sequence and the video's frame rate put them %.1f apart "
               "(rate off by %.2f %%)",
               end_location.frame - start_location.frame, nominal_rate * distance, 100.0 * deviation) +
        "; is this a recording of another sequence?");
  }
  // Positions known only to within plateaus (no frame across a light change) that
  // allow the nominal rate keep it: the container's rate is then the best estimate.
  const double tolerance = (start_location.uncertainty + end_location.uncertainty) / distance;
  const double chosen = std::abs(rate - nominal_rate) <= tolerance ? nominal_rate : rate;
  return FrameMap{start_location.frame - chosen * start.first_frame, chosen, start_location.map.exposure};
}

CodeLocation RefitCode(const std::vector<double>& signal, const LightTimeline& timeline, const LightCode& code,
                       const FrameMap& map, const CodeLocation& previous, const SyncOptions& options) {
  const CodeFit fit =
      FitCodeWindows(signal, timeline, {CodeWindow(timeline, code, options)}, map, false, options.fit);
  return FromFit(fit, code, previous.correlation);
}

}  // namespace

void SyncOptions::Check() const {
  search.Check();
  fit.Check();
  Require(min_correlation > 0.0 && min_correlation <= 1.0, "min_correlation must be in (0, 1]");
  Require(max_rate_deviation > 0.0 && max_rate_deviation < 0.5, "max_rate_deviation must be in (0, 0.5)");
  Require(context_before >= 0 && context_after >= 0 && context_before <= limits::kMaxFrames &&
              context_after <= limits::kMaxFrames,
          "context_before and context_after must be in [0, " + std::to_string(limits::kMaxFrames) + "]");
  Require(guard_samples >= 1 && guard_samples <= limits::kMaxFrames,
          "guard_samples must be in [1, " + std::to_string(limits::kMaxFrames) + "]");
}

FrameWindow CodeWindow(const LightTimeline& timeline, const LightCode& code, const SyncOptions& options) {
  return timeline.KnownWindow(code, options.context_before, options.context_after);
}

CodeLocation FitCode(const std::vector<double>& signal, const LightTimeline& timeline, const LightCode& code,
                     const CodeMatch& match, double nominal_rate, const SyncOptions& options) {
  const FrameWindow window = CodeWindow(timeline, code, options);
  // The match's position at the middle of the window, carried at the nominal rate.
  const double middle = 0.5 * (window.begin + window.end);
  const FrameMap initial{match.map.CameraFrame(middle) - nominal_rate * middle, nominal_rate, match.map.exposure};
  const CodeFit fit = FitCodeWindows(signal, timeline, {window}, initial, false, options.fit);
  return FromFit(fit, code, match.correlation);
}

CodeLocation LocateCode(const std::vector<double>& signal, const LightTimeline& timeline, const LightCode& code,
                        double nominal_rate, const SyncOptions& options, const std::string& source,
                        const std::string& what, int first_shift, int end_shift) {
  options.Check();
  CheckSearchInputs(signal, timeline, code, what);
  const FrameWindow window = CodeWindow(timeline, code, options);
  const CodeMatch match = SearchCode(signal, timeline, window, nominal_rate, options.search, first_shift, end_shift);
  if (!match.valid()) {
    throw std::runtime_error(source + ": " + what + " light code not found: the video (" +
                             std::to_string(signal.size()) + " frames) has no stretch of measured frames " +
                             "long enough to hold it where it was searched; is the recording truncated?");
  }
  if (match.correlation < options.min_correlation) {
    throw std::runtime_error(source + ": " + what + " light code not found: " +
                             Format("best correlation %.3f at camera frame %.0f (needs %.2f)", match.correlation,
                                    match.first_sample, options.min_correlation) +
                             "; is the projector in view, is this a recording of this sequence, and was "
                             "the camera's exposure locked (automatic exposure settling during the code "
                             "blurs it; start recording a few seconds before the projection)?");
  }
  return FitCode(signal, timeline, code, match, nominal_rate, options);
}

SyncResult SynchroniseFromStart(const std::vector<double>& signal, const LightTimeline& timeline,
                                const LightCode& start, const LightCode& end, const CodeLocation& start_location,
                                double nominal_rate, const SyncOptions& options, const std::string& source) {
  options.Check();
  CheckSearchInputs(signal, timeline, start, "start");
  CheckSearchInputs(signal, timeline, end, "end");
  // The end code's window starts where the start code and the nominal rate put it.
  const FrameWindow end_window = CodeWindow(timeline, end, options);
  const double distance = end_window.begin - start.first_frame;
  const double predicted = start_location.frame + nominal_rate * distance;
  const double spread = options.max_rate_deviation * nominal_rate * distance + 2.0;
  const int first_shift = std::max(0, static_cast<int>(std::floor(predicted - spread)));
  const int end_shift = static_cast<int>(std::ceil(predicted + spread)) + 1;
  if (first_shift >= static_cast<int>(signal.size())) {
    throw std::runtime_error(source + ": end light code not found: the video ends at frame " +
                             std::to_string(signal.size()) + Format(", before camera frame %.0f where the start "
                                                                    "code puts it; is the recording truncated?",
                                                                    predicted));
  }
  CodeLocation end_location;
  try {
    end_location = LocateCode(signal, timeline, end, nominal_rate, options, source, "end", first_shift, end_shift);
  } catch (const std::runtime_error&) {
    // Anywhere else after the start code, the codes disagree (another sequence);
    // nowhere, the first error stands.
    const int after_start = static_cast<int>(std::ceil(start_location.frame + nominal_rate * start.FrameCount()));
    const CodeMatch elsewhere = SearchCode(signal, timeline, end_window, nominal_rate, options.search, after_start);
    if (elsewhere.valid() && elsewhere.correlation >= options.min_correlation) {
      MapThroughCodes(start_location, FitCode(signal, timeline, end, elsewhere, nominal_rate, options), start,
                      end, nominal_rate, options, source);
    }
    const CodeMatch near = SearchCode(signal, timeline, end_window, nominal_rate, options.search, first_shift,
                                      end_shift);
    throw std::runtime_error(
        source + ": end light code not found " +
        Format("within camera frames %.0f..%.0f, where the start code and the video's frame rate put it ",
               first_shift, end_shift - 1) +
        Format("(best correlation %.3f, needs %.2f)", near.valid() ? near.correlation : -1.0,
               options.min_correlation) +
        "; is this a recording of another sequence, or was the projector out of view?");
  }

  // Positions -> rate -> both codes refitted at that rate -> positions again.
  SyncResult result;
  result.start = start_location;
  FrameMap map = MapThroughCodes(result.start, end_location, start, end, nominal_rate, options, source);
  result.start = RefitCode(signal, timeline, start, map, result.start, options);
  end_location = RefitCode(signal, timeline, end, map, end_location, options);
  map = MapThroughCodes(result.start, end_location, start, end, nominal_rate, options, source);
  result.end = end_location;

  const CodeFit joint = FitCodeWindows(
      signal, timeline, {CodeWindow(timeline, start, options), end_window}, map, true, options.fit);
  result.map = joint.map;
  result.window_map = joint.window_map;
  result.offset_uncertainty = joint.offset_uncertainty;
  result.rate_uncertainty = (result.start.uncertainty + result.end.uncertainty) / (end.first_frame - start.first_frame);
  result.sharp = joint.sharp;
  result.rms = joint.rms;
  return result;
}

SyncResult Synchronise(const std::vector<double>& signal, const LightTimeline& timeline, const LightCode& start,
                       const LightCode& end, double nominal_rate, const SyncOptions& options,
                       const std::string& source) {
  const CodeLocation start_location = LocateCode(signal, timeline, start, nominal_rate, options, source, "start");
  return SynchroniseFromStart(signal, timeline, start, end, start_location, nominal_rate, options, source);
}

}  // namespace calibproj::sync
