#pragma once
// Schema-versioned JSON files of calibproj (docs/conventions.md), read and written
// with the messages of the Python package, and atomic writes.

#include <filesystem>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace calibproj::formats {

// A bad input file or argument: printed as one line, exit status 2.
class InputError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Reads a calibproj JSON file of the given kind ("tracks", "intrinsics", ...), checking
// its "schema" tag; InputError names the file and the problem.
nlohmann::json ReadSchemaJson(const std::filesystem::path& path, const std::string& kind, int major);

// The same with every object's members in the file's order (where the order means
// something: a results file's cameras), accepting the kinds `also_accepted` too.
nlohmann::ordered_json ReadOrderedSchemaJson(const std::filesystem::path& path, const std::string& kind, int major,
                                             const std::vector<std::string>& also_accepted = {});

// Parses any JSON file (InputError naming the file when it is not JSON, or nests
// arrays and objects deeper than kMaxJsonDepth).
nlohmann::json ReadJson(const std::filesystem::path& path);
constexpr int kMaxJsonDepth = 512;

// Writes text to a temporary file in the same folder, syncs it, then renames it over
// `path`: readers see the old file or the whole new one. std::filesystem::filesystem_error
// with the system's error (a full disk, ...) when that fails; no temporary file stays.
void AtomicWrite(const std::filesystem::path& path, const std::string& text);

// Writes all of `data` to the file descriptor (retrying short writes); false with errno
// set when a write fails.
bool WriteFully(int fd, std::string_view data);

// A double as Python's repr() writes it (shortest digits that read back to the
// same value; fixed notation for exponents -4..15, with ".0" when integral), so that a
// file written here is byte for byte the one the Python package writes.
std::string PythonFloat(double value);

// JSON text as Python's json.dumps(value, indent=1) writes it: floats as repr() writes
// them, non-ASCII characters escaped. std::invalid_argument for a non-finite float.
std::string PythonJson(const nlohmann::ordered_json& value);

// Where the bytes stop being UTF-8, or npos.
size_t InvalidUtf8At(const std::string& text);

// The text without leading and trailing white space.
std::string Trimmed(const std::string& text);

// One number through printf's `format` ("%g", "%.4g", "%.0f"): Python's format
// specifications of the same name give the same text.
std::string FormatNumber(const char* format, double value);

// A string as Python's repr() writes it ('text', or "text" when it holds a ' and no "),
// for messages that quote what the user wrote as the Python package quotes it.
std::string PythonRepr(const std::string& text);

// The document with its schema tag first, as the Python writer writes it (PythonJson).
std::string DumpSchemaJson(const std::string& kind, int major, const nlohmann::ordered_json& body);

}  // namespace calibproj::formats
