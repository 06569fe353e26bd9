#pragma once
// The registration loop (paper section 2.2) over the steps of Reconstruction.
// The Python driver (calibproj.registration.driver) runs the same steps in the same order.

#include <functional>
#include <string>
#include <vector>

#include "calibproj/registration/reconstruction.h"

namespace calibproj::registration {

struct RunSummary {
  bool initialized = false;
  PairCandidate initial_pair;
  InitialPairResult initial;
  RefineResult refined;
};

// Progress messages (one per step) go to `log` when it is set; they name cameras by
// `camera_names` when given, else by index.
RunSummary Run(Reconstruction& reconstruction, const std::function<void(const std::string&)>& log = {},
               const std::vector<std::string>& camera_names = {});

}  // namespace calibproj::registration
