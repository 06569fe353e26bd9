// Bindings of calibproj::video: probing and the per-frame luma of a video.

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>

#include <string>
#include <vector>

#include "calibproj/video/luma_signal.h"
#include "calibproj/video/video_reader.h"
#include "registry.h"

namespace py = pybind11;

namespace calibproj::bindings {

void register_video(py::module_& m) {
  m.def(
      "probe",
      [](const std::string& path) {
        video::VideoInfo info;
        {
          py::gil_scoped_release release;
          info = video::ProbeVideo(path);
        }
        py::dict d;
        d["path"] = info.path;
        d["width"] = info.width;
        d["height"] = info.height;
        d["fps"] = info.fps;
        d["frame_count"] = info.frame_count;
        return d;
      },
      py::arg("path"),
      "Frame size, frame rate and declared frame count of a video (FFmpeg's libraries); "
      "RuntimeError naming the file when it cannot be opened.");
  m.def(
      "luma_signal",
      [](const std::string& path, double gamma, int row_step) {
        std::vector<double> signal;
        {
          py::gil_scoped_release release;
          signal = video::ReadLumaSignal(path, gamma, row_step);
        }
        py::array_t<double> out(static_cast<py::ssize_t>(signal.size()));
        std::copy(signal.begin(), signal.end(), out.mutable_data());
        return out;
      },
      py::arg("path"), py::arg("gamma") = 2.2, py::arg("row_step") = 2,
      "Mean luma of every frame (the decoder's luma plane in full range: cv2.cvtColor of the colour "
      "frame, up to rounding), each pixel linearised as (value / 255)^gamma, over every row_step-th "
      "row; one decoding pass.");
}

}  // namespace calibproj::bindings
