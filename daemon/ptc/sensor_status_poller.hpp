// The thread that asks the sensor for its status over PTC every status_interval_seconds, off the
// packet path: the receive, decode and writer threads never wait on the sensor's TCP port.
//
//   poller thread --SensorStatusChannel (SPSC queue of samples, atomic counters)--> writer
//
// Each round asks for the status (0x09); until known and then every 12th round, the
// configuration (0x08: is the clock source PTP?); and PTP diagnostics (0x06: the offset from
// the master) until the sensor answers anything but a valid PTP status (the first round's
// "unsupported" is counted once, logged once, and not asked again). A sample is pushed only for an
// answer; the writer keeps the latest and ages it, so a sensor that stops answering turns the
// status stale after 3 intervals instead of freezing the last values. Failures are counted; the log
// gets one warning when the sensor stops answering and one line when it answers again.
#pragma once

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <mutex>
#include <optional>

#include "core/ptc/ptc_messages.hpp"
#include "daemon/ptc/ptc_client.hpp"
#include "daemon/ptc/sensor_status_channel.hpp"

namespace pandarcap {

class SensorStatusPoller {
 public:
  // `clock_source`: what the start-up's configuration read said, if it answered.
  SensorStatusPoller(PtcClientOptions options, std::chrono::milliseconds interval,
                     SensorStatusChannel& channel, std::optional<std::uint8_t> clock_source);

  // The thread's body: polls until stop().
  void run();
  void stop();

 private:
  void poll_once(std::uint64_t round);

  PtcClient client_;
  std::chrono::milliseconds interval_;
  SensorStatusChannel& channel_;
  std::optional<std::uint8_t> clock_source_;
  bool ask_ptp_diagnostics_ = true;  // until the sensor says it does not answer 0x06
  std::uint64_t base_requests_ = 0, base_errors_ = 0;  // the channel's counts before this thread
  // The last status request was answered, or none failed yet: a failure after an answer is
  // warned about once, an answer after a failure said once.
  bool answering_ = true;
  std::uint32_t implausible_ = 0;  // the last status's implausible fields, logged when they change
  std::mutex mutex_;
  std::condition_variable wake_;
  bool stop_ = false;
};

}  // namespace pandarcap
