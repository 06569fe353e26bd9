#!/usr/bin/env bash
# Installs the Debian packages that calibproj builds and runs with.
# Safe to run any number of times: it only calls apt-get when something is missing.
set -euo pipefail

packages=(
  build-essential cmake ninja-build pkg-config
  python3-dev python3-venv
  libceres-dev libeigen3-dev
  libopencv-dev libopencv-contrib-dev
  libapriltag-dev
  libavformat-dev libavcodec-dev libavutil-dev libswscale-dev libavdevice-dev
  libmpv-dev  # the projector of `calibproj capture`
  xvfb  # the virtual operating room's projector display (tests, `calibproj demo --live`)
  # An RTSP camera on loopback for the tests (GStreamer's rtsp-server, run by python3).
  python3-gi gir1.2-gst-rtsp-server-1.0 gstreamer1.0-plugins-good
  nlohmann-json3-dev libcli11-dev
  ffmpeg
  opencv-doc  # OpenCV's sample images: tests/test_board.py checks calibproj intrinsics on them
)

missing=()
for package in "${packages[@]}"; do
  if ! dpkg-query -W -f='${Status}' "$package" 2>/dev/null | grep -q "install ok installed"; then
    missing+=("$package")
  fi
done

if [ "${#missing[@]}" -eq 0 ]; then
  echo "install_deps: all Debian packages present"
  exit 0
fi

sudo_cmd=()
if [ "$(id -u)" -ne 0 ]; then
  sudo_cmd=(sudo)
fi
echo "install_deps: installing ${missing[*]}"
"${sudo_cmd[@]}" apt-get update
DEBIAN_FRONTEND=noninteractive "${sudo_cmd[@]}" apt-get install -y --no-install-recommends "${missing[@]}"
