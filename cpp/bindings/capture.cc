// Bindings of calibproj::capture: the projector (libmpv) and the site file.

#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <atomic>
#include <memory>
#include <string>

#include "calibproj/capture/projector.h"
#include "calibproj/capture/site_file.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

// A flag set from any thread that ends a playback (or a live read) at once.
struct StopFlag {
  std::shared_ptr<std::atomic<bool>> flag = std::make_shared<std::atomic<bool>>(false);
};

}  // namespace

void register_capture(py::module_& m) {
  py::class_<StopFlag>(m, "Stop", "A flag set from any thread that ends a playback at once.")
      .def(py::init<>())
      .def("set", [](StopFlag& stop) { stop.flag->store(true); })
      .def_property_readonly("is_set", [](const StopFlag& stop) { return stop.flag->load(); });
  py::class_<capture::ProjectorOptions>(m, "ProjectorOptions", "Where and how the projection is played.")
      .def(py::init([](const std::string& display, int screen, const std::string& video_output, double timeout_s) {
             capture::ProjectorOptions options;
             options.display = display;
             options.screen = screen;
             options.video_output = video_output;
             options.timeout_s = timeout_s;
             options.Check();
             return options;
           }),
           py::arg("display") = "", py::arg("screen") = -1, py::arg("video_output") = "gpu,x11", py::arg("timeout_s") = 20.0,
           "ValueError naming the first bad field.")
      .def_readonly("display", &capture::ProjectorOptions::display, "X display; empty: the process's DISPLAY")
      .def_readonly("screen", &capture::ProjectorOptions::screen, "screen to fill; -1: the default")
      .def_readonly("video_output", &capture::ProjectorOptions::video_output, "mpv's video outputs, tried in turn")
      .def_readonly("timeout_s", &capture::ProjectorOptions::timeout_s);
  py::class_<capture::PresentationLog>(m, "PresentationLog", "When each frame of the projection was shown.")
      .def(py::init<>(), "An empty log (nothing shown).")
      .def_readonly("video_time_s", &capture::PresentationLog::video_time_s, "the frame's time in the video")
      .def_readonly("shown_s", &capture::PresentationLog::shown_s, "seconds since the first frame was shown")
      .def_readonly("dropped_frames", &capture::PresentationLog::dropped_frames)
      .def_readonly("duration_s", &capture::PresentationLog::duration_s);
  py::class_<capture::SiteCamera>(m, "SiteCamera", "One camera of a site file.")
      .def_readonly("name", &capture::SiteCamera::name)
      .def_readonly("source", &capture::SiteCamera::source, "as FFmpeg opens it: URL, device or file")
      .def_readonly("options", &capture::SiteCamera::options, "video.SourceOptions (live; no recording set)")
      .def_readonly("intrinsics", &capture::SiteCamera::intrinsics)
      .def_readonly("exposure_s", &capture::SiteCamera::exposure_s, "known exposure; 0: estimated");
  py::class_<capture::Site>(m, "Site", "A room named once: its cameras, projector and projection.")
      .def_readonly("path", &capture::Site::path)
      .def_readonly("sequence", &capture::Site::sequence)
      .def_readonly("projection", &capture::Site::projection)
      .def_readonly("projector", &capture::Site::projector)
      .def_readonly("cameras", &capture::Site::cameras, "in name order")
      .def_readonly("ready_s", &capture::Site::ready_s, "every camera delivers frames within this")
      .def_readonly("end_s", &capture::Site::end_s, "a camera still ingesting this long after the end is stopped");
  m.def(
      "read_site",
      [](const std::filesystem::path& path) { return capture::ReadSite(path); }, py::arg("path"),
      "Reads a site file (calibproj.site/1); formats.InputError naming the file and the entry.");
  m.def(
      "play",
      [](const std::string& video, const capture::ProjectorOptions& options, const StopFlag* stop) {
        capture::PresentationLog log;
        {
          py::gil_scoped_release release;
          log = capture::Projector(options).Play(video, stop != nullptr ? stop->flag : nullptr);
        }
        return log;
      },
      py::arg("video"), py::arg("options"), py::arg("stop") = nullptr,
      "Plays the video full screen where the options say (libmpv) and returns when it ended: "
      "the presentation log. RuntimeError naming the display when it cannot be played there.");
}

}  // namespace calibproj::bindings
