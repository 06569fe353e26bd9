#include "calibproj/formats/files.h"

#include "calibproj/formats/video_container.h"

#include <fcntl.h>
#include <unistd.h>

#include <cerrno>
#include <algorithm>
#include <cstdio>
#include <charconv>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <iterator>
#include <limits>

#include <fstream>
#include <random>
#include <regex>
#include <sstream>

namespace calibproj::formats {

std::string PythonFloat(double value) {
  if (std::isnan(value)) return "nan";
  if (std::isinf(value)) return value > 0 ? "inf" : "-inf";
  char buffer[64];
  const auto [end, error] = std::to_chars(buffer, buffer + sizeof(buffer), value, std::chars_format::scientific);
  if (error != std::errc()) throw std::runtime_error("cannot format a number");
  const std::string text(buffer, end);  // [-]d[.ddd]e(+|-)XX
  const size_t e = text.find('e');
  const bool negative = text[0] == '-';
  std::string digits;
  for (size_t i = negative ? 1 : 0; i < e; ++i) {
    if (text[i] != '.') digits += text[i];
  }
  const int exponent = std::stoi(text.substr(e + 1));
  std::string out = negative ? "-" : "";
  if (exponent < -4 || exponent >= 16) {
    out += digits.substr(0, 1);
    if (digits.size() > 1) out += "." + digits.substr(1);
    const std::string magnitude = std::to_string(std::abs(exponent));
    return out + "e" + (exponent < 0 ? "-" : "+") + (magnitude.size() < 2 ? "0" : "") + magnitude;
  }
  if (exponent < 0) return out + "0." + std::string(-exponent - 1, '0') + digits;
  if (digits.size() <= static_cast<size_t>(exponent) + 1) {
    return out + digits + std::string(exponent + 1 - digits.size(), '0') + ".0";
  }
  return out + digits.substr(0, exponent + 1) + "." + digits.substr(exponent + 1);
}

std::string Trimmed(const std::string& text) {
  const char* space = " \t\n\r\f\v";
  const size_t first = text.find_first_not_of(space);
  if (first == std::string::npos) return "";
  return text.substr(first, text.find_last_not_of(space) - first + 1);
}

std::string FormatNumber(const char* format, double value) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), format, value);
  return buffer;
}

std::string PythonRepr(const std::string& text) {
  const bool double_quotes = text.find('\'') != std::string::npos && text.find('"') == std::string::npos;
  const char quote = double_quotes ? '"' : '\'';
  std::string out(1, quote);
  for (const unsigned char c : text) {
    if (c == '\\' || c == quote) {
      out += '\\';
      out += static_cast<char>(c);
    } else if (c == '\n') {
      out += "\\n";
    } else if (c == '\r') {
      out += "\\r";
    } else if (c == '\t') {
      out += "\\t";
    } else if (c < 0x20 || c == 0x7f) {
      char hex[8];
      std::snprintf(hex, sizeof(hex), "\\x%02x", c);
      out += hex;
    } else {
      out += static_cast<char>(c);
    }
  }
  return out + quote;
}

namespace fs = std::filesystem;

size_t InvalidUtf8At(const std::string& text) {
  size_t i = 0;
  while (i < text.size()) {
    const unsigned char c = text[i];
    const int length = c < 0x80 ? 1 : (c >> 5) == 0x6 ? 2 : (c >> 4) == 0xE ? 3 : (c >> 3) == 0x1E ? 4 : 0;
    if (length == 0 || i + length > text.size()) return i;
    for (int k = 1; k < length; ++k) {
      if ((static_cast<unsigned char>(text[i + k]) >> 6) != 0x2) return i;
    }
    i += length;
  }
  return std::string::npos;
}

namespace {


// The first NaN, Infinity or -Infinity outside strings (Python's json writes them, but
// they are not JSON), with its offset; empty when there is none.
std::pair<std::string, size_t> NonJsonConstant(const std::string& text) {
  bool in_string = false;
  for (size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (in_string) {
      if (c == '\\') ++i;
      else if (c == '"') in_string = false;
      continue;
    }
    if (c == '"') {
      in_string = true;
      continue;
    }
    for (const char* name : {"NaN", "Infinity", "-Infinity"}) {
      if (text.compare(i, std::strlen(name), name) == 0) return {name, i};
    }
  }
  return {"", std::string::npos};
}

std::string Shortened(const std::string& text, size_t limit = 40) {
  return text.size() <= limit ? text
                              : text.substr(0, limit) + "... (" + std::to_string(text.size()) + " characters)";
}

// The problem of text that nlohmann refused, worded as the Python reader words it.
std::string JsonProblem(const std::string& text, const nlohmann::json::exception& error, size_t byte) {
  const auto [constant, at] = NonJsonConstant(text);
  if (!constant.empty() && at < byte) return constant + " is not a JSON number";
  std::string what = error.what();
  const std::string overflow = "number overflow parsing '";
  if (const size_t found = what.find(overflow); found != std::string::npos) {
    const std::string number = what.substr(found + overflow.size(), what.rfind('\'') - found - overflow.size());
    return "number " + Shortened(number) + " is beyond the range of a double";
  }
  if (what.rfind("[json.exception.", 0) == 0) what = what.substr(what.find("] ") + 2);
  // What the lexer read last quotes the file's bytes (control characters as <U+000A>).
  return std::regex_replace(what, std::regex("; last read: '.*?'(?=;|$)"), "");
}

// What was probably meant when a video was given as a calibproj file of `kind`.
std::string VideoGivenHint(const fs::path& path, const std::string& kind) {
  const fs::path folder = path.parent_path().empty() ? fs::path(".") : path.parent_path();
  if (kind == "sequence") {
    const fs::path beside = folder / "sequence.json";
    std::error_code error;
    if (fs::is_regular_file(beside, error)) return "; the sequence file beside it is " + beside.string();
    return "; give the sequence.json that calibproj generate wrote with it";
  }
  if (kind == "tracks") return "; camera videos are given as their folder (" + folder.string() + ")";
  return "";
}

// Where a calibproj file of kind `found` goes when it was given for one of kind `expected`.
std::string KindGivenHint(const std::string& found, const std::string& expected) {
  if (found == "sequence" && expected == "tracks") {
    return "; a sequence file is given with --sequence, the camera videos as their folder";
  }
  if (found == "tracks" && expected == "sequence") return "; a tracks file is given with --tracks";
  return "";
}

}  // namespace

