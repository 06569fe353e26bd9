#pragma once
// Command-line flags made from an option table (a Visit*Options walk): one per knob,
// dashed, with the table's help and the struct's default; a bool as --knob/--no-knob,
// an enumerated knob (registration::Choices<>) by the names of its choices.

#include <CLI/CLI.hpp>

#include <algorithm>
#include <string>
#include <type_traits>
#include <vector>

#include "calibproj/formats/command_flags.h"
#include "calibproj/formats/files.h"
#include "calibproj/registration/option_table.h"

namespace calibproj::app {

// The options' own check (std::invalid_argument naming the first bad knob) as a bad
// invocation: formats::InputError, exit status 2.
template <typename Options>
void RequireValidOptions(const Options& options) {
  try {
    options.Check();
  } catch (const std::invalid_argument& error) {
    throw formats::InputError(error.what());
  }
}

// A visitor for Visit*Options that adds each knob to `command` in `group`.
inline auto TableFlags(CLI::App* command, const std::string& group) {
  return [command, group](const std::string& name, auto& field, const std::string& help) {
    using T = std::decay_t<decltype(field)>;
    std::string flag = "--" + name;
    std::replace(flag.begin(), flag.end(), '_', '-');
    if constexpr (std::is_same_v<T, bool>) {
      command->add_flag(flag + ",!--no-" + flag.substr(2), field, help)->capture_default_str()->group(group);
    } else if constexpr (std::is_enum_v<T>) {
      std::vector<std::string> names;
      for (const auto& [choice, unused] : registration::Choices<T>::All()) names.push_back(choice);
      command
          ->add_option_function<std::string>(
              flag, [&field](const std::string& text) { registration::ChoiceFromName(text, &field); }, help)
          ->check(CLI::IsMember(names))
          ->type_name("CHOICE")
          ->default_str(registration::ChoiceName(field))
          ->group(group);
    } else {
      command->add_option(flag, field, help)->capture_default_str()->group(group);
    }
  };
}

// A flag both tools take (formats::SharedFlag): its name, metavar and help from the
// table, `value` filled by CLI11; a switch (no metavar) for a bool.
template <typename T>
CLI::Option* SharedFlag(CLI::App* command, const std::string& name, T& value) {
  const formats::CommandFlag& flag = formats::SharedFlag(command->get_name(), name);
  if constexpr (std::is_same_v<T, bool>) {
    return command->add_flag(flag.name, value, flag.help);
  } else {
    return command->add_option(flag.name, value, flag.help)->type_name(flag.metavar);
  }
}

}  // namespace calibproj::app
