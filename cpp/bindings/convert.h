#pragma once
// Conversions shared by the binding files: option strings to enums.

#include <map>
#include <stdexcept>
#include <string>

#include "calibproj/ba/bundle_adjuster.h"

namespace calibproj::bindings {

template <typename Enum>
Enum ParseChoice(const std::string& what, const std::string& value, const std::map<std::string, Enum>& choices) {
  const auto it = choices.find(value);
  if (it != choices.end()) return it->second;
  std::string names;
  for (const auto& [name, unused] : choices) names += (names.empty() ? "" : ", ") + name;
  throw std::invalid_argument(what + ": unknown value '" + value + "' (choose from " + names + ")");
}

inline ba::Model ParseModel(const std::string& value) {
  return ParseChoice<ba::Model>("model", value, {{"free", ba::Model::kFree}, {"coplanar", ba::Model::kCoplanar}});
}

inline ba::Loss ParseLoss(const std::string& value) {
  return ParseChoice<ba::Loss>("loss", value,
                               {{"none", ba::Loss::kNone}, {"huber", ba::Loss::kHuber}, {"cauchy", ba::Loss::kCauchy}});
}

}  // namespace calibproj::bindings
