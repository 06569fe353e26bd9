// provenance.json as the core writes it (formats/provenance.h), bound so that the Python
// commands record their calibrations with the same writer as calibproj-native.

#include <pybind11/functional.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <cmath>
#include <functional>
#include <stdexcept>
#include <string>

#include "calibproj/formats/files.h"
#include "calibproj/formats/provenance.h"
#include "calibproj/registration/option_table.h"
#include "knob_setter.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

using formats::ProvenanceInput;
using formats::ProvenanceRecord;
using formats::ScaleSource;

void register_provenance(py::module_& m) {
  m.attr("provenance_file") = formats::kProvenanceFile;
  m.attr("max_hashed_bytes") = formats::kMaxHashedBytes;
  m.attr("version") = formats::Version();
  m.def("path_as_recorded", &formats::PathAsRecorded, py::arg("path"), py::arg("folder"),
        "How a results folder records an input's path: relative to the folder when the input lies beside it\n"
        "(under the folder's parent), absolute otherwise.");

  py::class_<ProvenanceInput>(m, "ProvenanceInput",
                              "One input of a calibration: a path (identified when the record is written) or what was\n"
                              "given instead of one (e.g. 'Tracks given in memory').")
      .def(py::init([](const std::string& path, const std::string& given) { return ProvenanceInput{path, given}; }),
           py::arg("path") = "", py::arg("given") = "")
      .def_readwrite("path", &ProvenanceInput::path)
      .def_readwrite("given", &ProvenanceInput::given);

  py::class_<ScaleSource>(m, "ScaleSource", "Where the metric scale came from: the measurement, and its factor or "
                                            "why none applied.")
      .def(py::init([](const std::string& measurement, std::optional<double> metres_per_unit,
                       const std::string& error) {
             if (metres_per_unit && !(std::isfinite(*metres_per_unit) && *metres_per_unit > 0.0)) {
               throw std::invalid_argument("metres_per_unit: expected a positive finite number, got " +
                                           formats::PythonFloat(*metres_per_unit));
             }
             return ScaleSource{measurement, metres_per_unit, error};
           }),
           py::arg("measurement"), py::arg("metres_per_unit") = std::nullopt, py::arg("error") = "")
      .def_readwrite("measurement", &ScaleSource::measurement)
      .def_readwrite("metres_per_unit", &ScaleSource::metres_per_unit)
      .def_readwrite("error", &ScaleSource::error);

  py::class_<ProvenanceRecord>(m, "ProvenanceRecord", R"doc(What a tool knows of a calibration it writes
(provenance.json, calibproj.provenance/1); write() adds the date, version, platform and the
inputs' identities (paths as the folder records them, SHA-256 of the files).)doc")
      .def(py::init<>())
      .def_readwrite("command", &ProvenanceRecord::command, "The command line; None for a call of the Python API.")
      .def_readwrite("runtime", &ProvenanceRecord::runtime,
                     "(name, value) pairs the front end adds after the command (Python: its version).")
      .def_readwrite("source", &ProvenanceRecord::source)
      .def_readwrite("sequence", &ProvenanceRecord::sequence)
      .def_readwrite("intrinsics", &ProvenanceRecord::intrinsics)
      .def_readwrite("merged", &ProvenanceRecord::merged)
      .def_readwrite("checked", &ProvenanceRecord::checked)
      .def_readwrite("videos", &ProvenanceRecord::videos, "(camera, video file or live source URL) pairs.")
      .def_readwrite("markers", &ProvenanceRecord::markers)
      .def_readwrite("model", &ProvenanceRecord::model)
      .def_readwrite("scale", &ProvenanceRecord::scale)
      .def(
          "set_options",
          [](ProvenanceRecord& record, const py::kwargs& options) {
            record.options = OptionsFromKeywords<registration::Options>(
                options, "registration",
                [](auto& o, auto&& visitor) { registration::VisitRegistrationOptions(o, visitor); });
          },
          "The registration options the calibration used (keyword values, as RegistrationOptions holds them).")
      .def(
          "write",
          [](const ProvenanceRecord& record, const std::filesystem::path& staging,
             const std::filesystem::path& folder, const std::function<void(const std::string&)>& log) {
            formats::WriteProvenance(staging, formats::ProvenanceDocument(record, folder, log));
          },
          py::arg("staging"), py::arg("folder"), py::arg("log") = std::function<void(const std::string&)>(),
          "Writes staging/provenance.json for a results folder that will finally be at `folder` (paths beside\n"
          "it recorded relative to it); `log(line)` hears of an input that could not be identified.");
}

}  // namespace calibproj::bindings
