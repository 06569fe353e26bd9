#pragma once
// The package's Python objects as the core's types, for the binding files that take
// them: a bound Calibration as it is, io.intrinsics.Intrinsics converted; TypeError
// naming what is missing or of the wrong type.

#include <pybind11/pybind11.h>

#include <map>
#include <optional>
#include <string>

#include "calibproj/formats/calibration.h"
#include "calibproj/formats/intrinsics_file.h"

namespace calibproj::bindings {

const formats::Calibration& CalibrationFromPython(const pybind11::object& calibration);
// {camera name: Intrinsics}
std::map<std::string, formats::CameraIntrinsics> IntrinsicsFromPython(const pybind11::dict& cameras);

}  // namespace calibproj::bindings
