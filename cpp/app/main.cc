// calibproj-native: calibration of a camera network on a machine without Python.
// The same C++ steps as the calibproj Python package, the same files in and out.
//
// Exit status (README, "Exit status"): 0 done; 1 the run failed for another reason than
// its input (cameras not calibrated, another run writing the same output); 2 a bad
// invocation or input, reported in one line; 130 interrupted (interrupts.h).

#include <CLI/CLI.hpp>
#include <csignal>
#include <exception>
#include <iostream>
#include <string>
#include <vector>

#include "calibrate_command.h"
#include "capture_command.h"
#include "check_command.h"
#include "detect_command.h"
#include "calibproj/formats/files.h"
#include "interrupts.h"
#include "calibproj/formats/output_folder.h"

namespace {

constexpr int kExitFailure = 1;
constexpr int kExitUsage = 2;

}  // namespace

int main(int argc, char** argv) {
  // A file size limit (ulimit -f) then fails the write with EFBIG, reported and cleaned
  // up as a full disk is, instead of killing the process with its lock and staging
  // folder left behind (Python ignores the signal the same way).
  std::signal(SIGXFSZ, SIG_IGN);
  CLI::App app{"calibproj-native: external calibration of camera networks from projected multi-scale markers"};
  app.require_subcommand(1);
  CLI::App* calibrate = nullptr;
  const auto calibrate_args = calibproj::app::AddCalibrateCommand(app, &calibrate);
  CLI::App* detect = nullptr;
  const auto detect_args = calibproj::app::AddDetectCommand(app, &detect);
  CLI::App* check = nullptr;
  const auto check_args = calibproj::app::AddCheckCommand(app, &check);
  CLI::App* capture = nullptr;
  const auto capture_args = calibproj::app::AddCaptureCommand(app, &capture);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& error) {
    // CLI11 has an exit status per kind of error; the project has one for them all.
    return app.exit(error) == 0 ? 0 : kExitUsage;
  }
  // Recorded in the outputs that say how they were made (provenance.json).
  std::vector<std::string> command_line = {"calibproj-native"};
  for (int k = 1; k < argc; ++k) command_line.emplace_back(argv[k]);
  calibrate_args->command_line = check_args->command_line = capture_args->command_line = command_line;
  const std::string command = calibrate->parsed() ? "calibrate" : detect->parsed() ? "detect"
                              : check->parsed()   ? "check"
                              : capture->parsed() ? "capture"
                                                  : "";
  const std::string prefix = "calibproj-native " + command;
  calibproj::app::Interrupts interrupts(prefix);
  try {
    if (calibrate->parsed()) return calibproj::app::RunCalibrate(*calibrate_args, interrupts);
    if (detect->parsed()) return calibproj::app::RunDetect(*detect_args, interrupts);
    if (check->parsed()) return calibproj::app::RunCheck(*check_args, interrupts);
    if (capture->parsed()) return calibproj::app::RunCapture(*capture_args, interrupts);
  } catch (const calibproj::formats::OutputBusyError& error) {
    std::cerr << prefix << ": error: " << error.what() << "\n";
    return kExitFailure;
  } catch (const std::exception& error) {
    std::cerr << prefix << ": error: " << error.what() << "\n";
    return kExitUsage;
  }
  return kExitUsage;
}
