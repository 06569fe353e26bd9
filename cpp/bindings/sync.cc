// Bindings of calibproj::sync: light-code search and synchronisation of a brightness
// signal (numpy arrays in, dicts out).

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <string>
#include <vector>

#include "calibproj/sync/synchronise.h"
#include "checks.h"
#include "ingest_options.h"
#include "registry.h"
#include "sync_convert.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

std::vector<double> ToVector(const DoubleArray& array, const std::string& what) {
  RequireShape(array, {-1}, what);
  return std::vector<double>(array.data(), array.data() + array.size());
}

sync::SyncOptions SyncOptionsFromKwargs(const py::kwargs& kwargs) {
  sync::SyncOptions options;
  for (const auto& item : kwargs) {
    const std::string key = py::str(item.first);
    if (!SetSyncOption(&options, key, item.second)) ThrowUnknownOption("sync", key, SyncOptionTable());
  }
  options.Check();
  CheckSyncOptionValues(options);
  return options;
}

// The window of a code, which must lie within the timeline.
sync::FrameWindow CodeWindow(const sync::LightTimeline& timeline, const sync::LightCode& code,
                             const sync::SyncOptions& options, const std::string& what) {
  if (code.EndFrame() > timeline.frame_count()) {
    throw std::invalid_argument(what + ": the code ends after the " + std::to_string(timeline.frame_count()) +
                                " frames of levels");
  }
  return sync::CodeWindow(timeline, code, options);
}

}  // namespace

void register_sync(py::module_& m) {
  m.def("option_table", &SyncOptionTable, "Every sync knob as {name, default, help}, in order.");
  m.def(
      "synchronise",
      [](const DoubleArray& signal, const DoubleArray& levels, const py::dict& start, const py::dict& end,
         double nominal_rate, const std::string& source, const py::kwargs& kwargs) {
        const sync::SyncOptions options = SyncOptionsFromKwargs(kwargs);
        const std::vector<double> values = ToVector(signal, "signal");
        const sync::LightTimeline timeline(ToVector(levels, "levels"));
        const sync::LightCode start_code = LightCodeFromDict(start, "start_code");
        const sync::LightCode end_code = LightCodeFromDict(end, "end_code");
        sync::SyncResult result;
        {
          py::gil_scoped_release release;
          result = sync::Synchronise(values, timeline, start_code, end_code, nominal_rate, options, source);
        }
        return SyncResultDict(result);
      },
      py::arg("signal"), py::arg("levels"), py::arg("start_code"), py::arg("end_code"), py::arg("nominal_rate"),
      py::arg("source") = "signal",
      "Frame map of a camera from its per-frame brightness `signal` (NaN = not measured), the "
      "projector's per-frame `levels` (0..1, NaN = unknown) and the light codes ({bits, "
      "frames_per_bit, first_frame}); `nominal_rate` = camera fps / projector fps. Keyword "
      "options: see option_table(). RuntimeError naming `source` when a code is missing or "
      "the codes disagree.");
  m.def(
      "locate_code",
      [](const DoubleArray& signal, const DoubleArray& levels, const py::dict& code, double nominal_rate,
         const std::string& source, const py::kwargs& kwargs) {
        const sync::SyncOptions options = SyncOptionsFromKwargs(kwargs);
        const std::vector<double> values = ToVector(signal, "signal");
        const sync::LightTimeline timeline(ToVector(levels, "levels"));
        const sync::LightCode light_code = LightCodeFromDict(code, "code");
        sync::CodeLocation location;
        {
          py::gil_scoped_release release;
          location = sync::LocateCode(values, timeline, light_code, nominal_rate, options, source, "light");
        }
        return CodeLocationDict(location);
      },
      py::arg("signal"), py::arg("levels"), py::arg("code"), py::arg("nominal_rate"), py::arg("source") = "signal",
      "Where one light code lies in a brightness signal (see synchronise).");
  m.def(
      "estimate_readout",
      [](const py::array_t<double, py::array::c_style | py::array::forcecast>& band_signals,
         const DoubleArray& levels, const py::dict& start, const py::dict& end, const py::dict& map,
         const py::kwargs& kwargs) {
        RequireShape(band_signals, {-1, -1}, "band_signals");
        const sync::SyncOptions options = SyncOptionsFromKwargs(kwargs);
        std::vector<std::vector<double>> bands(static_cast<std::size_t>(band_signals.shape(0)));
        for (std::size_t b = 0; b < bands.size(); ++b) {
          const double* row = band_signals.data(static_cast<py::ssize_t>(b), 0);
          bands[b].assign(row, row + band_signals.shape(1));
        }
        const sync::LightTimeline timeline(ToVector(levels, "levels"));
        const std::vector<sync::FrameWindow> windows{
            CodeWindow(timeline, LightCodeFromDict(start, "start_code"), options, "start_code"),
            CodeWindow(timeline, LightCodeFromDict(end, "end_code"), options, "end_code")};
        const sync::FrameMap frame_map{DictItem<double>(map, "offset", "map"), DictItem<double>(map, "rate", "map"),
                                       DictItem<double>(map, "exposure", "map")};
        if (!(frame_map.rate > 0.0) || !(frame_map.exposure > 0.0)) throw std::invalid_argument("map: bad rate or exposure");
        sync::ReadoutEstimate estimate;
        {
          py::gil_scoped_release release;
          estimate = sync::EstimateReadout(bands, timeline, windows, frame_map, options.fit);
        }
        py::list fits;
        for (const sync::BandFit& band : estimate.bands) {
          fits.append(py::dict(py::arg("row") = band.row, py::arg("offset") = band.offset,
                               py::arg("sigma") = band.sigma, py::arg("rms") = band.rms, py::arg("used") = band.used));
        }
        return py::dict(py::arg("valid") = estimate.valid, py::arg("readout") = estimate.readout,
                        py::arg("sigma") = estimate.readout_sigma,
                        py::arg("first_row_offset") = estimate.first_row_offset,
                        py::arg("offset_sigma") = estimate.offset_sigma, py::arg("bands") = fits);
      },
      py::arg("band_signals"), py::arg("levels"), py::arg("start_code"), py::arg("end_code"), py::arg("map"),
      "Rolling-shutter readout (camera frames) from the brightness of horizontal bands of the image "
      "(bands, frames), fitted around both light codes starting from the whole frame's map "
      "({offset, rate, exposure}); per band its row, offset, sigma, fit rms and whether it was used.");
}

}  // namespace calibproj::bindings
