// Bindings of calibproj::sync: light-code search and synchronisation of a brightness
// signal (numpy arrays and LightCodes in, bound result classes out).

#include <pybind11/numpy.h>
#include <pybind11/operators.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include "calibproj/formats/files.h"
#include "calibproj/sync/synchronise.h"
#include "checks.h"
#include "ingest_options.h"
#include "registry.h"

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

// The synchronisation's results as bound classes (read-only).
void RegisterSyncTypes(py::module_& m) {
  py::class_<sync::LightCode>(m, "LightCode",
                              "A light code as projected: its bits (1 = white, 0 = black frames), each shown for "
                              "frames_per_bit projector frames from first_frame on")
      .def(py::init([](std::vector<int> bits, int frames_per_bit, int first_frame) {
             sync::LightCode code{std::move(bits), frames_per_bit, first_frame};
             code.Check("light code");
             if (first_frame < 0) throw std::invalid_argument("light code: first_frame must not be negative");
             return code;
           }),
           py::arg("bits"), py::arg("frames_per_bit"), py::arg("first_frame"),
           "ValueError for an empty or constant code, bits other than 0/1, a frames_per_bit below 1 or a "
           "negative first frame")
      .def_property_readonly("bits", [](const sync::LightCode& c) { return py::tuple(py::cast(c.bits)); })
      .def_readonly("frames_per_bit", &sync::LightCode::frames_per_bit)
      .def_readonly("first_frame", &sync::LightCode::first_frame)
      .def_property_readonly("frame_count", &sync::LightCode::FrameCount, "projector frames of the code")
      .def_property_readonly("last_frame", [](const sync::LightCode& c) { return c.EndFrame() - 1; })
      .def(
          "frame_levels",
          [](const sync::LightCode& c) {
            py::array_t<uint8_t> levels(c.FrameCount());
            for (int k = 0; k < c.FrameCount(); ++k) levels.mutable_data()[k] = c.bits[k / c.frames_per_bit];
            return levels;
          },
          "0/1 level of every projector frame of the code, (frame_count,)")
      .def(py::self == py::self)
      .def("__repr__", [](const sync::LightCode& c) {
        return "LightCode(" + std::to_string(c.bits.size()) + " bits, " + std::to_string(c.frames_per_bit) +
               " frames per bit, from frame " + std::to_string(c.first_frame) + ")";
      });
  py::class_<sync::FrameMap>(m, "FrameMap",
                             "Projector time to camera frames: frame = offset + rate * projector frame; exposure "
                             "in camera frames")
      .def(py::init([](double offset, double rate, double exposure) {
             if (!std::isfinite(offset) || !std::isfinite(rate) || !std::isfinite(exposure)) {
               throw py::value_error("FrameMap: offset, rate and exposure must be finite");
             }
             return sync::FrameMap{offset, rate, exposure};
           }),
           py::arg("offset"), py::arg("rate"), py::arg("exposure"))
      .def_readonly("offset", &sync::FrameMap::offset, "camera frame at which the sequence's frame 0 starts")
      .def_readonly("rate", &sync::FrameMap::rate, "camera frames per projector frame")
      .def_readonly("exposure", &sync::FrameMap::exposure, "exposure time, camera frames")
      .def("camera_frame", &sync::FrameMap::CameraFrame, py::arg("projector_time"),
           "Camera frame whose exposure starts at a projector time (frames)")
      .def("projector_time", &sync::FrameMap::ProjectorTime, py::arg("camera_frame"),
           "Projector time (frames) at which a camera frame starts its exposure")
      .def("__repr__", [](const sync::FrameMap& map) {
        return "FrameMap(offset=" + formats::PythonFloat(map.offset) + ", rate=" + formats::PythonFloat(map.rate) +
               ", exposure=" + formats::PythonFloat(map.exposure) + ")";
      });
  py::class_<sync::CodeLocation>(m, "CodeLocation", "Where one light code lies in a camera's brightness signal")
      .def_readonly("correlation", &sync::CodeLocation::correlation, "best coarse correlation (-1..1)")
      .def_readonly("frame", &sync::CodeLocation::frame, "camera frame where the code's first projector frame starts")
      .def_readonly("uncertainty", &sync::CodeLocation::uncertainty,
                    "half-width of the equally good positions, camera frames")
      .def_readonly("map", &sync::CodeLocation::map, "local fit (rate as searched)")
      .def_readonly("window_map", &sync::CodeLocation::window_map,
                    "covers every exposure window that fits (same rate)")
      .def_readonly("rms", &sync::CodeLocation::rms, "fit residual RMS as a share of the code's contrast")
      .def_readonly("sharp", &sync::CodeLocation::sharp, "the offsets that fit span at most two grid steps");
  py::class_<sync::BandFit>(m, "BandFit", "One horizontal band's fit of the light codes (rolling shutter)")
      .def_readonly("row", &sync::BandFit::row, "centre row of the band, share of the image height")
      .def_readonly("offset", &sync::BandFit::offset, "camera frames")
      .def_readonly("sigma", &sync::BandFit::sigma, "camera frames")
      .def_readonly("rms", &sync::BandFit::rms, "fit residual over contrast")
      .def_readonly("used", &sync::BandFit::used, "sharp and showing the codes");
  py::class_<sync::ReadoutEstimate>(m, "ReadoutEstimate", "A rolling shutter's readout from bands of the image")
      .def_readonly("bands", &sync::ReadoutEstimate::bands, "every band that could be fitted")
      .def_readonly("valid", &sync::ReadoutEstimate::valid, "enough sharp bands, spread over the image")
      .def_readonly("readout", &sync::ReadoutEstimate::readout, "camera frames from the first row's start to the last's")
      .def_readonly("readout_sigma", &sync::ReadoutEstimate::readout_sigma, "1 sigma, camera frames")
      .def_readonly("first_row_offset", &sync::ReadoutEstimate::first_row_offset,
                    "offset of the frame map of the first row")
      .def_readonly("offset_sigma", &sync::ReadoutEstimate::offset_sigma, "camera frames")
      .def_readonly("applied", &sync::ReadoutEstimate::applied, "the frame map was moved to the first row")
      .def_readonly("bands_used", &sync::ReadoutEstimate::bands_used);
  py::class_<sync::SyncResult>(m, "SyncResult", "A camera's frame map found from the light codes")
      .def_readonly("map", &sync::SyncResult::map,
                    "the frame map (the first row's when a rolling-shutter readout was applied)")
      .def_readonly("window_map", &sync::SyncResult::window_map,
                    "covers the exposure window of every map that fits the codes as well (every row)")
      .def_readonly("start", &sync::SyncResult::start, "the start code's location")
      .def_readonly("end", &sync::SyncResult::end, "the end code's location")
      .def_readonly("offset_uncertainty", &sync::SyncResult::offset_uncertainty,
                    "camera frames: the offsets that explain the signal as well (about a frame when no camera "
                    "frame spans a light change)")
      .def_readonly("rate_uncertainty", &sync::SyncResult::rate_uncertainty, "camera frames per projector frame")
      .def_readonly("sharp", &sync::SyncResult::sharp, "the offsets that fit span at most two grid steps")
      .def_readonly("rms", &sync::SyncResult::rms, "joint fit residual as a share of the contrast")
      .def_property_readonly(
          "readout",
          [](const sync::SyncResult& r) -> std::optional<sync::ReadoutEstimate> {
            if (!r.readout.valid) return std::nullopt;
            return r.readout;
          },
          "the rolling-shutter readout, None when not measured");
}

