#pragma once
// One keyword option onto the field of an option table (a Visit*Options walk) that
// bears its name; an enumerated knob (registration::Choices<>) by the name of its choice.

#include <pybind11/pybind11.h>

#include <string>
#include <type_traits>

#include "checks.h"
#include "convert.h"

namespace calibproj::bindings {

struct KnobSetter {
  const std::string& key;
  const pybind11::handle& value;
  std::string what;  // names the option in errors
  bool found = false;

  template <typename T>
  void operator()(const char* name, T& field, const char* /*help*/) {
    if (key != name) return;
    found = true;
    if constexpr (std::is_enum_v<T>) {
      field = ParseKnob<T>(what, CastTo<std::string>(value, what));
    } else {
      field = CastTo<T>(value, what);
    }
  }
};

// Per knob of an option struct, in order: {name, default, help}; `visit(options,
// visitor)` walks its table.
template <typename Options, typename Visit>
pybind11::list KnobTable(Visit&& visit) {
  Options o;
  pybind11::list table;
  visit(o, [&table](const char* name, const auto& field, const char* help) {
    pybind11::dict entry;
    entry["name"] = name;
    entry["default"] = field;
    entry["help"] = help;
    table.append(entry);
  });
  return table;
}

}  // namespace calibproj::bindings
