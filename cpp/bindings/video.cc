// Bindings of calibproj::video: probing and the per-frame luma of a video.

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <atomic>
#include <map>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "calibproj/video/luma_signal.h"
#include "calibproj/video/stream_writer.h"
#include "calibproj/video/video_reader.h"
#include "images.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

void register_video(py::module_& m) {
  py::class_<video::VideoInfo>(m, "VideoInfo", "What a video's container says of it.")
      .def_readonly("path", &video::VideoInfo::path)
      .def_readonly("width", &video::VideoInfo::width)
      .def_readonly("height", &video::VideoInfo::height)
      .def_readonly("fps", &video::VideoInfo::fps,
                    "rate of the frame grid the first timestamps lie on (else the declared one)")
      .def_readonly("declared_fps", &video::VideoInfo::declared_fps, "the container's average frame rate")
      .def_readonly("timed", &video::VideoInfo::timed, "the container gives frame timestamps")
      .def_readonly("frame_count", &video::VideoInfo::frame_count, "as the container declares it (may be approximate)");
  py::class_<video::SourceOptions>(m, "SourceOptions",
                                   "How a live source (a stream URL or a device) is opened, read and recorded.")
      .def(py::init([](bool live, const std::string& format, const std::map<std::string, std::string>& ffmpeg_options,
                       double open_timeout_s, double stall_timeout_s, const std::string& record_path) {
             video::SourceOptions options;
             options.live = live;
             options.format = format;
             options.ffmpeg_options = ffmpeg_options;
             options.open_timeout_s = open_timeout_s;
             options.stall_timeout_s = stall_timeout_s;
             options.record_path = record_path;
             options.Check();
             return options;
           }),
           py::arg("live") = true, py::arg("format") = "", py::arg("ffmpeg_options") = std::map<std::string, std::string>{},
           py::arg("open_timeout_s") = 10.0, py::arg("stall_timeout_s") = 5.0, py::arg("record_path") = "",
           "ValueError naming the first bad field.")
      .def_readonly("live", &video::SourceOptions::live)
      .def_readonly("format", &video::SourceOptions::format, "FFmpeg's input format; empty: from the URL")
      .def_readonly("ffmpeg_options", &video::SourceOptions::ffmpeg_options, "options of FFmpeg's protocol or device")
      .def_readonly("open_timeout_s", &video::SourceOptions::open_timeout_s, "first frames within this")
      .def_readonly("stall_timeout_s", &video::SourceOptions::stall_timeout_s, "nothing for this long: ended")
      .def_readonly("record_path", &video::SourceOptions::record_path, "Matroska recording; empty: none")
      .def("request_stop", [](const video::SourceOptions& options) { options.stop->store(true); },
           "Ends reading at once (from any thread), blocking network reads included.")
      .def_property_readonly("stop_requested", [](const video::SourceOptions& options) { return options.stop->load(); });
  py::class_<video::VideoReader>(m, "VideoReader",
                                 "Frames of a video or a live source, in order, as grey images with their times.")
      .def(py::init([](const std::string& path, const std::optional<video::SourceOptions>& source) {
             py::gil_scoped_release release;
             return std::make_unique<video::VideoReader>(path, source.value_or(video::SourceOptions{}));
           }),
           py::arg("path"), py::arg("source") = py::none(),
           "Opens the video (or, with `source`, the live source); RuntimeError naming it when it cannot.")
      .def_property_readonly("info", &video::VideoReader::info)
      .def_property_readonly("end_reason", &video::VideoReader::end_reason,
                             "why grab() gave None: '' at the end, 'stopped' or 'stalled: ...'")
      .def(
          "grab",
          [](video::VideoReader& reader) -> py::object {
            cv::Mat gray;
            bool grabbed = false;
            {
              py::gil_scoped_release release;
              grabbed = reader.Grab();
              if (grabbed) gray = reader.Gray();
            }
            if (!grabbed) return py::none();
            return py::make_tuple(reader.timestamp(), GrayArray(gray));
          },
          "The next frame as (container time in seconds or NaN, grey uint8 image), None at the end.");
  py::class_<video::StreamWriter>(m, "StreamWriter",
                                  "Grey frames encoded with libx264 and sent live (MPEG-TS over UDP by default), "
                                  "each at the time given.")
      .def(py::init([](const std::string& url, int width, int height, const std::string& format,
                       int key_frame_interval, int crf, const std::string& preset, double fps) {
             video::StreamOptions options;
             options.format = format;
             options.key_frame_interval = key_frame_interval;
             options.crf = crf;
             options.preset = preset;
             options.fps = fps;
             return std::make_unique<video::StreamWriter>(url, width, height, options);
           }),
           py::arg("url"), py::arg("width"), py::arg("height"), py::arg("format") = "mpegts",
           py::arg("key_frame_interval") = 15, py::arg("crf") = 23, py::arg("preset") = "ultrafast",
           py::arg("fps") = 30.0)
      .def(
          "write",
          [](video::StreamWriter& writer, const py::array& gray, double time_s) {
            const cv::Mat view = GrayView(gray);
            py::gil_scoped_release release;
            writer.Write(view, time_s);
          },
          py::arg("gray"), py::arg("time_s"),
          "Encodes and sends a frame shown at time_s (seconds, increasing); ValueError for a frame of "
          "another size, RuntimeError naming the URL when sending fails.")
      .def("close", &video::StreamWriter::Close, py::call_guard<py::gil_scoped_release>(), "Ends the stream.");
  m.def(
      "probe",
      [](const std::string& path) {
        video::VideoInfo info;
        {
          py::gil_scoped_release release;
          info = video::ProbeVideo(path);
        }
        return info;
      },
      py::arg("path"),
      "Frame size, frame rate (of the frame grid the first timestamps lie on; declared_fps: the "
      "container's average), whether frames carry timestamps, and the declared frame count of a video "
      "(FFmpeg's libraries); RuntimeError naming the file when it cannot be opened.");
  m.def(
      "frame_timestamps",
      [](const std::string& path) {
        std::vector<double> times;
        {
          py::gil_scoped_release release;
          times = video::ReadFrameTimestamps(path);
        }
        py::array_t<double> out(static_cast<py::ssize_t>(times.size()));
        std::copy(times.begin(), times.end(), out.mutable_data());
        return out;
      },
      py::arg("path"),
      "Container timestamp in seconds (NaN where none) of every decoded frame, in decoding order.");
  m.def(
      "frame_period",
      [](const std::vector<double>& times) { return video::EstimateFramePeriod(times); },
      py::arg("times"),
      "Period (seconds) of the frame grid that timestamps lie on, allowing for missing frames and "
      "jitter under half a period; 0 with fewer than three distinct timestamps.");
  m.def(
      "luma_signal",
      [](const std::string& path, double gamma, int row_step, bool use_timestamps, double max_frame_gap_s) {
        if (!(gamma > 0.0)) throw std::invalid_argument("gamma must be positive");
        if (row_step < 1) throw std::invalid_argument("row_step must be at least 1");
        std::vector<double> signal;
        {
          py::gil_scoped_release release;
          signal = video::ReadLumaSignal(path, gamma, row_step, use_timestamps, max_frame_gap_s);
        }
        py::array_t<double> out(static_cast<py::ssize_t>(signal.size()));
        std::copy(signal.begin(), signal.end(), out.mutable_data());
        return out;
      },
      py::arg("path"), py::arg("gamma") = 2.2, py::arg("row_step") = 2, py::arg("use_timestamps") = true,
      py::arg("max_frame_gap_s") = 2.0,
      "Mean luma per slot of the frame grid (NaN where the camera dropped a frame; use_timestamps "
      "false: one slot per decoded frame): the decoder's luma plane in full range (cv2.cvtColor of the "
      "colour frame, up to rounding), each pixel linearised as (value / 255)^gamma, over every "
      "row_step-th row; one decoding pass.");
}

}  // namespace calibproj::bindings