void register_sync(py::module_& m) {
  RegisterSyncTypes(m);
  m.def("option_table", &SyncOptionTable, "Every sync knob as a Knob (name, default, help), in order.");
  m.def(
      "synchronise",
      [](const DoubleArray& signal, const DoubleArray& levels, const sync::LightCode& start_code,
         const sync::LightCode& end_code, double nominal_rate, const std::string& source,
         const py::kwargs& kwargs) {
        const sync::SyncOptions options = SyncOptionsFromKwargs(kwargs);
        const std::vector<double> values = ToVector(signal, "signal");
        const sync::LightTimeline timeline(ToVector(levels, "levels"));
        sync::SyncResult result;
        {
          py::gil_scoped_release release;
          result = sync::Synchronise(values, timeline, start_code, end_code, nominal_rate, options, source);
        }
        return result;
      },
      py::arg("signal"), py::arg("levels"), py::arg("start_code"), py::arg("end_code"), py::arg("nominal_rate"),
      py::arg("source") = "signal",
      "Frame map of a camera from its per-frame brightness `signal` (NaN = not measured), the "
      "projector's per-frame `levels` (0..1, NaN = unknown) and the light codes (LightCode); "
      "`nominal_rate` = camera fps / projector fps. Keyword "
      "options: see option_table(). RuntimeError naming `source` when a code is missing or "
      "the codes disagree.");
  m.def(
      "locate_code",
      [](const DoubleArray& signal, const DoubleArray& levels, const sync::LightCode& light_code,
         double nominal_rate, const std::string& source, const py::kwargs& kwargs) {
        const sync::SyncOptions options = SyncOptionsFromKwargs(kwargs);
        const std::vector<double> values = ToVector(signal, "signal");
        const sync::LightTimeline timeline(ToVector(levels, "levels"));
        sync::CodeLocation location;
        {
          py::gil_scoped_release release;
          location = sync::LocateCode(values, timeline, light_code, nominal_rate, options, source, "light");
        }
        return location;
      },
      py::arg("signal"), py::arg("levels"), py::arg("code"), py::arg("nominal_rate"), py::arg("source") = "signal",
      "Where one light code lies in a brightness signal (see synchronise).");
  m.def(
      "estimate_readout",
      [](const py::array_t<double, py::array::c_style | py::array::forcecast>& band_signals,
         const DoubleArray& levels, const sync::LightCode& start, const sync::LightCode& end,
         const sync::FrameMap& frame_map,
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
            CodeWindow(timeline, start, options, "start_code"), CodeWindow(timeline, end, options, "end_code")};
        if (!(frame_map.rate > 0.0) || !(frame_map.exposure > 0.0)) throw std::invalid_argument("map: bad rate or exposure");
        sync::ReadoutEstimate estimate;
        {
          py::gil_scoped_release release;
          estimate = sync::EstimateReadout(bands, timeline, windows, frame_map, options.fit);
        }
        return estimate;
      },
      py::arg("band_signals"), py::arg("levels"), py::arg("start_code"), py::arg("end_code"), py::arg("map"),
      "Rolling-shutter readout (camera frames) from the brightness of horizontal bands of the image "
      "(bands, frames), fitted around both light codes starting from the whole frame's map "
      "(a FrameMap); a ReadoutEstimate, with per band its row, offset, sigma, fit rms and whether it was used.");
}

}  // namespace calibproj::bindings
