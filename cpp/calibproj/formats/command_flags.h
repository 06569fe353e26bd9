#pragma once
// The command-line flags that calibproj's commands and calibproj-native's both take,
// declared once with their help text: the Python parsers (calibproj.cli) and the
// executable's (cpp/app) are made from this table, so both tools describe a flag in the
// same words. Whether a flag is required, its type and its default stay with each tool.

#include <string>
#include <vector>

namespace calibproj::formats {

struct CommandFlag {
  std::string command;  // calibrate, detect, check or capture
  std::string name;     // "--scale"
  std::string metavar;  // "MEASUREMENT"; empty for a switch
  std::string help;
};

// Every shared flag, by command.
const std::vector<CommandFlag>& SharedCommandFlags();

// The flag `name` of `command`; std::invalid_argument when the table has none.
const CommandFlag& SharedFlag(const std::string& command, const std::string& name);

}  // namespace calibproj::formats
