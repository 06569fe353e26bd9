#pragma once
// Conversions of sync types between Python dicts and C++ (shared by sync.cc and ingest.cc).

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

inline pybind11::dict FrameMapDict(const sync::FrameMap& map) {
  pybind11::dict d;
  d["offset"] = map.offset;
  d["rate"] = map.rate;
  d["exposure"] = map.exposure;
  return d;
}

inline pybind11::dict CodeLocationDict(const sync::CodeLocation& location) {
  pybind11::dict d;
  d["correlation"] = location.correlation;
  d["frame"] = location.frame;
  d["uncertainty"] = location.uncertainty;
  d["map"] = FrameMapDict(location.map);
  d["window_map"] = FrameMapDict(location.window_map);
  d["rms"] = location.rms;
  d["sharp"] = location.sharp;
  return d;
}

inline pybind11::dict SyncResultDict(const sync::SyncResult& result) {
  pybind11::dict d = FrameMapDict(result.map);
  d["window_map"] = FrameMapDict(result.window_map);
  d["offset_uncertainty"] = result.offset_uncertainty;
  d["rate_uncertainty"] = result.rate_uncertainty;
  d["sharp"] = result.sharp;
  d["rms"] = result.rms;
  d["start"] = CodeLocationDict(result.start);
  d["end"] = CodeLocationDict(result.end);
  const sync::ReadoutEstimate& r = result.readout;
  d["readout"] = r.valid ? pybind11::object(pybind11::dict(
                               pybind11::arg("readout") = r.readout, pybind11::arg("sigma") = r.readout_sigma,
                               pybind11::arg("first_row_offset") = r.first_row_offset,
                               pybind11::arg("offset_sigma") = r.offset_sigma, pybind11::arg("bands") = r.bands_used,
                               pybind11::arg("applied") = r.applied))
                         : pybind11::object(pybind11::none());
  return d;
}

}  // namespace calibproj::bindings
