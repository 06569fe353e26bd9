#include "calibproj/formats/json_values.h"

#include <cmath>
#include <limits>
#include <set>
#include <stdexcept>

#include "calibproj/formats/files.h"

namespace calibproj::formats {

namespace {

using json = nlohmann::json;

constexpr size_t kDescribeCharacters = 40;

// json.dumps(value) with its default separators ", " and ": ".
void AppendInline(std::string& out, const json& value) {
  switch (value.type()) {
    case json::value_t::number_float:
      out += PythonFloat(value.get<double>());
      return;
    case json::value_t::string:
      out += value.dump(-1, ' ', true, json::error_handler_t::replace);
      return;
    case json::value_t::array: {
      out += "[";
      bool first = true;
      for (const auto& item : value) {
        out += first ? "" : ", ";
        first = false;
        AppendInline(out, item);
      }
      out += "]";
      return;
    }
    case json::value_t::object: {
      out += "{";
      bool first = true;
      for (auto item = value.begin(); item != value.end(); ++item) {
        out += first ? "" : ", ";
        first = false;
        out += json(item.key()).dump(-1, ' ', true, json::error_handler_t::replace) + ": ";
        AppendInline(out, item.value());
      }
      out += "}";
      return;
    }
    default:
      out += value.dump();
  }
}

std::string KindOf(const json& value) {
  switch (value.type()) {
    case json::value_t::string:
      return "a string";
    case json::value_t::array:
      return "a list of " + std::to_string(value.size()) + " items";
    case json::value_t::object:
      return "an object of " + std::to_string(value.size()) + " items";
    case json::value_t::number_float:
      return "float";
    case json::value_t::boolean:
      return "bool";
    default:
      return "int";
  }
}

// The leaves of nested lists and the lists' shape; std::invalid_argument when rows
// differ in length or numbers and lists mix at one level.
void Flatten(const json& value, const std::string& where, std::vector<const json*>* leaves, std::vector<size_t>* dims) {
  if (!value.is_array()) {
    leaves->push_back(&value);
    return;
  }
  std::vector<const json*> level = {&value};
  const auto all_lists = [&level] {
    for (const json* item : level) {
      if (!item->is_array()) return false;
    }
    return true;
  };
  while (!level.empty() && all_lists()) {
    std::set<size_t> lengths;
    for (const json* item : level) lengths.insert(item->size());
    if (lengths.size() > 1) {
      std::string listed;
      int shown = 0;
      for (size_t length : lengths) {
        if (shown++ == 4) break;
        listed += (listed.empty() ? "" : ", ") + std::to_string(length);
      }
      throw std::invalid_argument(where + ": rows of different lengths (" + listed + ")");
    }
    dims->push_back(*lengths.begin());
    std::vector<const json*> next;
    for (const json* item : level) {
      for (const auto& leaf : *item) next.push_back(&leaf);
    }
    level = std::move(next);
  }
  for (const json* item : level) {
    if (item->is_array()) throw std::invalid_argument(where + ": numbers and lists mixed at one level");
  }
  *leaves = std::move(level);
}

void CheckNumbers(const std::vector<const json*>& leaves, const std::string& where) {
  for (const json* item : leaves) {
    if (!item->is_number()) throw std::invalid_argument(where + ": expected numbers, got " + Describe(*item));
  }
}

}  // namespace

std::string Describe(const json& value) {
  std::string written;
  AppendInline(written, value);
  if (written.size() <= kDescribeCharacters) return written;
  return KindOf(value) + " (" + written.substr(0, kDescribeCharacters) + "...)";
}

double NumberValue(const nlohmann::json& value, const std::string& what) {
  if (!value.is_number()) throw std::invalid_argument(what + ": expected a number, got " + Describe(value));
  const double number = value.get<double>();
  if (!std::isfinite(number)) throw std::invalid_argument(what + ": expected a finite number");
  return number;
}

long long IntegerValue(const nlohmann::json& value, const std::string& what, long long lo, long long hi) {
  const bool integral = value.is_number_integer() ||
                        (value.is_number_float() && value.get<double>() == std::floor(value.get<double>()));
  if (!integral) {
    throw std::invalid_argument(what + ": expected an integer, got " + Describe(value));
  }
  // Compared as doubles first: a float or an unsigned beyond the range does not convert.
  const double approximate = value.get<double>();
  if (!(approximate >= static_cast<double>(lo) && approximate <= static_cast<double>(hi))) {
    throw std::invalid_argument(what + ": " + Describe(value) + " is outside [" + std::to_string(lo) + ", " +
                                std::to_string(hi) + "]");
  }
  const long long integer = value.is_number_float() ? static_cast<long long>(approximate) : value.get<long long>();
  if (integer < lo || integer > hi) {
    throw std::invalid_argument(what + ": " + Describe(value) + " is outside [" + std::to_string(lo) + ", " +
                                std::to_string(hi) + "]");
  }
  return integer;
}

int IntValue(const nlohmann::json& value, const std::string& what) {
  return static_cast<int>(
      IntegerValue(value, what, std::numeric_limits<int>::min(), std::numeric_limits<int>::max()));
}

bool BoolValue(const nlohmann::json& value, const std::string& what) {
  if (!value.is_boolean()) throw std::invalid_argument(what + ": expected true or false, got " + Describe(value));
  return value.get<bool>();
}

std::string StringValue(const nlohmann::json& value, const std::string& what) {
  if (!value.is_string()) throw std::invalid_argument(what + ": expected a string, got " + Describe(value));
  return value.get<std::string>();
}

std::vector<double> NumberList(const nlohmann::json& value, const std::string& what) {
  if (!value.is_array()) throw std::invalid_argument(what + ": expected a list of numbers, got " + Describe(value));
  std::vector<double> out;
  for (const auto& item : value) out.push_back(NumberValue(item, what + "[" + std::to_string(out.size()) + "]"));
  return out;
}

std::vector<int> IntList(const nlohmann::json& value, const std::string& what) {
  if (!value.is_array()) throw std::invalid_argument(what + ": expected a list of integers, got " + Describe(value));
  std::vector<int> out;
  for (const auto& item : value) out.push_back(IntValue(item, what + "[" + std::to_string(out.size()) + "]"));
  return out;
}

NumberArray NumbersOf(const json& value, const std::string& where) {
  std::vector<const json*> leaves;
  NumberArray out;
  Flatten(value, where, &leaves, &out.shape);
  CheckNumbers(leaves, where);
  for (const json* leaf : leaves) {
    const double number = leaf->get<double>();
    if (!std::isfinite(number)) throw std::invalid_argument(where + ": numbers must be finite");
    out.values.push_back(number);
  }
  return out;
}

NumberArray NumberArrayOf(const json& value, const std::string& where, size_t columns) {
  NumberArray out = NumbersOf(value, where);
  if (out.shape == std::vector<size_t>{0}) {  // an empty list: no rows
    out.shape = {0, columns};
    return out;
  }
  if (out.shape.size() != 2 || out.shape[1] != columns) {
    std::string found;
    for (size_t d : out.shape) found += (found.empty() ? "" : "x") + std::to_string(d);
    throw std::invalid_argument(where + ": expected Nx" + std::to_string(columns) + " numbers, got " +
                                (found.empty() ? "a single number" : found));
  }
  return out;
}

std::vector<std::int64_t> IntegerListOf(const json& value, const std::string& where, std::int64_t minimum,
                                        std::int64_t maximum) {
  std::vector<const json*> leaves;
  std::vector<size_t> dims;
  Flatten(value, where, &leaves, &dims);
  if (dims.size() != 1) throw std::invalid_argument(where + ": expected a list of integers");
  CheckNumbers(leaves, where);
  // long double holds every int64 exactly, so the bounds compare as Python compares.
  const auto as_long_double = [](const json& v) {
    return v.is_number_unsigned() ? static_cast<long double>(v.get<std::uint64_t>())
           : v.is_number_integer() ? static_cast<long double>(v.get<std::int64_t>())
                                   : static_cast<long double>(v.get<double>());
  };
  const json *low = nullptr, *high = nullptr;
  for (const json* leaf : leaves) {
    if (!low || as_long_double(*leaf) < as_long_double(*low)) low = leaf;
    if (!high || as_long_double(*leaf) > as_long_double(*high)) high = leaf;
  }
  if (low && (as_long_double(*low) < minimum || as_long_double(*high) > maximum)) {
    const json& outside = as_long_double(*low) < minimum ? *low : *high;
    throw std::invalid_argument(where + ": integers must be in [" + std::to_string(minimum) + ", " +
                                std::to_string(maximum) + "], got " + Describe(outside));
  }
  std::vector<std::int64_t> out;
  for (const json* leaf : leaves) {
    if (leaf->is_number_float() && leaf->get<double>() != std::floor(leaf->get<double>())) {
      throw std::invalid_argument(where + ": expected integers, got " + PythonFloat(leaf->get<double>()));
    }
    out.push_back(leaf->is_number_float() ? static_cast<std::int64_t>(leaf->get<double>()) : leaf->get<std::int64_t>());
  }
  return out;
}

std::string PythonList(const std::vector<std::string>& items) {
  std::string out = "[";
  for (size_t k = 0; k < items.size(); ++k) out += (k ? ", " : "") + PythonRepr(items[k]);
  return out + "]";
}

}  // namespace calibproj::formats
