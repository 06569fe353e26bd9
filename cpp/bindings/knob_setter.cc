// The Knob class: one entry of an option table, as the Python options classes read it.

#include "knob_setter.h"

#include <pybind11/stl.h>

#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

std::string KnobNames(const std::vector<Knob>& table) {
  std::string names;
  for (const Knob& knob : table) names += (names.empty() ? "" : ", ") + knob.name;
  return names;
}

void register_knob(py::module_& m) {
  py::class_<Knob>(m, "Knob",
                   "One knob of an option table (each stage's option_table()): the one declaration its Python "
                   "options class and both command lines are made from")
      .def_readonly("name", &Knob::name)
      .def_readonly("default", &Knob::default_value, "bool, int, float, or str for an enumerated knob")
      .def_readonly("help", &Knob::help)
      .def_property_readonly(
          "choices", [](const Knob& k) { return py::tuple(py::cast(k.choices)); },
          "an enumerated knob's choices; empty otherwise")
      .def("__repr__", [](const Knob& k) {
        return "Knob(" + k.name + "=" + py::repr(k.default_value).cast<std::string>() + ")";
      });
}

}  // namespace calibproj::bindings
