#include "files.h"

#include <charconv>
#include <cstdlib>

#include <fstream>
#include <random>
#include <sstream>

namespace calibproj::app {

std::string PythonFloat(double value) {
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


namespace fs = std::filesystem;

nlohmann::json ReadJson(const fs::path& path) {
  if (!fs::is_regular_file(path)) throw InputError(path.string() + ": no such file");
  std::ifstream in(path);
  try {
    return nlohmann::json::parse(in);
  } catch (const nlohmann::json::parse_error& error) {
    throw InputError(path.string() + ": not valid JSON (" + error.what() + ")");
  }
}

nlohmann::json ReadSchemaJson(const fs::path& path, const std::string& kind, int major) {
  const nlohmann::json document = ReadJson(path);
  if (!document.is_object()) throw InputError(path.string() + ": expected a JSON object at the top level");
  const std::string expected = "calibproj." + kind + "/" + std::to_string(major);
  const auto tag_it = document.find("schema");
  const std::string tag = (tag_it != document.end() && tag_it->is_string()) ? tag_it->get<std::string>() : "";
  const std::string prefix = "calibproj.";
  const auto slash = tag.find('/');
  if (tag.rfind(prefix, 0) != 0 || slash == std::string::npos) {
    throw InputError(path.string() + ": not a calibproj " + kind + " file (schema " +
                     (tag.empty() ? std::string("None") : "'" + tag + "'") + ", expected '" + expected + "')");
  }
  const std::string found_kind = tag.substr(prefix.size(), slash - prefix.size());
  const std::string found_major = tag.substr(slash + 1);
  if (found_kind != kind) {
    throw InputError(path.string() + ": is a calibproj " + found_kind + " file, expected " + kind + " ('" + expected +
                     "')");
  }
  if (found_major.empty() || found_major.find_first_not_of("0123456789") != std::string::npos ||
      std::stoi(found_major) > major) {
    throw InputError(path.string() + ": schema '" + tag + "' is newer than this calibproj reads ('" + expected +
                     "'); upgrade calibproj");
  }
  return document;
}

void AtomicWrite(const fs::path& path, const std::string& text) {
  if (!path.parent_path().empty()) fs::create_directories(path.parent_path());
  std::random_device random;
  const fs::path tmp = path.parent_path() / ("." + path.filename().string() + "." + std::to_string(random()) + ".tmp");
  {
    std::ofstream out(tmp, std::ios::binary);
    out << text;
    out.flush();
    if (!out) {
      std::error_code ignored;
      fs::remove(tmp, ignored);
      throw std::runtime_error(path.string() + ": cannot write");
    }
  }
  fs::rename(tmp, path);
}

std::string DumpSchemaJson(const std::string& kind, int major, const nlohmann::ordered_json& body) {
  nlohmann::ordered_json document;
  document["schema"] = "calibproj." + kind + "/" + std::to_string(major);
  for (const auto& [key, value] : body.items()) document[key] = value;
  return document.dump(1) + "\n";
}

}  // namespace calibproj::app
