#include "calibproj/registration/incremental.h"

#include <cstdio>

namespace calibproj::registration {

namespace {

void Log(const std::function<void(const std::string&)>& log, const std::string& message) {
  if (log) log(message);
}

}  // namespace

RunSummary Run(Reconstruction& reconstruction, const std::function<void(const std::string&)>& log) {
  RunSummary summary;
  for (const PairCandidate& pair : reconstruction.RankInitialPairs()) {
    summary.initial = reconstruction.Initialize(pair.camera1, pair.camera2);
    if (summary.initial.success) {
      summary.initial_pair = pair;
      summary.initialized = true;
      break;
    }
    Log(log, "initial pair " + std::to_string(pair.camera1) + "-" + std::to_string(pair.camera2) +
                 " rejected: " + summary.initial.reason);
  }
  if (!summary.initialized) {
    reconstruction.FailUnregistered();
    return summary;
  }
  reconstruction.Adjust(false);
  Log(log, "initial pair " + std::to_string(summary.initial_pair.camera1) + "-" +
               std::to_string(summary.initial_pair.camera2) + ": " + std::to_string(summary.initial.points) +
               " points");
  for (NextCameraCandidate next = reconstruction.ChooseNextCamera(); next.camera >= 0;
       next = reconstruction.ChooseNextCamera()) {
    const RegisterResult registered = reconstruction.RegisterCamera(next.camera);
    if (!registered.success) {
      Log(log, "camera " + std::to_string(next.camera) + " failed: " + registered.reason);
      continue;
    }
    const int added = reconstruction.AddPoints(next.camera);
    reconstruction.Adjust(false);
    reconstruction.FilterOutliers();
    Log(log, "camera " + std::to_string(next.camera) + " registered: " + std::to_string(registered.inliers) +
                 " inliers, " + std::to_string(added) + " new points");
  }
  reconstruction.FailUnregistered();
  summary.refined = reconstruction.Refine();
  return summary;
}

}  // namespace calibproj::registration
