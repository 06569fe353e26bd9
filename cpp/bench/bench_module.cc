// calibproj._bench: benchmark-only module. The same bundle adjuster as
// calibproj._core.ba.bundle_adjust, with AutoDiff costs instead of the analytic ones.

#include <pybind11/pybind11.h>

#include "../bindings/registry.h"
#include "autodiff_costs.h"

PYBIND11_MODULE(_bench, m) {
  m.doc() = "Benchmark-only: bundle adjustment with Ceres AutoDiff costs";
  // Its results are the core's ba.Result class: the core registers it first.
  pybind11::module_::import("calibproj._core");
  calibproj::bindings::def_bundle_adjust(m, "bundle_adjust_autodiff", calibproj::bench::AutoDiffCosts());
}
