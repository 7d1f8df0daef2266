#!/usr/bin/env python3
"""A real IP camera for the RTSP tests (tests/rtsp.rs): GStreamer's RTSP server on a free loopback
port serving a recorded sequence's JPEG frames as H.264 (/h264) and, where x265enc exists, H.265
(/h265), looping at the sequence's frame rate. Prints "port N" once listening; runs until killed.

Usage: rtsp_server.py FRAMES_DIR FPS [PORT]   (PORT 0 or absent: a free one)
Needs Debian's gstreamer1.0-plugins-{base,good,ugly}, gir1.2-gst-rtsp-server-1.0 and python3-gi
(`make setup` installs them).
"""
import sys

import gi

gi.require_version("Gst", "1.0")
gi.require_version("GstRtspServer", "1.0")
from gi.repository import GLib, Gst, GstRtspServer  # noqa: E402


def launch(frames, fps, encoder, payloader):
    # Frames are numbered from 000001 like a MOTChallenge img1/ folder; the loop restarts at 1.
    return (
        f"( multifilesrc location={frames}/%06d.jpg start-index=1 loop=true "
        f'caps="image/jpeg,framerate={fps}/1" ! jpegdec ! videoconvert ! video/x-raw,format=I420 ! '
        f"{encoder} ! {payloader} name=pay0 pt=96 )"
    )


def main():
    frames, fps = sys.argv[1], int(sys.argv[2])
    port = sys.argv[3] if len(sys.argv) > 3 else "0"
    Gst.init(None)
    server = GstRtspServer.RTSPServer()
    server.set_address("127.0.0.1")
    server.set_service(port)
    mounts = server.get_mount_points()
    h264 = "x264enc tune=zerolatency speed-preset=ultrafast key-int-max=30 ! video/x-h264,profile=main"
    streams = {"/h264": (h264, "rtph264pay config-interval=1")}
    if Gst.ElementFactory.find("x265enc"):
        streams["/h265"] = ("x265enc tune=zerolatency speed-preset=ultrafast", "rtph265pay config-interval=1")
    for path, (enc, pay) in streams.items():
        factory = GstRtspServer.RTSPMediaFactory()
        factory.set_launch(launch(frames, fps, enc, pay))
        # Not shared: each client gets its own pipeline, from frame 1.
        factory.set_shared(False)
        mounts.add_factory(path, factory)
    if server.attach(None) == 0:
        sys.exit("rtsp_server.py: cannot listen on 127.0.0.1:" + port)
    print(f"port {server.get_bound_port()}", flush=True)
    GLib.MainLoop().run()


if __name__ == "__main__":
    main()
