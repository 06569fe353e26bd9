// Keyword options of the video, sync and ingest bindings.

#include "ingest_options.h"

#include <stdexcept>

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

// One table drives both setting and listing, so the two cannot disagree. The ingest
// takes the exposure in seconds (exposure_s), the bare sync in camera frames.
template <typename Options, typename Visitor>
void VisitSyncCommon(Options& o, Visitor&& visit) {
  visit("min_correlation", o.min_correlation);
  visit("max_rate_deviation", o.max_rate_deviation);
  visit("context_before", o.context_before);
  visit("context_after", o.context_after);
  visit("guard_samples", o.guard_samples);
  visit("rate_search", o.search.rate_search);
  visit("rate_step", o.search.rate_step);
  visit("phases", o.search.phases);
  visit("coarse_exposure", o.search.exposure);
  visit("offset_range", o.fit.offset_range);
  visit("offset_step", o.fit.offset_step);
  visit("min_exposure", o.fit.min_exposure);
  visit("max_exposure", o.fit.max_exposure);
  visit("exposure_steps", o.fit.exposure_steps);
  visit("feasible_chi2", o.fit.feasible_chi2);
  visit("plateau_tolerance", o.fit.plateau_tolerance);
  visit("fit_iterations", o.fit.max_iterations);
}

template <typename Options, typename Visitor>
void VisitSync(Options& o, Visitor&& visit) {
  VisitSyncCommon(o, visit);
  visit("fixed_exposure", o.fit.fixed_exposure);
}

template <typename Options, typename Visitor>
void VisitIngest(Options& o, Visitor&& visit) {
  VisitSyncCommon(o.sync, visit);
  visit("margin", o.pick.margin);
  visit("average_frames", o.pick.average_frames);
  visit("max_clock_drift", o.pick.max_clock_drift);
  visit("use_roi", o.use_roi);
  visit("bootstrap_downscale", o.bootstrap_downscale);
  visit("refine_undistorted", o.refine_undistorted);
  visit("edge_search_fraction", o.edges.search_fraction);
  visit("edge_outward_fraction", o.edges.outward_fraction);
  visit("edge_gap_share", o.edge_gap_share);
  visit("edge_spacing_px", o.edges.spacing_px);
  visit("edge_min_samples", o.edges.min_samples);
  visit("edge_max_samples", o.edges.max_samples);
  visit("edge_profile_samples_per_px", o.edges.profile_samples_per_px);
  visit("edge_max_profile_samples", o.edges.max_profile_samples);
  visit("edge_end_margin", o.edges.end_margin);
  visit("edge_min_contrast", o.edges.min_contrast);
  visit("edge_passes", o.edges.passes);
  visit("edge_tolerance_px", o.edges.tolerance_px);
  visit("roi_padding_fraction", o.roi.padding_fraction);
  visit("roi_padding_px", o.roi.padding_px);
  visit("roi_alignment", o.roi.alignment);
  visit("min_module_px", o.roi.min_module_px);
  visit("border_px", o.roi.border_px);
  visit("max_roi_area_fraction", o.roi.max_area_fraction);
  visit("max_offset_px", o.roi.max_offset_px);
  visit("max_offset_fraction", o.roi.max_offset_fraction);
  visit("target_module_px", o.roi.target_module_px);
  visit("max_downscale", o.roi.max_downscale);
  visit("learn_resolution", o.learn_resolution);
  visit("resolution_bin_px", o.resolution.bin_px);
  visit("resolution_min_trials", o.resolution.min_trials);
  visit("resolution_min_found_share", o.resolution.min_found_share);
  visit("homography_min_points", o.homography.min_points);
  visit("homography_min_spread", o.homography.min_spread);
  visit("homography_threshold_px", o.homography.ransac_threshold_px);
  visit("homography_min_inlier_share", o.homography.min_inlier_share);
  visit("homography_max_rms_px", o.homography.max_rms_px);
  visit("max_deviation_px", o.merge.max_deviation_px);
  visit("min_scales", o.merge.min_scales);
  visit("mean_row_step", o.mean_row_step);
  visit("luma_gamma", o.luma_gamma);
  visit("exposure_s", o.exposure_s);
  visit("lookback_frames", o.lookback_frames);
  visit("search_interval", o.search_interval);
  visit("detection_threads", o.detection_threads);
  visit("max_pending_jobs", o.max_pending_jobs);
}

struct Setter {
  const std::string& key;
  const py::handle& value;
  bool found = false;

  template <typename T>
  void operator()(const char* name, T& field) {
    if (key == name) {
      field = value.cast<T>();
      found = true;
    }
  }
};

struct Lister {
  py::dict out;
  template <typename T>
  void operator()(const char* name, const T& field) {
    out[name] = field;
  }
};

}  // namespace

bool SetSyncOption(sync::SyncOptions* o, const std::string& key, const py::handle& value) {
  Setter setter{key, value};
  VisitSync(*o, setter);
  return setter.found;
}

bool SetIngestOption(ingest::IngestOptions* o, const std::string& key, const py::handle& value) {
  Setter setter{key, value};
  VisitIngest(*o, setter);
  return setter.found;
}

py::dict SyncOptionDefaults() {
  sync::SyncOptions o;
  Lister lister;
  VisitSync(o, lister);
  return lister.out;
}

py::dict IngestOptionDefaults() {
  ingest::IngestOptions o;
  Lister lister;
  VisitIngest(o, lister);
  return lister.out;
}

void ThrowUnknownOption(const std::string& what, const std::string& key, const py::dict& known) {
  std::string names;
  for (const auto& item : known) names += (names.empty() ? "" : ", ") + std::string(py::str(item.first));
  throw std::invalid_argument(what + ": unknown option '" + key + "' (choose from " + names + ")");
}

}  // namespace calibproj::bindings
