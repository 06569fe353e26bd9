#pragma once
// The marker size below which a camera does not decode markers, learnt from its own
// detections. Whether a marker is found depends on its size in the image (modules of a
// few pixels drown in blur, noise and compression); each camera's record of successes
// per predicted module size lets it stop searching markers it cannot resolve.

#include <vector>

namespace calibproj::detect {

struct ResolutionOptions {
  // Predicted module sizes are grouped in bins of this many pixels.
  double bin_px = 0.25;
  // A bin is judged after this many searched markers ...
  int min_trials = 24;
  // ... and hopeless below this share found.
  double min_found_share = 0.05;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

class ResolutionLimit {
 public:
  explicit ResolutionLimit(ResolutionOptions options);

  // One searched marker of predicted module `module_px`, found or not.
  void Record(double module_px, bool found);

  // True when markers of this module size, or of some larger one, were searched often
  // enough and almost never found (finding markers gets easier as they grow).
  bool Hopeless(double module_px) const;

 private:
  int Bin(double module_px) const;

  ResolutionOptions options_;
  std::vector<int> trials_, found_;
};

}  // namespace calibproj::detect
