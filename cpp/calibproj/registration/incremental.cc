#include "calibproj/registration/incremental.h"

#include <cstdio>

namespace calibproj::registration {

namespace {

void Log(const std::function<void(const std::string&)>& log, const std::string& message) {
  if (log) log(message);
}

}  // namespace

RunSummary Run(Reconstruction& reconstruction, const std::function<void(const std::string&)>& log,
               const std::vector<std::string>& camera_names) {
  const auto name = [&camera_names](int camera) {
    return camera >= 0 && camera < static_cast<int>(camera_names.size()) ? camera_names[camera]
                                                                          : std::to_string(camera);
  };
  RunSummary summary;
  for (const PairCandidate& pair : reconstruction.RankInitialPairs()) {
    summary.initial = reconstruction.Initialize(pair.camera1, pair.camera2);
    if (summary.initial.success) {
      summary.initial_pair = pair;
      summary.initialized = true;
      break;
    }
    Log(log, "initial pair " + name(pair.camera1) + "-" + name(pair.camera2) +
                 " rejected: " + summary.initial.reason);
  }
  if (!summary.initialized) {
    reconstruction.FailUnregistered();
    return summary;
  }
  reconstruction.Adjust(false);
  Log(log, "initial pair " + name(summary.initial_pair.camera1) + "-" + name(summary.initial_pair.camera2) + ": " + std::to_string(summary.initial.points) +
               " points");
  for (NextCameraCandidate next = reconstruction.ChooseNextCamera(); next.camera >= 0;
       next = reconstruction.ChooseNextCamera()) {
    const RegisterResult registered = reconstruction.RegisterCamera(next.camera);
    if (!registered.success) {
      Log(log, "camera " + name(next.camera) + " failed: " + registered.reason);
      continue;
    }
    const int added = reconstruction.AddPoints(next.camera);
    reconstruction.Adjust(false);
    reconstruction.FilterOutliers();
    Log(log, "camera " + name(next.camera) + " registered: " + std::to_string(registered.inliers) +
                 " inliers, " + std::to_string(added) + " new points");
  }
  reconstruction.FailUnregistered();
  summary.refined = reconstruction.Refine();
  if (summary.refined.relief.tested) Log(log, summary.refined.relief.Describe());
  return summary;
}

}  // namespace calibproj::registration
