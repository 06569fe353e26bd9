#pragma once
// One keyword option onto the field of an option table (a Visit*Options walk) that
// bears its name; an enumerated knob (registration::Choices<>) by the name of its choice.

#include <pybind11/pybind11.h>

#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

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

// One knob of an option table as Python sees it (_core.Knob): the Python options
// classes and both command lines are made from these.
struct Knob {
  std::string name;
  pybind11::object default_value;     // bool, int, float or str (an enumerated knob's choice)
  std::string help;
  std::vector<std::string> choices;   // an enumerated knob's; empty otherwise
};

// The names of a table, "a, b, c".
std::string KnobNames(const std::vector<Knob>& table);

// Per knob of an option struct, in order; `visit(options, visitor)` walks its table.
template <typename Options, typename Visit>
std::vector<Knob> KnobTable(Visit&& visit) {
  Options o;
  std::vector<Knob> table;
  visit(o, [&table](const char* name, const auto& field, const char* help) {
    table.push_back({name, pybind11::cast(field), help, {}});
  });
  return table;
}

// Options of a table (`visit(options, visitor)` walks it) from keyword values, checked by
// the options' own Check(); an unknown name raises std::invalid_argument naming `what`
// ("check", "self-calibration") and the knobs there are.
template <typename Options, typename Visit>
Options OptionsFromKeywords(const pybind11::dict& values, const std::string& what, Visit&& visit) {
  Options options;
  for (const auto& item : values) {
    const std::string key = pybind11::str(item.first);
    KnobSetter setter{key, item.second, what + " option '" + key + "'"};
    visit(options, setter);
    if (!setter.found) {
      throw std::invalid_argument(what + ": unknown option '" + key + "' (choose from " +
                                  KnobNames(KnobTable<Options>(visit)) + ")");
    }
  }
  options.Check();
  return options;
}

}  // namespace calibproj::bindings
