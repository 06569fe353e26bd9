#pragma once
// One register_<stage>() per binding file, called from module.cc.

#include <pybind11/pybind11.h>

#include "calibproj/ba/bundle_adjuster.h"

namespace calibproj::bindings {

// The Knob class (one entry of every stage's option_table()), in the top module.
void register_knob(pybind11::module_& m);
void register_ba(pybind11::module_& m);
void register_geometry(pybind11::module_& m);
void register_registration(pybind11::module_& m);
void register_detect(pybind11::module_& m);
void register_video(pybind11::module_& m);
void register_sync(pybind11::module_& m);
void register_ingest(pybind11::module_& m);
// The Sequence class and its parts, in the ingest submodule.
void register_sequence(pybind11::module_& m);
// The CameraIngestResult class and its parts, in the ingest submodule.
void register_ingest_result(pybind11::module_& m);
void register_selfcal(pybind11::module_& m);
void register_check(pybind11::module_& m);
void register_formats(pybind11::module_& m);
// The Tracks class, in the formats submodule.
void register_tracks(pybind11::module_& m);
// The Calibration class and its parts, in the formats submodule.
void register_calibration(pybind11::module_& m);
// The CameraIntrinsics class, in the formats submodule.
void register_camera_intrinsics(pybind11::module_& m);
// The results-folder transaction (OutputFolder, OutputFile), in the formats submodule.
void register_output_folder(pybind11::module_& m);
// provenance.json's record and writer, in the formats submodule.
void register_provenance(pybind11::module_& m);
void register_uncertainty(pybind11::module_& m);
void register_capture(pybind11::module_& m);

// Defines m.<name>(...) solving with the given costs; register_ba uses the analytic
// ones, the benchmark-only module calibproj._bench the AutoDiff ones.
void def_bundle_adjust(pybind11::module_& m, const char* name, const ba::CostFactory& make_cost);

}  // namespace calibproj::bindings
