#pragma once
// The last few decoded frames' luma, kept while the start light code is being looked
// for: once it is found, frames that show patterns shortly after it are taken from
// here. Memory stays bounded by the capacity whatever the video length.

#include <opencv2/core.hpp>

#include <deque>
#include <utility>

#include "calibproj/video/luma.h"

namespace calibproj::video {

class FrameRing {
 public:
  explicit FrameRing(int capacity) : capacity_(capacity) {}

  // Keeps a copy of `luma` as frame `index`, in the oldest frame's buffer once full
  // (the luma is only stretched to full range for the frames that are used).
  void Push(int index, const LumaPlane& luma) {
    if (capacity_ <= 0) return;
    LumaPlane copy;
    if (static_cast<int>(frames_.size()) == capacity_) {
      copy = std::move(frames_.front().second);
      frames_.pop_front();
    }
    luma.image.copyTo(copy.image);  // reuses the buffer when the size is the same
    copy.limited_range = luma.limited_range;
    frames_.emplace_back(index, std::move(copy));
  }

  const std::deque<std::pair<int, LumaPlane>>& frames() const { return frames_; }
  void Clear() { frames_.clear(); }

 private:
  int capacity_;
  std::deque<std::pair<int, LumaPlane>> frames_;
};

}  // namespace calibproj::video
