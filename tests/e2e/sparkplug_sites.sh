#!/usr/bin/env bash
# Many sites: three gridscada edge nodes (three simulated plants, each the
# demo plant on its own Modbus ports) and one gridscada central host on one
# Debian mosquitto; the checks are in tests/e2e/sparkplug_sites.py (every
# site's tags at the centre, Bad on kill -9 of an edge, back through its
# rebirth, a write from the centre confirmed by the right site's device).
# Same needs and setup as sparkplug_central.sh, which runs it.
exec bash "$(dirname "$0")/sparkplug_central.sh" sparkplug_sites.py
