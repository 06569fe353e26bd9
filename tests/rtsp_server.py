"""An RTSP server on loopback for the tests, as an IP camera serves its stream:
GStreamer's rtsp-server, run by Debian's python3 (its gi bindings), serving one H.264
Matroska file at rtsp://127.0.0.1:PORT/camera, played in real time from its start for
each client. Prints "ready" once it listens.

    /usr/bin/python3 tests/rtsp_server.py VIDEO.mkv PORT
"""

import sys

import gi

gi.require_version("Gst", "1.0")
gi.require_version("GstRtspServer", "1.0")
from gi.repository import GLib, Gst, GstRtspServer  # noqa: E402 - after the versions are chosen


def main() -> None:
    video, port = sys.argv[1], sys.argv[2]
    Gst.init(None)
    server = GstRtspServer.RTSPServer()
    server.set_address("127.0.0.1")
    server.set_service(port)
    factory = GstRtspServer.RTSPMediaFactory()
    # The packets as they are in the file (no re-encoding), with the stream's parameters
    # before every key frame.
    factory.set_launch(f'( filesrc location="{video}" ! matroskademux '
                       '! rtph264pay name=pay0 pt=96 config-interval=-1 )')
    server.get_mount_points().add_factory("/camera", factory)
    if server.attach(None) == 0:
        sys.exit(f"rtsp_server: cannot listen on port {port}")
    print("ready", flush=True)
    GLib.MainLoop().run()


if __name__ == "__main__":
    main()
