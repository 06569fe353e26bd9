#pragma once
// JSON documents between the C++ core (nlohmann::json) and Python (dict, list, str,
// int, float, bool, None), so that a document the core reads or writes crosses the
// binding as Python values, not as text parsed again on the other side.

#include <pybind11/pybind11.h>

#include <nlohmann/json.hpp>

#include <cmath>
#include <stdexcept>
#include <string>

#include "checks.h"

namespace calibproj::bindings {

// Nesting of a document handed in from Python (the files' own limit, formats::kMaxJsonDepth).
constexpr int kMaxDocumentDepth = 512;

inline pybind11::object JsonToPython(const nlohmann::json& value) {
  namespace py = pybind11;
  switch (value.type()) {
    case nlohmann::json::value_t::object: {
      py::dict out;
      for (auto item = value.begin(); item != value.end(); ++item) out[py::str(item.key())] = JsonToPython(item.value());
      return std::move(out);
    }
    case nlohmann::json::value_t::array: {
      py::list out;
      for (const auto& item : value) out.append(JsonToPython(item));
      return std::move(out);
    }
    case nlohmann::json::value_t::string:
      return py::str(value.get_ref<const std::string&>());
    case nlohmann::json::value_t::boolean:
      return py::bool_(value.get<bool>());
    case nlohmann::json::value_t::number_integer:
      return py::int_(value.get<long long>());
    case nlohmann::json::value_t::number_unsigned:
      return py::int_(value.get<unsigned long long>());
    case nlohmann::json::value_t::number_float:
      return py::float_(value.get<double>());
    default:
      return py::none();
  }
}

// A Python value as json.dumps would write it (dict keys must be strings; tuples are
// lists; numpy scalars are numbers). std::invalid_argument naming `where` for anything
// else, a non-finite float, an integer beyond 64 bits or nesting deeper than the files allow.
// Json = nlohmann::ordered_json keeps the dicts' order, as json.dumps does.
template <typename Json = nlohmann::json>
Json PythonToJson(const pybind11::handle& value, const std::string& where, int depth = 0) {
  namespace py = pybind11;
  if (depth > kMaxDocumentDepth) throw std::invalid_argument(where + ": nested deeper than 512 levels");
  if (value.is_none()) return nullptr;
  if (py::isinstance<py::bool_>(value)) return value.cast<bool>();
  if (py::isinstance<py::str>(value)) return value.cast<std::string>();
  if (py::isinstance<py::dict>(value)) {
    Json out = Json::object();
    for (const auto& item : py::reinterpret_borrow<py::dict>(value)) {
      if (!py::isinstance<py::str>(item.first)) {
        throw std::invalid_argument(where + ": keys must be strings, got " + TypeName(item.first));
      }
      const std::string key = item.first.cast<std::string>();
      out[key] = PythonToJson<Json>(item.second, where + "['" + key + "']", depth + 1);
    }
    return out;
  }
  if (py::isinstance<py::list>(value) || py::isinstance<py::tuple>(value)) {
    Json out = Json::array();
    size_t index = 0;
    for (const auto& item : value) {
      out.push_back(PythonToJson<Json>(item, where + "[" + std::to_string(index++) + "]", depth + 1));
    }
    return out;
  }
  if (py::hasattr(value, "__index__")) {  // int and numpy's integers
    PyObject* index = PyNumber_Index(value.ptr());
    if (index == nullptr) throw py::error_already_set();
    try {
      return py::reinterpret_steal<py::int_>(index).cast<long long>();
    } catch (const py::cast_error&) {
      throw std::invalid_argument(where + ": integer beyond 64 bits");
    }
  }
  if (py::hasattr(value, "__float__")) {
    const double number = py::float_(py::reinterpret_borrow<py::object>(value)).cast<double>();
    if (!std::isfinite(number)) throw std::invalid_argument(where + ": expected a finite number");
    return number;
  }
  throw std::invalid_argument(where + ": " + TypeName(value) + " is not a JSON value");
}

}  // namespace calibproj::bindings
