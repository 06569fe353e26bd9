#include "calibproj/detect/msm_merge.h"

#include <algorithm>
#include <map>
#include <stdexcept>
#include <utility>

namespace calibproj::detect {

namespace {

double Median(std::vector<double> values) {
  const std::size_t n = values.size();
  std::nth_element(values.begin(), values.begin() + n / 2, values.end());
  const double upper = values[n / 2];
  if (n % 2 == 1) return upper;
  return 0.5 * (upper + *std::max_element(values.begin(), values.begin() + n / 2));
}

}  // namespace

void MergeOptions::Check() const {
  if (!(max_deviation_px > 0.0)) throw std::invalid_argument("merge options: max_deviation_px must be positive");
  if (min_scales < 1) throw std::invalid_argument("merge options: min_scales must be at least 1");
}

std::vector<MergedCentre> MergeScales(std::vector<ScaleRecord>* records, const MergeOptions& options) {
  options.Check();
  std::map<std::pair<int, int>, std::vector<ScaleRecord*>> by_msm;
  for (ScaleRecord& record : *records) by_msm[{record.array, record.marker}].push_back(&record);
  std::vector<MergedCentre> out;
  for (auto& [key, scales] : by_msm) {
    std::vector<double> xs, ys;
    for (const ScaleRecord* r : scales) {
      xs.push_back(r->centre.x);
      ys.push_back(r->centre.y);
    }
    const cv::Point2d median(Median(xs), Median(ys));
    MergedCentre merged{key.first, key.second, {0.0, 0.0}, 0, 0};
    for (ScaleRecord* r : scales) {
      r->deviation_px = cv::norm(r->centre - median);
      r->kept = r->deviation_px <= options.max_deviation_px;
      if (r->kept) {
        merged.centre += r->centre;
        ++merged.scales_kept;
      } else {
        ++merged.scales_rejected;
      }
    }
    if (merged.scales_kept < options.min_scales) {
      for (ScaleRecord* r : scales) r->kept = false;
      continue;
    }
    merged.centre *= 1.0 / merged.scales_kept;
    out.push_back(merged);
  }
  return out;
}

}  // namespace calibproj::detect
