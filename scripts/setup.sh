#!/usr/bin/env bash
# Installs what fme needs to build, test and run, idempotently. Safe to run again and again.
# - libclang-dev: bindgen for the v4l crate's V4L2 bindings.
# - mosquitto: the MQTT broker the MQTT tests and `make bench-mqtt` start on a loopback port of their
#   own (Debian installs it to /usr/sbin; the system service is not started here).
# - ONNX Runtime 1.31.1 shared library, taken from the PyPI onnxruntime wheel (no binary downloads
#   outside the package registries) and placed in .ort/lib, where the fme binary looks for it.
set -euo pipefail
cd "$(dirname "$0")/.."

ORT_VERSION=1.31.1
ORT_DIR=.ort/lib
SUDO=""
[ "$(id -u)" -eq 0 ] || SUDO="sudo"

need_apt=()
dpkg -s libclang-dev >/dev/null 2>&1 || need_apt+=(libclang-dev)
dpkg -s pkg-config >/dev/null 2>&1 || need_apt+=(pkg-config)
command -v unzip >/dev/null 2>&1 || need_apt+=(unzip)
# mosquitto_passwd (for the wrong-password test) comes with the same package.
command -v mosquitto >/dev/null 2>&1 || [ -x /usr/sbin/mosquitto ] || need_apt+=(mosquitto)
# socat: the documented way to reach the console without a serial port (tests/daemon/console_socat.rs).
command -v socat >/dev/null 2>&1 || need_apt+=(socat)
# The web page's browser test (tests/web_browser.rs) drives headless Chromium through chromedriver.
command -v chromium >/dev/null 2>&1 || need_apt+=(chromium)
command -v chromedriver >/dev/null 2>&1 || need_apt+=(chromium-driver)
# GStreamer's RTSP server with x264enc: the real IP camera the RTSP tests start on a loopback port
# (tests/rtsp.rs, tests/rtsp_server.py), x265enc (plugins-bad) for its H.265 camera; nasm: openh264's
# assembly (faster H.264 decoding).
for p in gstreamer1.0-tools gstreamer1.0-plugins-base gstreamer1.0-plugins-good gstreamer1.0-plugins-ugly \
  gstreamer1.0-plugins-bad gir1.2-gst-rtsp-server-1.0 python3-gi nasm; do
  dpkg -s "$p" >/dev/null 2>&1 || need_apt+=("$p")
done
if [ ${#need_apt[@]} -gt 0 ]; then
  echo "setup: installing ${need_apt[*]} with apt" >&2
  $SUDO apt-get update -q >/dev/null
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -q --no-install-recommends "${need_apt[@]}" >/dev/null
fi

if [ ! -f "$ORT_DIR/libonnxruntime.so.$ORT_VERSION" ]; then
  echo "setup: fetching ONNX Runtime $ORT_VERSION from the PyPI onnxruntime wheel" >&2
  tmp=$(mktemp -d)
  trap 'rm -rf "$tmp"' EXIT
  python3 -m pip download -q --no-deps --only-binary=:all: "onnxruntime==$ORT_VERSION" -d "$tmp"
  whl=$(ls "$tmp"/onnxruntime-*.whl)
  mkdir -p "$ORT_DIR"
  unzip -q -j -o "$whl" "onnxruntime/capi/libonnxruntime.so.$ORT_VERSION" -d "$ORT_DIR"
fi
ln -sf "libonnxruntime.so.$ORT_VERSION" "$ORT_DIR/libonnxruntime.so"
echo "setup: ok (ONNX Runtime in $ORT_DIR)" >&2
