#include "calibproj/detect/apriltag_detector.h"

#include <apriltag/apriltag.h>

#include <opencv2/core.hpp>

#include <algorithm>
#include <stdexcept>
#include <string>

#include "calibproj/common/limits.h"
#include "calibproj/detect/option_table.h"

namespace calibproj::detect {

namespace {

// libapriltag puts the centre of the top-left pixel at (0.5, 0.5); OpenCV at (0, 0).
constexpr double kAprilTagPixelOffset = 0.5;

// libapriltag's corners p[0..3] are OpenCV's corners 1, 0, 3, 2 (measured on the
// same tag36h11 image through both detectors): OpenCV corner k is p[kOpenCvToAprilTag[k]].
constexpr int kOpenCvToAprilTag[4] = {1, 0, 3, 2};

void Require(bool condition, const std::string& message) {
  if (!condition) throw std::invalid_argument("AprilTag options: " + message);
}

const std::string& AprilTagName(const MarkerFamily& family) {
  if (family.system != MarkerSystemKind::kAprilTag) {
    throw std::invalid_argument(family.Spec() + " is not an AprilTag family");
  }
  return family.name;
}

// libapriltag reads out of bounds when the decimated image has a side under 3 px
// (measured: 8 px rows at quad_decimate 4 crash); keep one pixel to spare.
constexpr int kMinDecimatedSide = 4;

// Side of the image libapriltag segments: image_u8_decimate() keeps 2 of every 3
// pixels for a factor of 1.5, else 1 + (side - 1) / int(factor).
int DecimatedSide(int side, float decimate) {
  if (decimate == 1.5f) return side / 3 * 2;
  return decimate > 1.0f ? 1 + (side - 1) / static_cast<int>(decimate) : side;
}

void CheckDecimatedSize(const cv::Mat& gray, float decimate) {
  if (std::min(DecimatedSide(gray.cols, decimate), DecimatedSide(gray.rows, decimate)) < kMinDecimatedSide) {
    throw std::invalid_argument("image of " + std::to_string(gray.cols) + "x" + std::to_string(gray.rows) +
                                " px is too small for quad_decimate " + cv::format("%g", decimate) + " (needs " +
                                std::to_string(kMinDecimatedSide) + " px per side after decimation)");
  }
}

// Frees the detections and the array holding them.
struct DetectionsDeleter {
  void operator()(zarray_t* detections) const { apriltag_detections_destroy(detections); }
};

}  // namespace

void AprilTagOptions::Check() const {
  // libapriltag sizes its blur kernel and decimated image from these, unchecked.
  Require(quad_decimate >= 1.0f && quad_decimate <= 64.0f, "quad_decimate must be in [1, 64]");
  Require(quad_sigma >= 0.0f && quad_sigma <= 100.0f, "quad_sigma must be in [0, 100]");
  Require(nthreads >= 1 && nthreads <= limits::kMaxThreads,
          "nthreads must be in [1, " + std::to_string(limits::kMaxThreads) + "]");
  Require(decode_sharpening >= 0.0 && decode_sharpening <= 100.0, "decode_sharpening must be in [0, 100]");
  Require(max_hamming >= 0 && max_hamming <= 3, "max_hamming must be in [0, 3]");
  Require(min_white_black_diff >= 0 && min_white_black_diff <= 255, "min_white_black_diff must be in [0, 255]");
  refinement.Check();
}

AprilTagDetector::AprilTagDetector(const MarkerFamily& family, const AprilTagOptions& options)
    : options_(options),
      quad_cells_(GetMarkerGeometry(family).quad_cells),
      family_(CreateAprilTagFamily(AprilTagName(family))),
      detector_(nullptr, apriltag_detector_destroy) {
  options_.Check();
  detector_.reset(apriltag_detector_create());
  if (!detector_) throw std::runtime_error("libapriltag could not create a detector");
  detector_->quad_decimate = options_.quad_decimate;
  detector_->quad_sigma = options_.quad_sigma;
  detector_->nthreads = options_.nthreads;
  detector_->refine_edges = options_.refine_edges;
  detector_->decode_sharpening = options_.decode_sharpening;
  detector_->qtp.min_white_black_diff = options_.min_white_black_diff;
  apriltag_detector_add_family_bits(detector_.get(), family_.get(), options_.max_hamming);
}

AprilTagDetector::~AprilTagDetector() = default;

Detections AprilTagDetector::Detect(const cv::Mat& gray, int min_white_black_diff) const {
  CheckGrayImage(gray);
  CheckDecimatedSize(gray, options_.quad_decimate);
  cv::Mat image = options_.inverted ? cv::Mat(255 - gray) : gray;
  image_u8_t view = {image.cols, image.rows, static_cast<int32_t>(image.step[0]), image.data};
  std::unique_ptr<zarray_t, DetectionsDeleter> found;
  {
    const std::lock_guard<std::mutex> lock(mutex_);
    detector_->qtp.min_white_black_diff =
        min_white_black_diff > 0 ? min_white_black_diff : options_.min_white_black_diff;
    found.reset(apriltag_detector_detect(detector_.get(), &view));
  }
  if (!found) throw std::runtime_error("libapriltag detection failed");
  Detections out;
  for (int i = 0; i < zarray_size(found.get()); ++i) {
    apriltag_detection_t* detection = nullptr;
    zarray_get(found.get(), i, &detection);
    Quad quad;
    for (int k = 0; k < 4; ++k) {
      const double* p = detection->p[kOpenCvToAprilTag[k]];
      quad[k] = cv::Point2d(p[0] - kAprilTagPixelOffset, p[1] - kAprilTagPixelOffset);
    }
    RefineCorners(image, quad_cells_, options_.refinement, &quad);
    out.ids.push_back(detection->id);
    out.corners.push_back(quad);
  }
  SortById(&out);
  return out;
}

}  // namespace calibproj::detect
