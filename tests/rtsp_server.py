#!/usr/bin/env python3
"""A real IP camera for the RTSP tests (tests/rtsp.rs): GStreamer's RTSP server on a free loopback
port serving a recorded sequence's JPEG frames as H.264 (/h264) and, where x265enc exists, H.265
(/h265), looping at the sequence's frame rate; /stall answers DESCRIBE, SETUP and PLAY like /h264
but then sends no picture (a camera whose encoder hung). Prints "port N" once listening; runs
until killed.

Usage: rtsp_server.py FRAMES_DIR FPS [PORT] [--auth basic|digest --login USER:PASSWORD]
  PORT 0 or absent: a free one. --auth: every path asks for that login, as cameras do.
Needs Debian's gstreamer1.0-plugins-{base,good,ugly}, gir1.2-gst-rtsp-server-1.0 and python3-gi
(`make setup` installs them).
"""
import argparse
import sys

import gi

gi.require_version("Gst", "1.0")
gi.require_version("GstRtsp", "1.0")
gi.require_version("GstRtspServer", "1.0")
from gi.repository import GLib, Gst, GstRtsp, GstRtspServer  # noqa: E402


def launch(frames, fps, encoder, payloader):
    # Frames are numbered from 000001 like a MOTChallenge img1/ folder; the loop restarts at 1.
    return (
        f"( multifilesrc location={frames}/%06d.jpg start-index=1 loop=true "
        f'caps="image/jpeg,framerate={fps}/1" ! jpegdec ! videoconvert ! video/x-raw,format=I420 ! '
        f"{encoder} ! {payloader} name=pay0 pt=96 )"
    )


def stall_after_prepare(_factory, media):
    """Drops every RTP packet of the media once it is prepared: the SDP (from the prerolled
    picture) is right, PLAY succeeds, and no picture follows."""
    state = {"stalled": False}

    def on_prepared(_media):
        state["stalled"] = True

    def probe(_pad, _info):
        return Gst.PadProbeReturn.DROP if state["stalled"] else Gst.PadProbeReturn.OK

    media.connect("prepared", on_prepared)
    pay = media.get_element().get_by_name("pay0")
    pay.get_static_pad("src").add_probe(Gst.PadProbeType.BUFFER | Gst.PadProbeType.BUFFER_LIST, probe)


def require_login(server, factories, method, login):
    """Every factory asks for `login` (USER:PASSWORD) with Basic or Digest authentication."""
    user, _, password = login.partition(":")
    auth = GstRtspServer.RTSPAuth()
    token = GstRtspServer.RTSPToken()
    token.set_string("media.factory.role", "viewer")
    if method == "basic":
        auth.add_basic(GstRtspServer.RTSPAuth.make_basic(user, password), token)
        auth.set_supported_methods(GstRtsp.RTSPAuthMethod.BASIC)
    else:
        auth.add_digest(user, password, token)
        auth.set_supported_methods(GstRtsp.RTSPAuthMethod.DIGEST)
    server.set_auth(auth)
    permissions = GstRtspServer.RTSPPermissions()
    permissions.add_permission_for_role("viewer", "media.factory.access", True)
    permissions.add_permission_for_role("viewer", "media.factory.construct", True)
    for factory in factories:
        factory.set_permissions(permissions)


def main():
    parser = argparse.ArgumentParser(description="GStreamer RTSP server for the fme tests")
    parser.add_argument("frames")
    parser.add_argument("fps", type=int)
    parser.add_argument("port", nargs="?", default="0")
    parser.add_argument("--auth", choices=["basic", "digest"])
    parser.add_argument("--login", default="viewer:viewer")
    args = parser.parse_args()
    Gst.init(None)
    server = GstRtspServer.RTSPServer()
    server.set_address("127.0.0.1")
    server.set_service(args.port)
    mounts = server.get_mount_points()
    h264 = "x264enc tune=zerolatency speed-preset=ultrafast key-int-max=30 ! video/x-h264,profile=main"
    h264_pay = "rtph264pay config-interval=1"
    streams = {"/h264": (h264, h264_pay), "/stall": (h264, h264_pay)}
    if Gst.ElementFactory.find("x265enc"):
        streams["/h265"] = ("x265enc tune=zerolatency speed-preset=ultrafast", "rtph265pay config-interval=1")
    factories = []
    for path, (enc, pay) in streams.items():
        factory = GstRtspServer.RTSPMediaFactory()
        factory.set_launch(launch(args.frames, args.fps, enc, pay))
        # Not shared: each client gets its own pipeline, from frame 1.
        factory.set_shared(False)
        if path == "/stall":
            factory.connect("media-configure", stall_after_prepare)
        mounts.add_factory(path, factory)
        factories.append(factory)
    if args.auth:
        require_login(server, factories, args.auth, args.login)
    if server.attach(None) == 0:
        sys.exit("rtsp_server.py: cannot listen on 127.0.0.1:" + args.port)
    print(f"port {server.get_bound_port()}", flush=True)
    GLib.MainLoop().run()


if __name__ == "__main__":
    main()
