#pragma once
// Picking the camera frames that show one projected pattern cleanly: their whole
// exposure falls inside the pattern's display interval, away from the changes at
// either end (projectors take a few milliseconds to switch).

#include <vector>

#include "calibproj/sync/frame_map.h"

namespace calibproj::video {

struct PickOptions {
  // Projector frames kept clear of each pattern change, on either side.
  double margin = 0.1;
  // Frames averaged per pattern before detection (the most central clean ones; fewer
  // where the camera records fewer). Three lower the noise that limits the centres under
  // room light (room-light-strong: rotation error 0.0113 -> 0.0084 deg) but cost a 60 fps
  // camera on a strongly textured floor all its markers (its first whole-frame detections
  // disagree with one floor homography), so one stays the default until that is understood.
  int average_frames = 1;
  // Further clean frames per pattern that stand in for picked frames the camera
  // dropped (later ones only: frames are decoded once, in order).
  int spare_frames = 2;
  // Largest relative clock drift between a camera and the projector; bounds the error
  // of the map used while decoding (from the start code and the nominal frame rate).
  double max_clock_drift = 2e-4;

  // Throws std::invalid_argument naming the first bad field.
  void Check() const;
};

// True when camera frame `frame` exposes wholly inside [begin + margin, end - margin]
// (projector frames; end is one past the pattern's last frame).
bool IsClean(const sync::FrameMap& map, int frame, double begin, double end, double margin);

// Up to `count` frames clean with margin + slack, the closest to the interval's centre
// first, returned in increasing order; frames from `first_frame` on only.
std::vector<int> PickFrames(const sync::FrameMap& map, double begin, double end, double margin, double slack,
                            int count, int first_frame = 0);

}  // namespace calibproj::video
