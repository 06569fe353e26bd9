// The results-folder transaction of the core (formats/output_folder.h), bound so that the
// Python commands write their outputs through the same code as calibproj-native.

#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <memory>
#include <optional>

#include "calibproj/formats/output_folder.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

using formats::OutputFile;
using formats::OutputFolder;

// None when there is no staging folder, else its path.
std::optional<std::filesystem::path> StagingOf(const OutputFolder& folder) {
  if (folder.staging().empty()) return std::nullopt;
  return folder.staging();
}

}  // namespace

void register_output_folder(py::module_& m) {
  // Registered after InputError, so that an OutputError (an InputError in C++) is
  // translated as itself.
  py::register_exception<formats::OutputError>(m, "OutputError", PyExc_ValueError);
  py::register_exception<formats::OutputBusyError>(m, "OutputBusyError", PyExc_RuntimeError);
  m.attr("min_free_bytes") = formats::kMinFreeBytes;

  py::class_<OutputFolder>(m, "OutputFolder", R"doc(A folder written as one transaction.

open() checks that the folder can be written (OutputError naming it when it cannot),
takes the lock `.<name>.lock` beside it (OutputBusyError when another run holds it) and
creates the staging folder `.<name>.tmp-XXXXXX`; the work writes into `staging`;
commit() moves it into place (the previous folder aside, the new one in, the previous
one deleted); abort() deletes it and leaves the previous folder as it was.

signature: files of which at least one marks a folder this command wrote; a non-empty
folder holding none of them is refused, with force or without.
min_free_bytes: the free space below which open() refuses.)doc")
      .def(py::init([](const std::filesystem::path& path, bool force, std::vector<std::string> signature,
                       std::uintmax_t min_free_bytes) {
             return std::make_unique<OutputFolder>(path.string(), force, std::move(signature), nullptr,
                                                   min_free_bytes);
           }),
           py::arg("path"), py::kw_only(), py::arg("force") = false,
           py::arg("signature") = std::vector<std::string>{}, py::arg("min_free_bytes") = formats::kMinFreeBytes)
      .def("open", &OutputFolder::Open, py::call_guard<py::gil_scoped_release>(),
           "Checks, locks, and creates the staging folder (before any long work)")
      .def("commit", &OutputFolder::Commit, py::call_guard<py::gil_scoped_release>(),
           "Moves the staging folder into place and releases the lock")
      .def("abort", &OutputFolder::Abort, py::call_guard<py::gil_scoped_release>(),
           "Deletes the staging folder and releases the lock; the previous folder stays")
      .def_property_readonly("path", &OutputFolder::path,
                             "The folder (where a symbolic link leads, once open)")
      .def_property_readonly("staging", &StagingOf, "The staging folder while it is open, else None");

  py::class_<OutputFile>(m, "OutputFile", R"doc(The checks and the lock of OutputFolder for a single file.

open() fails in one line naming the path when it is an existing folder, one of the run's
`inputs`, an existing file and `force` is off, its folder cannot be written, the disk is
full, or another run holds its lock; close() releases the lock.)doc")
      .def(py::init([](const std::filesystem::path& path, bool force, const std::vector<std::filesystem::path>& inputs,
                       std::uintmax_t min_free_bytes) {
             std::vector<std::string> names;
             for (const auto& input : inputs) names.push_back(input.string());
             return std::make_unique<OutputFile>(path.string(), force, std::move(names), nullptr, min_free_bytes);
           }),
           py::arg("path"), py::kw_only(), py::arg("force") = false,
           py::arg("inputs") = std::vector<std::filesystem::path>{}, py::arg("min_free_bytes") = formats::kMinFreeBytes)
      .def("open", &OutputFile::Open, py::call_guard<py::gil_scoped_release>(),
           "Checks that the file can be written and takes its lock")
      .def("close", &OutputFile::Close, py::call_guard<py::gil_scoped_release>(), "Releases the lock")
      .def_property_readonly("path", &OutputFile::path, "The file");
}

}  // namespace calibproj::bindings
