#pragma once
// The registration loop (paper section 2.2) over the steps of Reconstruction.
// The Python driver (calibproj.registration) runs the same steps in the same order.

#include <functional>
#include <string>

#include "calibproj/registration/reconstruction.h"

namespace calibproj::registration {

struct RunSummary {
  bool initialized = false;
  PairCandidate initial_pair;
  InitialPairResult initial;
  RefineResult refined;
};

// Progress messages (one per step) go to `log` when it is set.
RunSummary Run(Reconstruction& reconstruction, const std::function<void(const std::string&)>& log = {});

}  // namespace calibproj::registration
