#pragma once
// The package's Python objects (calibproj.calibration.Calibration, io.intrinsics.Intrinsics,
// tracks.Tracks) as the core's types, for the binding files that take them; TypeError
// naming what is missing or of the wrong type.

#include <pybind11/pybind11.h>

#include <map>
#include <optional>
#include <string>

#include "calibproj/formats/calibration.h"
#include "calibproj/formats/intrinsics_file.h"
#include "calibproj/formats/tracks_file.h"

namespace calibproj::bindings {

formats::Calibration CalibrationFromPython(const pybind11::object& calibration);
// {camera name: Intrinsics}
std::map<std::string, formats::CameraIntrinsics> IntrinsicsFromPython(const pybind11::dict& cameras);
// None gives nothing.
std::optional<formats::Tracks> TracksFromPython(const pybind11::object& tracks);

}  // namespace calibproj::bindings