namespace {

template <typename Json>
Json ParseJsonFile(const fs::path& path) {
  if (!fs::is_regular_file(path)) throw InputError(path.string() + ": no such file");
  std::ifstream in(path, std::ios::binary);
  const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (const std::string container = VideoContainerOf(text.substr(0, 1024)); !container.empty()) {
    throw InputError(path.string() + ": is a video (" + container + "), not a JSON file");
  }
  if (const size_t bad = InvalidUtf8At(text); bad != std::string::npos) {
    char byte[8];
    std::snprintf(byte, sizeof(byte), "0x%02x", static_cast<unsigned char>(text[bad]));
    throw InputError(path.string() + ": not valid JSON (not UTF-8: 'utf-8' codec can't decode byte " + byte +
                     " in position " + std::to_string(bad) + ")");
  }
  // Refused while parsing: freeing a much deeper document would overflow the stack.
  const auto limit_depth = [&path](int depth, typename Json::parse_event_t, Json&) {
    if (depth > kMaxJsonDepth) {
      throw InputError(path.string() + ": not valid JSON (arrays and objects nested deeper than " +
                       std::to_string(kMaxJsonDepth) + " levels)");
    }
    return true;
  };
  try {
    return Json::parse(text, limit_depth);
  } catch (const typename Json::parse_error& error) {
    throw InputError(path.string() + ": not valid JSON (" + JsonProblem(text, error, error.byte) + ")");
  } catch (const typename Json::exception& error) {
    throw InputError(path.string() + ": not valid JSON (" + JsonProblem(text, error, text.size()) + ")");
  }
}

template <typename Json>
Json ParseSchemaJsonFile(const fs::path& path, const std::string& kind, int major,
                         const std::vector<std::string>& also_accepted) {
  if (const std::string container = VideoContainerOfFile(path); !container.empty()) {
    throw InputError(path.string() + ": is a video (" + container + "), not a calibproj " + kind + " file" +
                     VideoGivenHint(path, kind));
  }
  Json document = ParseJsonFile<Json>(path);
  if (!document.is_object()) throw InputError(path.string() + ": expected a JSON object at the top level");
  const std::string expected = "calibproj." + kind + "/" + std::to_string(major);
  const auto tag_it = document.find("schema");
  const std::string tag = (tag_it != document.end() && tag_it->is_string()) ? tag_it->template get<std::string>() : "";
  const std::string prefix = "calibproj.";
  const auto slash = tag.find('/');
  if (tag.rfind(prefix, 0) != 0 || slash == std::string::npos) {
    const std::string found = tag_it == document.end() ? "None"
                              : tag_it->is_string() ? PythonRepr(tag)
                              : tag_it->is_null()   ? "None"
                              : tag_it->is_boolean() ? (tag_it->template get<bool>() ? "True" : "False")
                                                     : tag_it->dump();
    throw InputError(path.string() + ": not a calibproj " + kind + " file (schema " + found + ", expected '" +
                     expected + "')");
  }
  const std::string found_kind = tag.substr(prefix.size(), slash - prefix.size());
  const std::string found_major = tag.substr(slash + 1);
  if (found_kind != kind &&
      std::find(also_accepted.begin(), also_accepted.end(), found_kind) == also_accepted.end()) {
    throw InputError(path.string() + ": is a calibproj " + found_kind + " file, expected " + kind + " ('" + expected +
                     "')" + KindGivenHint(found_kind, kind));
  }
  if (found_major.empty() || found_major.find_first_not_of("0123456789") != std::string::npos ||
      std::stoi(found_major) > major) {
    throw InputError(path.string() + ": schema '" + tag + "' is newer than this calibproj reads ('" + prefix +
                     found_kind + "/" + std::to_string(major) + "'); upgrade calibproj");
  }
  return document;
}

}  // namespace

