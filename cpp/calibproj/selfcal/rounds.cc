#include "calibproj/selfcal/rounds.h"

#include <algorithm>
#include <stdexcept>

namespace calibproj::selfcal {

namespace {

bool SameLenses(const IntrinsicsMap& a, const IntrinsicsMap& b) {
  return std::all_of(a.begin(), a.end(), [&](const auto& item) {
    const auto other = b.find(item.first);
    return other != b.end() && item.second.K == other->second.K && item.second.dist == other->second.dist;
  });
}

}  // namespace

RefinedCalibration RefineWithRegistrations(const formats::Calibration& first, const formats::Tracks& tracks,
                                           const IntrinsicsMap& intrinsics, const RefineRequest& request,
                                           const SelfCalibrationOptions& options, int num_threads,
                                           const RegisterFunction& register_tracks,
                                           const std::function<void(const std::string&)>& log) {
  if (first.poses.empty()) throw std::invalid_argument("self-calibration: no camera registered to refine from");
  if (options.rounds < 1) throw std::invalid_argument("self-calibration: rounds must be at least 1");
  RefinedCalibration out{first, tracks, intrinsics, {}, {}};
  const IntrinsicsMap start = ClosedFormStart(tracks, intrinsics, first, request, options, log);
  if (!SameLenses(start, intrinsics)) {
    out.tracks = ConvertTracks(tracks, intrinsics, start);
    out.intrinsics = start;
    out.calibration = register_tracks(out.tracks, out.intrinsics, nullptr);
  }
  for (int round = 0; round < options.rounds; ++round) {  // each from the registration the last one made
    SelfCalibration result = SelfCalibrate(out.tracks, out.intrinsics, out.calibration, request, options, num_threads,
                                           &intrinsics, round > 0 ? &out.result.reports : nullptr, log);
    out.tracks = ConvertTracks(out.tracks, out.intrinsics, result.intrinsics);
    out.intrinsics = result.intrinsics;
    out.result = std::move(result);
    out.calibration = register_tracks(out.tracks, out.intrinsics, &out.result.lens_covariance);
  }
  out.weak = MarkUntrustedLensesWeak(out.result, out.calibration);
  return out;
}

}  // namespace calibproj::selfcal
