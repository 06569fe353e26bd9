// calibproj-native: calibration of a camera network on a machine without Python.
// The same C++ steps as the calibproj Python package, the same files in and out.

#include <CLI/CLI.hpp>
#include <exception>
#include <iostream>

#include "calibrate_command.h"
#include "detect_command.h"
#include "files.h"

int main(int argc, char** argv) {
  CLI::App app{"calibproj-native: external calibration of camera networks from projected multi-scale markers"};
  app.require_subcommand(1);
  CLI::App* calibrate = nullptr;
  const auto calibrate_args = calibproj::app::AddCalibrateCommand(app, &calibrate);
  CLI::App* detect = nullptr;
  const auto detect_args = calibproj::app::AddDetectCommand(app, &detect);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& error) {
    return app.exit(error);
  }
  const std::string command = calibrate->parsed() ? "calibrate" : detect->parsed() ? "detect" : "";
  try {
    if (calibrate->parsed()) return calibproj::app::RunCalibrate(*calibrate_args);
    if (detect->parsed()) return calibproj::app::RunDetect(*detect_args);
  } catch (const std::exception& error) {
    std::cerr << "calibproj-native " << command << ": error: " << error.what() << "\n";
    return 2;
  }
  return 2;
}
