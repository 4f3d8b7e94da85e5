#!/usr/bin/env bash
# The primary host's STATE (Sparkplug 3.0): gridscada's edge node births only
# while a Python primary host says online, buffers while it is offline, and
# sends the buffer as history when it is back; gridscada's central host
# stamps every MQTT session's STATE anew. The checks are in
# tests/e2e/sparkplug_primary.py; same needs and setup as
# sparkplug_central.sh, which runs it.
exec bash "$(dirname "$0")/sparkplug_central.sh" sparkplug_primary.py
