#pragma once
// Typed values of the JSON documents calibproj reads, with the messages of the Python
// package's calibproj.formats.json_values (which now reads through here for the formats
// the C++ core owns). A number is a JSON number (not true, not "3"); an integer is a
// number without a fractional part. Every check throws std::invalid_argument naming
// the entry (`where`, e.g. "observations.cam0.xy"); each format's reader adds the file.

#include <nlohmann/json.hpp>

#include <cstdint>
#include <string>
#include <vector>

namespace calibproj::formats {

// A value as json.dumps writes it ("true", "null", "\"text\""), or its kind and
// beginning when longer than 40 characters.
std::string Describe(const nlohmann::json& value);

// Single values and flat lists with the type a schema gives them; std::invalid_argument
// naming `what` otherwise. nlohmann converts silently between booleans, floats and
// integers (true as 1, 1e30 as an int), so a file is read through these.
double NumberValue(const nlohmann::json& value, const std::string& what);
long long IntegerValue(const nlohmann::json& value, const std::string& what, long long lo, long long hi);
int IntValue(const nlohmann::json& value, const std::string& what);
bool BoolValue(const nlohmann::json& value, const std::string& what);
std::string StringValue(const nlohmann::json& value, const std::string& what);
std::vector<double> NumberList(const nlohmann::json& value, const std::string& what);
std::vector<int> IntList(const nlohmann::json& value, const std::string& what);


// Nested lists of numbers with rows of equal length: the numbers row-major and the
// lists' shape (an empty shape for a single number).
struct NumberArray {
  std::vector<double> values;
  std::vector<size_t> shape;
};

// Nested lists of numbers of any shape (or one number), finite, row-major.
NumberArray NumbersOf(const nlohmann::json& value, const std::string& where);

// `columns` > 0: a list of rows of that many numbers ("expected Nx2 numbers, ...");
// an empty list is no rows.
NumberArray NumberArrayOf(const nlohmann::json& value, const std::string& where, size_t columns);

// A list of integers (3 or 3.0) in [minimum, maximum].
std::vector<std::int64_t> IntegerListOf(const nlohmann::json& value, const std::string& where, std::int64_t minimum,
                                        std::int64_t maximum);

// A list of strings as Python's repr() of a list writes it: ['a', 'b'].
std::string PythonList(const std::vector<std::string>& items);

}  // namespace calibproj::formats
