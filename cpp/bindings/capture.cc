// Bindings of calibproj::capture: the projector (libmpv) and the site file.

#include <pybind11/pybind11.h>
#include <pybind11/stl.h>
#include <pybind11/stl/filesystem.h>

#include <atomic>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include "calibproj/capture/projector.h"
#include "calibproj/capture/session.h"
#include "calibproj/capture/site_file.h"
#include "ingest_options.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

namespace {

// A flag set from any thread that ends a playback (or a live read) at once.
struct StopFlag {
  std::shared_ptr<std::atomic<bool>> flag = std::make_shared<std::atomic<bool>>(false);
};

// A capture's outcome with the plan it ran (whose sequence the ingest results need).
struct CapturedRun {
  capture::CapturePlan plan;
  capture::CaptureRun run;

  const formats::CameraOutcome& Camera(const std::string& name) const {
    for (const auto& camera : run.cameras) {
      if (camera.name == name) return camera;
    }
    throw py::value_error("no camera " + name + " in the capture");
  }
};

capture::CapturePlan MakePlan(const capture::Site& site, const std::filesystem::path& sequence_file,
                              const ingest::SequenceDescription& sequence, const std::filesystem::path& video,
                              const std::filesystem::path& intrinsics_folder,
                              const std::filesystem::path& recordings, const detect::ArucoOptions& aruco,
                              const detect::AprilTagOptions& apriltag, double status_interval_s,
                              const py::kwargs& kwargs) {
  capture::CapturePlan plan{site, sequence_file, sequence, video, intrinsics_folder,
                            IngestOptionsFromKwargs(aruco, apriltag, kwargs), recordings, status_interval_s};
  plan.options.Check();
  return plan;
}

// Calls a Python function from the capture's threads; what it raises is reported as
// unraisable (a logging handler's failure must not end a camera's thread).
capture::CaptureLogger PythonLogger(const std::optional<py::function>& log) {
  if (!log) return {};
  return [function = *log](bool error, const std::string& line) {
    py::gil_scoped_acquire acquire;
    try {
      function(error, line);
    } catch (py::error_already_set& raised) {
      raised.discard_as_unraisable("calibproj capture log");
    }
  };
}

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
  py::register_exception<capture::CaptureInterrupted>(m, "CaptureInterrupted", PyExc_RuntimeError);
  m.def("site_intrinsics_provenance", &capture::SiteIntrinsicsProvenance,
        "What provenance.json records as a capture's intrinsics: the files its site file names.");
  py::class_<capture::CapturePlan>(m, "CapturePlan", "What a capture projects and how it reads the cameras.")
      .def(py::init(&MakePlan), py::arg("site"), py::arg("sequence_file"), py::arg("sequence"), py::arg("video"),
           py::arg("intrinsics_folder"), py::arg("recordings"), py::arg("aruco"), py::arg("apriltag"),
           py::arg("status_interval_s") = 2.0,
           "`intrinsics_folder`: where the cameras' intrinsics files are (empty: the site's files); `recordings`: an "
           "existing folder that receives <camera>.mkv; keyword options: the ingest's (ingest.option_table()).");
  py::class_<formats::CameraOutcome>(m, "CameraOutcome", "One camera's ingest in a capture.")
      .def(py::init<>(), "An empty outcome (no camera).")
      .def_readonly("name", &formats::CameraOutcome::name)
      .def_readonly("source", &formats::CameraOutcome::video, "the URL, device or file it was read from")
      .def_readonly("intrinsics", &formats::CameraOutcome::intrinsics, "the intrinsics file, or why there is none")
      .def_readonly("error", &formats::CameraOutcome::error, "empty when the camera was ingested")
      .def_property_readonly("ok", &formats::CameraOutcome::ok);
  py::class_<capture::Delivery>(m, "Delivery", "What one camera delivered.")
      .def(py::init<>(), "Nothing delivered.")
      .def_readonly("frames", &capture::Delivery::frames)
      .def_readonly("first_frame_s", &capture::Delivery::first_frame_s, "since the capture started; None: no frame")
      .def_readonly("recording", &capture::Delivery::recording, "file name in the recordings folder");
  py::class_<CapturedRun>(m, "CaptureRun", "What a capture recorded and ingested.")
      .def(py::init<>(), "An empty run (no camera, nothing projected).")
      .def_property_readonly("cameras", [](const CapturedRun& r) { return r.run.cameras; }, "in the site's order")
      .def_property_readonly("delivered", [](const CapturedRun& r) { return r.run.delivered; }, "the same order")
      .def_property_readonly("projection", [](const CapturedRun& r) { return r.run.projection; })
      .def_property_readonly("projection_started_s", [](const CapturedRun& r) { return r.run.projection_started_s; })
      .def_property_readonly("cameras_done_after_end_s",
                             [](const CapturedRun& r) { return r.run.cameras_done_after_end_s; })
      .def(
          "ingest_result",
          [](const CapturedRun& r, const std::string& name) {
            const formats::CameraOutcome& camera = r.Camera(name);
            if (!camera.ok()) throw py::value_error("camera " + name + " failed: " + camera.error);
            return BoundIngestResult(camera.result, r.plan.sequence);
          },
          py::arg("name"), "A camera's ingest as ingest_camera returns it (an ingested camera only).")
      .def(
          "write_log",
          [](const CapturedRun& r, const std::filesystem::path& path) { capture::WriteCaptureLog(path, r.plan, r.run); },
          py::arg("path"), "Writes capture.json (calibproj.capture/1).");
  m.def(
      "record",
      [](const capture::CapturePlan& plan, const StopFlag* abort, const std::optional<py::function>& log) {
        const capture::CaptureLogger logger = PythonLogger(log);
        CapturedRun out{plan, {}};
        {
          py::gil_scoped_release release;
          out.run = capture::Record(plan, abort != nullptr ? abort->flag : nullptr, logger);
        }
        return out;
      },
      py::arg("plan"), py::arg("abort") = nullptr, py::arg("log") = py::none(),
      "Records and ingests every camera of the plan's site while its projector plays the projection "
      "(calibproj/capture/session.h); `log(error, line)` gets the status lines, `abort` (a Stop) ends it at once "
      "with CaptureInterrupted. RuntimeError when no camera delivers frames or the projector cannot play.");
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
