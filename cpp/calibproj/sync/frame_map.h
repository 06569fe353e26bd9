#pragma once
// The linear map between sequence time and a camera's frames.

namespace calibproj::sync {

// Camera frame j (a real number: frame indices in decoding order, 0 = first frame of
// the video) starts its exposure at projector time (j - offset) / rate, in projector
// frames (projector frame k is shown during [k, k + 1)). `rate` is camera frames per
// projector frame (camera fps / projector fps, clock drift included) and `exposure`
// the exposure time in camera frames (0 < exposure <= 1).
struct FrameMap {
  double offset = 0.0;
  double rate = 1.0;
  double exposure = 0.5;

  // Camera frame whose exposure starts at projector time t.
  double CameraFrame(double projector_time) const { return offset + rate * projector_time; }
  // Projector time at which camera frame j starts its exposure.
  double ProjectorTime(double camera_frame) const { return (camera_frame - offset) / rate; }
  // Exposure time in projector frames.
  double ProjectorExposure() const { return exposure / rate; }
};

}  // namespace calibproj::sync
