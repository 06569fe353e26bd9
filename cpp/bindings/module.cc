// calibproj._core: thin pybind11 bindings of the C++ library.
// Each stage registers its functions in a submodule of the same name.

#include <pybind11/pybind11.h>

#include <ceres/version.h>
#include <opencv2/core/version.hpp>

#include "registry.h"

namespace py = pybind11;

PYBIND11_MODULE(_core, m) {
  m.doc() = "calibproj C++ core: bundle adjustment, geometry, registration, detection, video";
  m.attr("ceres_version") = CERES_VERSION_STRING;
  m.attr("opencv_version") = CV_VERSION;
  calibproj::bindings::register_knob(m);

  auto ba = m.def_submodule("ba", "Bundle adjustment with analytic Jacobians (Ceres)");
  calibproj::bindings::register_ba(ba);
  auto geometry = m.def_submodule("geometry", "Two-view and multi-view geometry");
  calibproj::bindings::register_geometry(geometry);
  auto uncertainty = m.def_submodule("uncertainty", "The poses' joint covariance and the triangulation error it gives");
  calibproj::bindings::register_uncertainty(uncertainty);
  auto registration = m.def_submodule("registration", "Incremental registration of cameras from tracks");
  calibproj::bindings::register_registration(registration);
  auto detect = m.def_submodule("detect", "ArUco and AprilTag marker families and detection");
  calibproj::bindings::register_detect(detect);
  auto video = m.def_submodule("video", "Streaming video decode and per-frame luma");
  calibproj::bindings::register_video(video);
  auto sync = m.def_submodule("sync", "Light-code synchronisation of a camera with the sequence");
  calibproj::bindings::register_sync(sync);
  auto ingest = m.def_submodule("ingest", "One camera's video to MSM centres (sync, frame picking, detection)");
  calibproj::bindings::register_ingest(ingest);
  auto selfcal = m.def_submodule("selfcal", "Lenses refined with the poses from points on the floor");
  calibproj::bindings::register_selfcal(selfcal);
  auto check = m.def_submodule("check", "A stored calibration tested camera by camera against a short check projection");
  calibproj::bindings::register_check(check);
  auto formats = m.def_submodule("formats", "Results files, metric scale and exports (as calibproj-native writes them)");
  calibproj::bindings::register_formats(formats);
  auto capture = m.def_submodule("capture", "The room run live: the projector and the site file");
  calibproj::bindings::register_capture(capture);
}
