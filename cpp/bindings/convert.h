#pragma once
// Conversions shared by the binding files: option strings to enums, numpy rows to
// fixed-width Eigen matrices.

#include <map>
#include <stdexcept>
#include <string>

#include "calibproj/ba/bundle_adjuster.h"
#include "calibproj/registration/option_table.h"

namespace calibproj::bindings {

template <typename Enum>
Enum ParseChoice(const std::string& what, const std::string& value, const std::map<std::string, Enum>& choices) {
  const auto it = choices.find(value);
  if (it != choices.end()) return it->second;
  std::string names;
  for (const auto& [name, unused] : choices) names += (names.empty() ? "" : ", ") + name;
  throw std::invalid_argument(what + ": unknown value '" + value + "' (choose from " + names + ")");
}

// An enumerated knob of registration::Choices<> by name; std::invalid_argument naming
// `what` and the choices otherwise.
template <typename Enum>
Enum ParseKnob(const std::string& what, const std::string& value) {
  Enum out{};
  if (!registration::ChoiceFromName(value, &out)) {
    throw std::invalid_argument(what + ": unknown value '" + value + "' (choose from " +
                                registration::ChoiceList<Enum>() + ")");
  }
  return out;
}

inline ba::Model ParseModel(const std::string& value) { return ParseKnob<ba::Model>("model", value); }

using RowMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

// `array` as a matrix of `cols` columns; std::invalid_argument naming `what` otherwise
// (an empty array gives an empty matrix whatever its shape).
template <typename Matrix>
Matrix RowsOf(const RowMatrix& array, int cols, const std::string& what) {
  if (array.cols() != cols && array.size() > 0) {
    throw std::invalid_argument(what + ": expected shape (N, " + std::to_string(cols) + "), got (" +
                                std::to_string(array.rows()) + ", " + std::to_string(array.cols()) + ")");
  }
  Matrix out(array.rows(), cols);
  if (array.size() > 0) out = array;
  return out;
}

inline ba::Loss ParseLoss(const std::string& value) { return ParseKnob<ba::Loss>("loss", value); }

}  // namespace calibproj::bindings
