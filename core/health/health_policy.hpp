// The health state and its reason, decided from what changed in the last second. Pure: the
// writer thread hands it the counters of now and of the previous health record, the gauges and
// what the operator expects; nothing here reads a clock or a file.
//
// Precedence: error > no_data > degraded > ok (a silence the receiver is behind on: degraded).
//   - error:    receive_errors grew ("3 receive errors: the socket is failing"): not capturing.
//   - no_data:  no packet yet, or none for longer than the no-data timeout (`silent`):
//               "no packet received yet" / "no packet for 2.5 s". Not while the receiver is
//               behind (Silence below): then degraded, "the receiver is 2.3 s behind: no packet
//               seen for 3.1 s, whether the sensor sent is not known", and the second's losses
//               and the host's side, as after a silence.
//   - degraded: data flows but something grew or looks wrong (or a silence the receiver cannot
//               vouch for, above); every problem is named, joined by
//               "; " in a fixed order: write errors first (with the last error's text), then
//               kernel drops, ring overruns, a second sensor on the port ("3600 packets from a
//               second sensor at 127.0.0.2:2368 (the sensor is 127.0.0.1:2368): one sensor per
//               daemon") or the sensor's source changed, frames dropped, packets not recorded,
//               packets lost, files removed before they were uploaded ("1 file removed before it
//               was uploaded (9.0 MB; the last by the free-space floor:
//               pandarcap_..._0003.pcap.zst)"), sequence resets and reorders, azimuth gaps, points
//               missing, rejects, duplicates, outliers, timestamp troubles, the high-temperature
//               flag, a return mode other than expected, a motor that stopped ("motor stopped: the
//               packets' tail says 0 RPM, azimuth standing in 3600 packets, no frame closed in
//               2521 packets"; or "azimuth turning at 12.5 RPM", under a tenth of the expected
//               speed), a motor speed more than 10 % off (the tail's, else the one
//               measured from the azimuth), a packet rate more than 10 % off the sensor's
//               ("packet rate 7200/s (expected 3600 in dual return)"), a sensor clock
//               off from the host's by more than the bound ("sensor clock off by 168035162 s
//               (behind the host): not synchronised?"), then the
//               sensor's own status (gauges.sensor_status): stale ("sensor status stale: no
//               answer over PTC for 16 s"), or PTP configured but not locked ("sensor clock
//               source is PTP but PTP is tracking (not locked)"). A sensor that never answered
//               PTC does not degrade: it is reported (age -1, ptc_errors), not assumed broken.
//               Then the health files' own directory failing ("health written to
//               /run/pandarcap/front (cannot write '/var/log/pandarcap/front/health.jsonl':
//               Read-only file system)"). Last, fewer hours of disk left than health.min_hours_left
//               ("0.8 hours of disk left (3072 MiB free at 1.1 MB/s written; health.min_hours_left
//               1)"), and the standing problems (gauges.standing: a replay's damaged recording, a
//               live view that cannot listen), which hold until they end rather than while a
//               counter grows.
//   - ok:       none of these; the reason is "".
// Example: "2 kernel drops; return mode dual (expected last)".
#pragma once

#include <string_view>

#include "core/health/health.hpp"
#include "core/sensors/sensor_model_id.hpp"

namespace pandarcap {

// Standing packets (core/decode/stream_decoder.hpp) in one record that say the motor stopped: a
// stop lasts longer than 2 ms. Fewer are copies or glitches, named as such.
inline constexpr std::uint64_t kStandingPacketsForStop = 8;

struct HealthExpectations {
  std::string_view return_mode = "any";  // "any", or the mode the sensor must send
  int rpm = 600;                         // motor speed; a tail more than 10 % off is a problem
  // A sensor clock further than this from the host's is a problem (gauges'
  // sensor_clock_offset_seconds); 0 = not checked. The daemon's default is 1 s
  // (health.max_sensor_clock_offset_seconds); 0 here keeps the pure default neutral.
  double max_clock_offset_seconds = 0;
  // Fewer hours of disk left than this (gauges' storage.hours_left) is a problem; 0 = not
  // checked (health.min_hours_left).
  double min_hours_left = 0;
  // Whose packet rate the stream is judged by: the model the packets are decoded as.
  SensorModelId model = SensorModelId::kPandar40P;
  // What else names a model, checked against it once packets are accepted (0: not known): the
  // calibration's channels, and the lasers the sensor's PTC inventory reports. A mismatch is a
  // problem naming both (a live "auto" whose packets are another model than its table: the
  // model's nominal table is then used).
  int calibration_channels = 0;
  int inventory_lasers = 0;
};

// What the writer knows of a silence. `silent`: no packet yet, or none for longer than the
// no-data timeout. `receiver_behind_seconds` (0: its looks are current): how long ago the moment
// was up to which the receiver has seen everything the kernel took, when that is further back
// than it looks. A silence is then the receiver's as much as the sensor's (a receive thread
// starved of CPU, a backlog it works through): the record says degraded and how far behind,
// never no_data, which would blame the sensor. Made from a bool where that is all there is.
struct Silence {
  bool silent = false;
  double receiver_behind_seconds = 0;
  Silence(bool silent_now, double behind_seconds = 0) noexcept
      : silent(silent_now), receiver_behind_seconds(behind_seconds) {}
};

// Sets gauges.state and gauges.reason from `now` against `before` (the counters of the previous
// health record) and the gauges' return_mode, high_temperature, rpm_tail and
// seconds_since_last_packet (-1: no packet yet). `silence`: above. `last_write_error` is quoted
// when write_errors grew. The reason is rewritten in place: once its capacity has grown to the
// longest reason, nothing is allocated.
void classify_health(const HealthCounters& now, const HealthCounters& before,
                     const HealthExpectations& expected, Silence silence,
                     std::string_view last_write_error, HealthGauges& gauges);

}  // namespace pandarcap