nlohmann::json ReadJson(const fs::path& path) { return ParseJsonFile<nlohmann::json>(path); }

nlohmann::json ReadSchemaJson(const fs::path& path, const std::string& kind, int major) {
  return ParseSchemaJsonFile<nlohmann::json>(path, kind, major, {});
}

nlohmann::ordered_json ReadOrderedSchemaJson(const fs::path& path, const std::string& kind, int major,
                                             const std::vector<std::string>& also_accepted) {
  return ParseSchemaJsonFile<nlohmann::ordered_json>(path, kind, major, also_accepted);
}

bool WriteFully(int fd, std::string_view data) {
  while (!data.empty()) {
    const ssize_t written = write(fd, data.data(), data.size());
    if (written < 0 && errno == EINTR) continue;
    if (written <= 0) {
      if (written == 0) errno = EIO;
      return false;
    }
    data.remove_prefix(static_cast<size_t>(written));
  }
  return true;
}

namespace {

// A new file `.<name>.<random>.tmp` beside `path`, opened for writing, with the
// permissions a plain open() gives.
int CreateTemporaryBeside(const fs::path& path, fs::path* temporary) {
  const fs::path folder = path.has_parent_path() ? path.parent_path() : fs::path(".");
  std::random_device random;
  constexpr int kAttempts = 100;
  for (int attempt = 0; attempt < kAttempts; ++attempt) {
    *temporary = folder / ("." + path.filename().string() + "." + std::to_string(random()) + ".tmp");
    const int fd = open(temporary->c_str(), O_WRONLY | O_CREAT | O_EXCL | O_CLOEXEC, 0666);
    if (fd >= 0) return fd;
    if (errno != EEXIST) {
      throw fs::filesystem_error("cannot create", *temporary, std::error_code(errno, std::system_category()));
    }
  }
  throw fs::filesystem_error("cannot create", *temporary, std::make_error_code(std::errc::file_exists));
}

}  // namespace

void AtomicWrite(const fs::path& path, const std::string& text) {
  // The file is replaced whole: a device, a pipe or a folder there would be replaced
  // too (as root, "/dev/null" became a plain file).
  std::error_code ignored;
  const fs::file_status existing = fs::status(path, ignored);
  if (fs::exists(existing) && !fs::is_regular_file(existing)) {
    throw fs::filesystem_error("cannot write over what is not a regular file", path,
                               std::make_error_code(std::errc::file_exists));
  }
  if (path.has_parent_path()) fs::create_directories(path.parent_path());
  fs::path temporary;
  const int fd = CreateTemporaryBeside(path, &temporary);
  int error = 0;
  if (!WriteFully(fd, text) || fsync(fd) != 0) error = errno;
  if (close(fd) != 0 && error == 0) error = errno;
  std::error_code failure = error ? std::error_code(error, std::system_category()) : std::error_code();
  if (!failure) fs::rename(temporary, path, failure);
  if (failure) {
    unlink(temporary.c_str());
    throw fs::filesystem_error("cannot write", path, failure);
  }
}

namespace {

void AppendPythonJson(std::string& out, const nlohmann::ordered_json& value, int depth) {
  using value_t = nlohmann::ordered_json::value_t;
  const auto newline = [&out](int level) { out += "\n" + std::string(level, ' '); };
  switch (value.type()) {
    case value_t::number_float: {
      const double number = value.get<double>();
      // Python's json.dumps(allow_nan=False) refuses these as well.
      if (!std::isfinite(number)) throw std::invalid_argument("Out of range float values are not JSON compliant");
      out += PythonFloat(number);
      return;
    }
    case value_t::string:
      // ensure_ascii as Python's default; bytes that are not UTF-8 (a reason quoting a
      // malformed input file) become U+FFFD instead of making the file unwritable.
      out += value.dump(-1, ' ', true, nlohmann::ordered_json::error_handler_t::replace);
      return;
    case value_t::array:
    case value_t::object: {
      const bool object = value.is_object();
      if (value.empty()) {
        out += object ? "{}" : "[]";
        return;
      }
      out += object ? "{" : "[";
      bool first = true;
      for (auto item = value.begin(); item != value.end(); ++item) {
        if (!first) out += ",";
        first = false;
        newline(depth + 1);
        if (object) {
          out += nlohmann::ordered_json(item.key()).dump(-1, ' ', true, nlohmann::ordered_json::error_handler_t::replace);
          out += ": ";
        }
        AppendPythonJson(out, item.value(), depth + 1);
      }
      newline(depth);
      out += object ? "}" : "]";
      return;
    }
    default:
      out += value.dump();
  }
}

}  // namespace

std::string PythonJson(const nlohmann::ordered_json& value) {
  std::string out;
  AppendPythonJson(out, value, 0);
  return out;
}

std::string DumpSchemaJson(const std::string& kind, int major, const nlohmann::ordered_json& body) {
  nlohmann::ordered_json document;
  document["schema"] = "calibproj." + kind + "/" + std::to_string(major);
  for (const auto& [key, value] : body.items()) document[key] = value;
  return PythonJson(document) + "\n";
}

}  // namespace calibproj::formats
