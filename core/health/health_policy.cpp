#include "core/health/health_policy.hpp"

#include <fmt/format.h>

#include <cmath>
#include <iterator>
#include <utility>

#include "core/ipv4.hpp"
#include "core/ptc/ptc_messages.hpp"
#include "core/ptc/status_plausibility.hpp"
#include "core/sensors/sensor_model.hpp"
#include "core/sensors/sensor_models.hpp"

namespace pandarcap {

namespace {
constexpr auto kPtpLocked = static_cast<std::uint8_t>(ptc::PtpState::kLocked);

// A motor that stands (or turns too slowly), said whatever the tail claims: its speed from the
// azimuth against the time, packets whose azimuth stood, frames that stopped closing; and a
// packet rate that is not the sensor's.
template <typename Problem>
void motor_problems(const HealthCounters& c, const HealthCounters& p,
                    const HealthExpectations& expected, const HealthGauges& g,
                    std::string& problems, Problem& problem) {
  const bool arriving = c.packets_accepted > p.packets_accepted;
  const std::uint64_t standing = c.standing_packets - p.standing_packets;
  const std::uint64_t frameless = c.frameless_packets - p.frameless_packets;
  const bool tail_zero = arriving && g.seconds_since_last_packet >= 0 && g.rpm_tail == 0;
  // A motor stops for longer than 2 ms: fewer standing packets are copies or glitches.
  const bool stood = standing >= kStandingPacketsForStop;
  // An azimuth that barely turns (its jitter keeps it from standing still) is a stopped motor.
  const bool crawling = arriving && g.rpm_measured > 0 && g.rpm_measured < 0.1 * expected.rpm;
  if (tail_zero || stood || crawling || frameless > 0) {
    problem("motor stopped:");
    const auto out = std::back_inserter(problems);
    if (tail_zero) problems += " the packets' tail says 0 RPM,";
    if (stood) fmt::format_to(out, " azimuth standing in {} packets,", standing);
    if (crawling) fmt::format_to(out, " azimuth turning at {:.1f} RPM,", g.rpm_measured);
    if (frameless > 0) fmt::format_to(out, " no frame closed in {} packets,", frameless);
    problems.pop_back();  // the last comma
  } else if (standing > 0) {
    problem("{} packets with the azimuth standing", standing);
  }
  // The tail's speed is checked by the caller; when it is fine (or 0), the azimuth's.
  const bool tail_off = g.seconds_since_last_packet >= 0 && g.rpm_tail > 0 &&
                        std::abs(g.rpm_tail - expected.rpm) > 0.1 * expected.rpm;
  if (!tail_off && arriving && !crawling && g.rpm_measured > 0 &&
      std::abs(g.rpm_measured - expected.rpm) > 0.1 * expected.rpm) {
    // The tail may say what the motor was set to; the azimuth says how it turns.
    problem("motor measured at {:.0f} RPM (expected {})", g.rpm_measured, expected.rpm);
  }
  const auto mode = return_mode_from_string(g.return_mode);
  if (arriving && mode && g.packet_rate_hz > 0) {
    const double rpm = g.rpm_measured > 0 ? g.rpm_measured
                       : g.rpm_tail > 0   ? g.rpm_tail
                                          : static_cast<double>(expected.rpm);
    const double rate =
        with_model(expected.model,
                   [&]<class M>(std::type_identity<M>) {
                     return M::packets_per_revolution(returns_per_firing(*mode), rpm);
                   }) *
        rpm / 60.0;
    if (std::abs(g.packet_rate_hz - rate) > 0.1 * rate) {
      problem("packet rate {:.0f}/s (expected {:.0f} in {} return)", g.packet_rate_hz, rate,
              g.return_mode);
    }
  }
}

}  // namespace

void classify_health(const HealthCounters& c, const HealthCounters& p,
                     const HealthExpectations& expected, Silence silence,
                     std::string_view last_write_error, HealthGauges& g) {
  // The problems are written straight into the reason (cleared, its capacity kept). A failing
  // socket or a silence is decided first: each says only what is true of it (below).
  std::string& problems = g.reason;
  problems.clear();
  const auto problem = [&]<typename... Args>(fmt::format_string<Args...> format, Args&&... args) {
    if (!problems.empty()) problems += "; ";
    fmt::format_to(std::back_inserter(problems), format, std::forward<Args>(args)...);
  };
  const auto grew = [&](std::uint64_t now_value, std::uint64_t before, const char* what) {
    if (now_value > before) problem("{} {}", now_value - before, what);
  };
  // What was lost in the second, in this order: written first whatever the state (below).
  const auto losses = [&] {
    if (c.write_errors > p.write_errors) {
      problem("{} write errors ({} bytes not written): {}", c.write_errors - p.write_errors,
              c.bytes_not_written - p.bytes_not_written, last_write_error);
    }
    // What those writes held (or what was not written to keep the health's room), by output.
    grew(c.pcap_packets_not_written, p.pcap_packets_not_written,
         "packets not written to the pcap (failed writes or the health's room)");
    grew(c.mcap_messages_not_written, p.mcap_messages_not_written,
         "MCAP messages not written (failed writes or the health's room)");
    grew(c.kernel_drops, p.kernel_drops, "kernel drops");
    grew(c.ring_overruns, p.ring_overruns, "ring overruns");
    grew(c.frames_dropped_no_arena, p.frames_dropped_no_arena, "frames dropped (no free arena)");
    grew(c.pcap_packets_not_recorded, p.pcap_packets_not_recorded, "packets not recorded");
    grew(c.pcap_packets_lost, p.pcap_packets_lost, "recorded packets lost (recording removed)");
    grew(c.mcap_messages_not_recorded, p.mcap_messages_not_recorded,
         "MCAP messages not recorded (behind: compression, its disk or the writer)");
    grew(c.mcap_messages_lost, p.mcap_messages_lost, "MCAP messages lost (file removed)");
    if (c.files_removed_before_upload > p.files_removed_before_upload) {
      const UploadGauges& upload = g.storage.upload;
      const std::uint64_t files = c.files_removed_before_upload - p.files_removed_before_upload;
      problem(
          "{} file{} removed before {} uploaded ({:.1f} MB; the last by {}: {})", files,
          files == 1 ? "" : "s", files == 1 ? "it was" : "they were",
          static_cast<double>(c.bytes_removed_before_upload - p.bytes_removed_before_upload) / 1e6,
          upload.last_removed_by_floor ? "the free-space floor" : "retention",
          std::string_view(upload.last_removed));
    }
  };
  // The host's side, said whatever the state too: where the health goes, the disk's time left,
  // and what stands (a replay's damage, the live view's).
  const auto host = [&] {
    if (g.health_fallback.active && !g.health_fallback.directory.empty()) {
      problem("health written to {} ({})", g.health_fallback.directory, g.health_fallback.error);
    } else if (g.health_fallback.active) {
      problem("health files cannot be written anywhere ({})", g.health_fallback.error);
    }
    const StorageGauges& storage = g.storage;
    if (expected.min_hours_left > 0 && storage.free_known &&
        storage.hours_left < expected.min_hours_left) {
      problem(
          "{:.1f} hours of disk left ({} MiB free at {:.1f} MB/s written; health.min_hours_left "
          "{})",
          storage.hours_left, storage.free_bytes >> 20,
          storage.written_bytes_per_second_total / 1e6, expected.min_hours_left);
    }
    if (!g.standing.empty()) problem("{}", g.standing);
  };
  // A failing socket is an error: the daemon is not capturing. The second's losses and the
  // host's side follow, as they follow a silence.
  if (c.receive_errors > p.receive_errors) {
    g.state = HealthState::kError;
    fmt::format_to(std::back_inserter(g.reason), "{} receive errors: the socket is failing",
                   c.receive_errors - p.receive_errors);
    losses();
    host();
    return;
  }
  if (silence.silent && silence.receiver_behind_seconds > 0) {
    // The receiver has not seen what the kernel holds: a silence here may be its own, and the
    // sensor is not blamed for it. What follows a silence follows this too.
    g.state = HealthState::kDegraded;
    fmt::format_to(std::back_inserter(g.reason),
                   "the receiver is {:.1f} s behind: ", silence.receiver_behind_seconds);
    if (g.seconds_since_last_packet < 0) {
      g.reason += "no packet seen yet";
    } else {
      fmt::format_to(std::back_inserter(g.reason), "no packet seen for {:.1f} s",
                     g.seconds_since_last_packet);
    }
    g.reason += ", whether the sensor sent is not known";
    losses();
    host();
    return;
  }
  if (silence.silent) {
    // Silence leads, and the second's losses and the host's side follow it: a silence that a
    // stop or a stalled writer ended, said alone, hid the losses counted in it (the writer's,
    // catching up) from every reader of the reason. What is about the packets or the sensor
    // (rejects, the motor, the clock, its status) is not said: no packet came.
    g.state = HealthState::kNoData;
    if (g.seconds_since_last_packet < 0) {
      g.reason += "no packet received yet";
    } else {
      fmt::format_to(std::back_inserter(g.reason), "no packet for {:.1f} s",
                     g.seconds_since_last_packet);
    }
    losses();
    host();
    return;
  }
  losses();
  const bool source_changed = c.sensor_source_changes > p.sensor_source_changes;
  if (c.other_sensor_packets > p.other_sensor_packets && source_changed) {
    // The sensor changed within the second: the packets dropped before the change came from
    // the one that is the sensor now, those after it from the one that was; the two addresses
    // as they stand now would name them the wrong way round, so both are named, no roles.
    problem("{} packets from a second sensor (", c.other_sensor_packets - p.other_sensor_packets);
    append_ipv4_source(problems, g.sensor_source);
    problems += " or ";
    append_ipv4_source(problems, g.other_sensor_source);
    problems += ": the sensor changed in this second): one sensor per daemon";
  } else if (c.other_sensor_packets > p.other_sensor_packets) {
    // Two sensors sending to one port: the second is dropped, and named with the first.
    problem("{} packets from a second sensor at ", c.other_sensor_packets - p.other_sensor_packets);
    append_ipv4_source(problems, g.other_sensor_source);
    problems += " (the sensor is ";
    append_ipv4_source(problems, g.sensor_source);
    problems += "): one sensor per daemon";
  }
  if (source_changed) {
    problem("the sensor's source changed to ");
    append_ipv4_source(problems, g.sensor_source);
    problems += " (";
    append_ipv4_source(problems, g.other_sensor_source);
    problems += " silent)";
  }
  grew(c.sequence_lost, p.sequence_lost, "packets lost (sequence)");
  grew(c.sequence_resets, p.sequence_resets, "sequence resets (the sensor restarted?)");
  grew(c.sequence_reordered, p.sequence_reordered, "packets reordered");
  grew(c.azimuth_gaps, p.azimuth_gaps, "azimuth gaps");
  grew(c.points_missing, p.points_missing, "points missing (lost packets)");
  grew(c.packets_rejected, p.packets_rejected, "packets rejected");
  grew(c.duplicate_packets, p.duplicate_packets, "duplicate packets");
  grew(c.outlier_packets, p.outlier_packets, "isolated outlier packets");
  grew(c.stream_changes, p.stream_changes,
       "stream changes (a restart, a gap, a new speed, a clock step or a reversal)");
  grew(c.reversed_packets, p.reversed_packets, "packets turning backwards (left out)");
  grew(c.static_timestamp_packets, p.static_timestamp_packets, "static timestamps");
  grew(c.backward_timestamp_packets, p.backward_timestamp_packets, "timestamps going back");
  grew(c.timestamp_jump_packets, p.timestamp_jump_packets, "timestamps leaping forward");
  if (c.invalid_time_packets > p.invalid_time_packets) {
    problem("{} packets with an impossible tail time (the last: {})",
            c.invalid_time_packets - p.invalid_time_packets,
            g.last_invalid_time.empty() ? std::string_view("date or microseconds")
                                        : std::string_view(g.last_invalid_time));
  }
  if (g.high_temperature) problem("sensor high-temperature flag set");
  if (c.packets_accepted > 0) {
    const int channels = channel_count(expected.model);
    const std::string_view model = display_name(expected.model);
    if (expected.inventory_lasers > 0 && expected.inventory_lasers != channels) {
      problem("the sensor reports {} lasers over PTC, its packets are a {}'s ({} channels)",
              expected.inventory_lasers, model, channels);
    }
    if (expected.calibration_channels > 0 && expected.calibration_channels != channels) {
      problem(
          "the calibration has {} channels, the packets are a {}'s ({}): its nominal table "
          "is used",
          expected.calibration_channels, model, channels);
    }
  }
  if (expected.return_mode != "any" && !g.return_mode.empty() &&
      g.return_mode != expected.return_mode) {
    problem("return mode {} (expected {})", g.return_mode, expected.return_mode);
  }
  if (g.seconds_since_last_packet >= 0 && g.rpm_tail > 0 &&
      std::abs(g.rpm_tail - expected.rpm) > 0.1 * expected.rpm) {
    problem("motor at {:.0f} RPM (expected {})", g.rpm_tail, expected.rpm);
  }
  motor_problems(c, p, expected, g, problems, problem);
  if (expected.max_clock_offset_seconds > 0 && g.sensor_clock_offset_known &&
      std::abs(g.sensor_clock_offset_seconds) > expected.max_clock_offset_seconds) {
    const double off = std::abs(g.sensor_clock_offset_seconds);
    problem("sensor clock off by {:.{}f} s ({} the host): not synchronised?", off,
            off >= 10 ? 0 : 3, g.sensor_clock_offset_seconds < 0 ? "behind" : "ahead of");
  }
  const SensorStatusGauges& sensor = g.sensor_status;
  if (sensor.polled && sensor.available && sensor.stale) {
    problem("sensor status stale: no answer over PTC for {:.0f} s", sensor.age_seconds);
  } else if (sensor.polled && sensor.available) {
    // What the sensor says is believed only within physical ranges; the rest is a problem.
    if (sensor.implausible != 0)
      problem("sensor status implausible: {}", sensor.implausible_reason);
    const bool ptp_known = (sensor.implausible >> ptc::kPtpStateBit & 1u) == 0;
    if (ptp_known && sensor.clock_source_known && sensor.clock_source_ptp &&
        sensor.ptp_state != kPtpLocked) {
      problem("sensor clock source is PTP but PTP is {} (not locked)",
              ptc::ptp_state_name(sensor.ptp_state));
    }
    // The status's motor speed, checked as the packets' is.
    const bool motor_known = (sensor.implausible >> ptc::kMotorBit & 1u) == 0;
    if (motor_known && std::abs(sensor.motor_rpm - expected.rpm) > 0.1 * expected.rpm) {
      problem("sensor status: motor at {:.0f} RPM (expected {})", sensor.motor_rpm, expected.rpm);
    }
  }
  host();
  // Failing writes degrade (capture goes on, and every byte not written is counted; they lead
  // the reason).
  g.state = problems.empty() ? HealthState::kOk : HealthState::kDegraded;
}

}  // namespace pandarcap
