#pragma once
// The light codes of a sequence document as the core's type (shared by sync.cc and ingest.cc).

#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "calibproj/sync/synchronise.h"
#include "checks.h"

namespace calibproj::bindings {

// {"bits": [...], "frames_per_bit": n, "first_frame": k} (LightCode.to_dict()).
inline sync::LightCode LightCodeFromDict(const pybind11::handle& d, const std::string& what) {
  sync::LightCode code;
  code.bits = DictItem<std::vector<int>>(d, "bits", what);
  code.frames_per_bit = DictItem<int>(d, "frames_per_bit", what);
  code.first_frame = DictItem<int>(d, "first_frame", what);
  code.Check(what.c_str());
  return code;
}

}  // namespace calibproj::bindings
