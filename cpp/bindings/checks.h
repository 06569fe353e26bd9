#pragma once
// Checks of Python arguments shared by the binding files: array shapes, finite values,
// dictionary entries and keyword option values. Each throws an exception that pybind11
// turns into ValueError or TypeError naming the argument and the problem.

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <initializer_list>
#include <limits>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "calibproj/common/limits.h"

namespace calibproj::bindings {

using DoubleArray = pybind11::array_t<double, pybind11::array::c_style | pybind11::array::forcecast>;

// "(3, 2)", "(N, 2)" (-1 stands for any size).
inline std::string ShapeText(std::initializer_list<pybind11::ssize_t> shape) {
  std::string out = "(";
  for (const auto size : shape) out += (out.size() > 1 ? ", " : "") + (size < 0 ? "N" : std::to_string(size));
  return out + (shape.size() == 1 ? ",)" : ")");
}

inline std::string ShapeText(const pybind11::array& array) {
  std::string out = "(";
  for (pybind11::ssize_t d = 0; d < array.ndim(); ++d) out += (d ? ", " : "") + std::to_string(array.shape(d));
  return out + (array.ndim() == 1 ? ",)" : ")");
}

// Throws ValueError unless `array` has `shape` (-1: any size along that axis).
inline void RequireShape(const pybind11::array& array, std::initializer_list<pybind11::ssize_t> shape,
                         const std::string& what) {
  bool ok = array.ndim() == static_cast<pybind11::ssize_t>(shape.size());
  pybind11::ssize_t axis = 0;
  for (const auto size : shape) {
    if (ok && size >= 0 && array.shape(axis) != size) ok = false;
    ++axis;
  }
  if (!ok) throw std::invalid_argument(what + ": expected shape " + ShapeText(shape) + ", got " + ShapeText(array));
}

// Throws ValueError when a value is NaN or infinite.
inline void RequireFiniteValues(const DoubleArray& array, const std::string& what) {
  const double* data = array.data();
  for (pybind11::ssize_t i = 0; i < array.size(); ++i) {
    if (!std::isfinite(data[i])) {
      throw std::invalid_argument(what + ": non-finite value at flat index " + std::to_string(i));
    }
  }
}

// Throws ValueError naming `what` when `value` lies outside [lo, hi].
inline void RequireCount(long long value, long long lo, long long hi, const std::string& what) {
  if (value < lo || value > hi) {
    throw std::invalid_argument(what + " must be in [" + std::to_string(lo) + ", " + std::to_string(hi) + "], got " +
                                std::to_string(value));
  }
}

// The Python type's name of an object (its __name__: "ndarray", not "numpy.ndarray"), for
// messages.
inline std::string TypeName(const pybind11::handle& value) {
  const std::string name = Py_TYPE(value.ptr())->tp_name;
  return name.substr(name.rfind('.') + 1);
}

// What a value of type T is called in messages.
template <typename T>
struct Expected {
  static std::string Name() {
    if constexpr (std::is_same_v<T, bool>) return "True or False";
    else if constexpr (std::is_integral_v<T>) return "an integer";
    else if constexpr (std::is_floating_point_v<T>) return "a number";
    else if constexpr (std::is_same_v<T, std::string>) return "a string";
    else if constexpr (std::is_same_v<T, pybind11::dict>) return "a dict";
    else return "a list";
  }
};
template <typename Item>
struct Expected<std::vector<Item>> {
  static std::string Name() {
    if constexpr (std::is_arithmetic_v<Item>) {
      return std::is_integral_v<Item> ? "a list of integers" : "a list of numbers";
    } else {
      return "a list of lists";
    }
  }
};

// value cast to T; TypeError naming `what` when it cannot be, ValueError for an
// integer that T cannot hold (a negative seed, a count beyond 2^31).
template <typename T>
T CastTo(const pybind11::handle& value, const std::string& what) {
  try {
    return value.cast<T>();
  } catch (const pybind11::cast_error&) {
    if constexpr (std::is_integral_v<T> && !std::is_same_v<T, bool>) {
      if (pybind11::isinstance<pybind11::int_>(value) && !pybind11::isinstance<pybind11::bool_>(value)) {
        throw std::invalid_argument(what + ": " + std::string(pybind11::str(value)) + " is out of range (" +
                                    std::to_string(std::numeric_limits<T>::min()) + " to " +
                                    std::to_string(std::numeric_limits<T>::max()) + ")");
      }
    }
    throw pybind11::type_error(what + ": expected " + Expected<T>::Name() + ", got " + TypeName(value));
  }
}

// d[key] cast to T. The dicts hold documents (sequence.json, light codes), so a bad
// one is a ValueError, as the Python package reports a bad file: when `d` is not a
// dict, lacks `key` or has an entry of the wrong type.
template <typename T>
T DictItem(const pybind11::handle& d, const char* key, const std::string& what) {
  if (!pybind11::isinstance<pybind11::dict>(d)) {
    throw std::invalid_argument(what + ": expected a dict, got " + TypeName(d));
  }
  const auto dict = pybind11::reinterpret_borrow<pybind11::dict>(d);
  if (!dict.contains(key)) throw std::invalid_argument(what + ": missing entry '" + key + "'");
  const pybind11::object item = dict[key];
  try {
    return item.cast<T>();
  } catch (const pybind11::cast_error&) {
    throw std::invalid_argument(what + "['" + key + "']: expected " + Expected<T>::Name() + ", got " + TypeName(item));
  }
}

}  // namespace calibproj::bindings
