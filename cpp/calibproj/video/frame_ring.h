#pragma once
// The last few decoded grey frames, kept while the start light code is being looked
// for: once it is found, frames that show patterns shortly after it are taken from
// here. Memory stays bounded by the capacity whatever the video length.

#include <opencv2/core.hpp>

#include <deque>
#include <utility>

namespace calibproj::video {

class FrameRing {
 public:
  explicit FrameRing(int capacity) : capacity_(capacity) {}

  // Keeps `gray` (taken over, not copied) as frame `index`, dropping the oldest frame.
  void Push(int index, cv::Mat gray) {
    if (capacity_ <= 0) return;
    if (static_cast<int>(frames_.size()) == capacity_) frames_.pop_front();
    frames_.emplace_back(index, std::move(gray));
  }

  const std::deque<std::pair<int, cv::Mat>>& frames() const { return frames_; }
  void Clear() { frames_.clear(); }

 private:
  int capacity_;
  std::deque<std::pair<int, cv::Mat>> frames_;
};

}  // namespace calibproj::video
