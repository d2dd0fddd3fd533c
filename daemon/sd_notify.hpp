// systemd integration through libsystemd's sd_notify: READY=1, STATUS=..., WATCHDOG=1 and
// STOPPING=1. Outside systemd (no NOTIFY_SOCKET) every call is a cheap no-op.
#pragma once

#include <systemd/sd-daemon.h>

#include <chrono>
#include <optional>
#include <string>

namespace pandarcap::systemd {

inline void notify(const std::string& state) {
  sd_notify(0, state.c_str());
}
inline void ready() {
  notify("READY=1");
}
inline void stopping() {
  notify("STOPPING=1");
}
inline void status(const std::string& line) {
  notify("STATUS=" + line);
}
inline void watchdog() {
  notify("WATCHDOG=1");
}

// The watchdog interval systemd asked for (WatchdogSec=), if any.
inline std::optional<std::chrono::microseconds> watchdog_interval() {
  std::uint64_t usec = 0;
  if (sd_watchdog_enabled(0, &usec) > 0 && usec > 0) return std::chrono::microseconds(usec);
  return std::nullopt;
}

}  // namespace pandarcap::systemd
