// What the sensor status poller (daemon/ptc/sensor_status_poller.hpp) hands the writer: the
// sensor's answers, timed, through a preallocated SPSC queue, and the PTC request counts.
// Lock-free on both sides; the writer reads it once a second.
#pragma once

#include <atomic>
#include <cstdint>
#include <optional>

#include "core/ptc/ptc_messages.hpp"
#include "ringbuf/spsc_queue.hpp"

namespace pandarcap {

struct SensorStatusSample {
  std::int64_t monotonic_ns = 0;  // when the answer arrived
  ptc::SensorStatus status;
  std::optional<std::uint8_t> clock_source;   // from the last configuration read, if any
  std::optional<std::int64_t> ptp_offset_ns;  // from 0x06, where the sensor answers it
};

// Between the poller (producer) and the writer (consumer). Preallocated; a full queue drops the
// sample (the writer only wants the latest, and reads every second).
struct SensorStatusChannel {
  ringbuf::SpscQueue<SensorStatusSample> samples{8};
  std::atomic<std::uint64_t> requests{0};  // PTC requests since start-up (start-up's included)
  std::atomic<std::uint64_t> errors{0};
  // Statuses with a field outside its physical range (core/ptc/status_plausibility.hpp).
  std::atomic<std::uint64_t> implausible{0};
};

}  // namespace pandarcap
