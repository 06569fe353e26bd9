#pragma once
// One register_<stage>() per binding file, called from module.cc.

#include <pybind11/pybind11.h>

namespace calibproj::bindings {

void register_ba(pybind11::module_& m);
void register_geometry(pybind11::module_& m);

}  // namespace calibproj::bindings
