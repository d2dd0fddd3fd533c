// The health state and reason (core/health/health_policy.hpp), decided from two counter snapshots
// without a daemon: each problem's text, their order, and error > no_data > degraded > ok.
#include <catch2/catch.hpp>
#include <string>

#include "core/health/health_policy.hpp"
#include "core/ipv4.hpp"

using namespace pandarcap;

namespace {

// A sensor streaming as expected: packets arriving, 600 RPM, last return.
HealthGauges streaming() {
  HealthGauges g;
  g.return_mode = "last";
  g.rpm_tail = 600;
  g.seconds_since_last_packet = 0.01;
  g.state = HealthState::kNoData;  // whatever it was before: classify_health overwrites it
  g.reason = "stale reason";
  return g;
}

const HealthExpectations kLast{"last", 600};

}  // namespace

TEST_CASE("Health: nothing grew, nothing wrong is ok with an empty reason", "[health][policy]") {
  HealthCounters before, now;
  now.datagrams_received = before.datagrams_received + 10'000;  // traffic alone is no problem
  now.packets_accepted = before.packets_accepted + 10'000;
  HealthGauges g = streaming();
  classify_health(now, before, kLast, false, "", g);
  CHECK(g.state == HealthState::kOk);
  CHECK(g.reason.empty());
}

TEST_CASE("Health: each counter that grew is a named problem", "[health][policy]") {
  struct Case {
    std::uint64_t HealthCounters::*counter;
    const char* reason;
  };
  const Case cases[] = {
      {&HealthCounters::kernel_drops, "3 kernel drops"},
      {&HealthCounters::ring_overruns, "3 ring overruns"},
      {&HealthCounters::frames_dropped_no_arena, "3 frames dropped (no free arena)"},
      {&HealthCounters::pcap_packets_not_recorded, "3 packets not recorded"},
      {&HealthCounters::sequence_lost, "3 packets lost (sequence)"},
      {&HealthCounters::azimuth_gaps, "3 azimuth gaps"},
      {&HealthCounters::packets_rejected, "3 packets rejected"},
      {&HealthCounters::static_timestamp_packets, "3 static timestamps"},
      {&HealthCounters::backward_timestamp_packets, "3 timestamps going back"},
      {&HealthCounters::timestamp_jump_packets, "3 timestamps leaping forward"},
      {&HealthCounters::invalid_time_packets,
       "3 packets with an impossible tail time (the last: date or microseconds)"},
      {&HealthCounters::sequence_resets, "3 sequence resets (the sensor restarted?)"},
      {&HealthCounters::sequence_reordered, "3 packets reordered"},
      {&HealthCounters::points_missing, "3 points missing (lost packets)"},
      {&HealthCounters::standing_packets, "3 packets with the azimuth standing"},
      {&HealthCounters::reversed_packets, "3 packets turning backwards (left out)"},
      {&HealthCounters::stream_changes,
       "3 stream changes (a restart, a gap, a new speed, a clock step or a reversal)"},
  };
  for (const Case& c : cases) {
    INFO(c.reason);
    HealthCounters before, now;
    before.*c.counter = 5;  // what grew counts, not the total
    now.*c.counter = 8;
    HealthGauges g = streaming();
    classify_health(now, before, kLast, false, "", g);
    CHECK(g.state == HealthState::kDegraded);
    CHECK(g.reason == c.reason);
    // Not growing any more: back to ok.
    classify_health(now, now, kLast, false, "", g);
    CHECK(g.state == HealthState::kOk);
  }
}

TEST_CASE("Health: write errors quote the last error and lead the reason", "[health][policy]") {
  HealthCounters before, now;
  now.write_errors = 2;
  now.bytes_not_written = 4096;
  now.kernel_drops = 1;
  HealthGauges g = streaming();
  classify_health(now, before, kLast, false, "cannot write 'x': No space left on device", g);
  CHECK(g.state == HealthState::kDegraded);
  CHECK(g.reason ==
        "2 write errors (4096 bytes not written): cannot write 'x': No space left on device; "
        "1 kernel drops");
}

TEST_CASE("Health: what a full disk kept out of the recordings is said per output",
          "[health][policy]") {
  // The bytes alone do not say how many packets or messages the recordings lack: each output's
  // count follows them, also without a write error (the health's room kept).
  for (const bool failed : {true, false}) {
    HealthCounters before, now;
    before.pcap_packets_not_written = 10;
    before.mcap_messages_not_written = 20;
    now = before;
    now.write_errors = failed ? 3 : 0;
    now.bytes_not_written = failed ? 9000 : 0;
    now.pcap_packets_not_written = 17;
    now.mcap_messages_not_written = 31;
    HealthGauges g = streaming();
    classify_health(now, before, kLast, false, "cannot write 'x': No space left on device", g);
    INFO(g.reason);
    CHECK(g.state == HealthState::kDegraded);
    CHECK(g.reason ==
          std::string(failed ? "3 write errors (9000 bytes not written): cannot write 'x': No "
                               "space left on device; "
                             : "") +
              "7 packets not written to the pcap (failed writes or the health's room); 11 MCAP "
              "messages not written (failed writes or the health's room)");
  }
}

TEST_CASE("Health: the sensor's high-temperature flag degrades", "[health][policy]") {
  HealthCounters counters;
  HealthGauges g = streaming();
  g.high_temperature = true;
  classify_health(counters, counters, kLast, false, "", g);
  CHECK(g.state == HealthState::kDegraded);
  CHECK(g.reason == "sensor high-temperature flag set");
}

TEST_CASE("Health: a return mode other than expected degrades, unless any is expected",
          "[health][policy]") {
  HealthCounters counters;
  HealthGauges g = streaming();
  g.return_mode = "dual";
  classify_health(counters, counters, kLast, false, "", g);
  CHECK(g.state == HealthState::kDegraded);
  CHECK(g.reason == "return mode dual (expected last)");
  classify_health(counters, counters, HealthExpectations{"any", 600}, false, "", g);
  CHECK(g.state == HealthState::kOk);
  g.return_mode = "";  // before the first packet: nothing to compare
  classify_health(counters, counters, kLast, false, "", g);
  CHECK(g.state == HealthState::kOk);
}

TEST_CASE("Health: a motor more than 10 % off the expected speed degrades", "[health][policy]") {
  HealthCounters counters;
  HealthGauges g = streaming();
  g.rpm_tail = 659;  // within 10 % of 600
  classify_health(counters, counters, kLast, false, "", g);
  CHECK(g.state == HealthState::kOk);
  g.rpm_tail = 661;
  classify_health(counters, counters, kLast, false, "", g);
  CHECK(g.state == HealthState::kDegraded);
  CHECK(g.reason == "motor at 661 RPM (expected 600)");
  g.rpm_tail = 539.6;
  classify_health(counters, counters, kLast, false, "", g);
  CHECK(g.reason == "motor at 540 RPM (expected 600)");
  g.rpm_tail = 1200;
  classify_health(counters, counters, HealthExpectations{"last", 1200}, false, "", g);
  CHECK(g.state == HealthState::kOk);
}

TEST_CASE("Health: receive errors are an error, whatever else is wrong", "[health][policy]") {
  // The second's losses follow the error (as they follow a silence: a reader summing the
  // reasons' counts finds them all); what is about the sensor does not.
  HealthCounters before, now;
  now.receive_errors = 4;
  now.kernel_drops = 7;
  now.write_errors = 1;
  now.bytes_not_written = 100;
  now.pcap_packets_not_written = 2;
  HealthGauges g = streaming();
  g.high_temperature = true;
  classify_health(now, before, kLast, true, "disk full", g);  // silent too: error still wins
  CHECK(g.state == HealthState::kError);
  CHECK(g.reason ==
        "4 receive errors: the socket is failing; 1 write errors (100 bytes not written): disk "
        "full; 2 packets not written to the pcap (failed writes or the health's room); 7 kernel "
        "drops");
}

TEST_CASE("Health: silence is no_data, before and after the first packet", "[health][policy]") {
  HealthCounters before, now;
  now.packets_rejected = 2;  // a problem too, but silence wins over degraded
  HealthGauges g = streaming();
  g.seconds_since_last_packet = -1;
  classify_health(now, before, kLast, true, "", g);
  CHECK(g.state == HealthState::kNoData);
  CHECK(g.reason == "no packet received yet");
  g.seconds_since_last_packet = 2.54;
  classify_health(now, before, kLast, true, "", g);
  CHECK(g.state == HealthState::kNoData);
  CHECK(g.reason == "no packet for 2.5 s");
}

TEST_CASE("Health: a silence while the receiver is behind is degraded, not no_data",
          "[health][policy]") {
  // The receiver has not seen what arrived in the last 2.3 s (its thread starved, a backlog):
  // the sensor is not blamed. The second's losses and the host's side follow, as after a
  // silence; what is about the packets does not (none was seen).
  HealthCounters before, now;
  now.kernel_drops = 12;
  now.packets_rejected = 2;
  HealthGauges g = streaming();
  g.seconds_since_last_packet = 3.14;
  g.high_temperature = true;
  classify_health(now, before, kLast, Silence(true, 2.34), "", g);
  CHECK(g.state == HealthState::kDegraded);
  CHECK(g.reason ==
        "the receiver is 2.3 s behind: no packet seen for 3.1 s, whether the sensor sent is not "
        "known; 12 kernel drops");
  g.seconds_since_last_packet = -1;
  classify_health(now, now, kLast, Silence(true, 1.2), "", g);
  CHECK(g.reason ==
        "the receiver is 1.2 s behind: no packet seen yet, whether the sensor sent is not known");
  // Not silent: the packets speak for themselves, however late the receiver's last look.
  g.seconds_since_last_packet = 0.2;
  g.high_temperature = false;
  classify_health(now, now, kLast, Silence(false, 2.0), "", g);
  CHECK(g.state == HealthState::kOk);
  // Receive errors still win.
  now.receive_errors = 1;
  classify_health(now, before, kLast, Silence(true, 2.0), "", g);
  CHECK(g.state == HealthState::kError);
}

TEST_CASE("Health: a silent second's losses follow the silence in its reason", "[health][policy]") {
  // A writer stalled, then a stop (SIGTERM): the receiver stopped, and the writer, released
  // later, counted what it could not keep in a second that is silent by then. Each loss of
  // each kind is said after the silence; what is about the packets (the motor, rejects, the
  // tail's speed) is not, as no packet came.
  HealthCounters before, now;
  now.pcap_packets_not_recorded = 7;
  now.mcap_messages_not_recorded = 6130;
  now.frames_dropped_no_arena = 2;
  now.write_errors = 1;
  now.bytes_not_written = 4096;
  now.packets_rejected = 3;
  HealthGauges g = streaming();
  g.seconds_since_last_packet = 2.14;
  g.rpm_tail = 300;
  classify_health(now, before, kLast, true, "cannot write 'x.pcd.part': No space left on device",
                  g);
  CHECK(g.state == HealthState::kNoData);
  CHECK(g.reason ==
        "no packet for 2.1 s; 1 write errors (4096 bytes not written): cannot write "
        "'x.pcd.part': No space left on device; 2 frames dropped (no free arena); 7 packets not "
        "recorded; 6130 MCAP messages not recorded (behind: compression, its disk or the "
        "writer)");
  // Nothing new in the next second: the silence alone.
  classify_health(now, now, kLast, true, "", g);
  CHECK(g.reason == "no packet for 2.1 s");
  // Before the first packet too.
  HealthCounters dropped;
  dropped.kernel_drops = 5;
  g.seconds_since_last_packet = -1;
  classify_health(dropped, before, kLast, true, "", g);
  CHECK(g.reason == "no packet received yet; 5 kernel drops");
}

TEST_CASE("Health: several problems are joined by semicolons, in a fixed order",
          "[health][policy]") {
  HealthCounters before, now;
  now.timestamp_jump_packets = 1;
  now.kernel_drops = 2;
  now.packets_rejected = 3;
  HealthGauges g = streaming();
  g.return_mode = "strongest";
  g.rpm_tail = 300;
  g.high_temperature = true;
  classify_health(now, before, kLast, false, "", g);
  CHECK(g.state == HealthState::kDegraded);
  CHECK(g.reason ==
        "2 kernel drops; 3 packets rejected; 1 timestamps leaping forward; sensor high-temperature "
        "flag set; "
        "return mode strongest (expected last); motor at 300 RPM (expected 600)");
}

TEST_CASE("Health: the reason is rewritten in place, keeping its capacity", "[health][policy]") {
  HealthCounters before, now;
  now.kernel_drops = 1;
  HealthGauges g = streaming();
  g.reason.reserve(256);
  const char* const storage = g.reason.data();
  classify_health(now, before, kLast, false, "", g);
  CHECK(g.reason == "1 kernel drops");
  CHECK(g.reason.data() == storage);
  classify_health(now, before, kLast, true, "", g);
  CHECK(g.reason == "no packet for 0.0 s; 1 kernel drops");
  CHECK(g.reason.data() == storage);
}

TEST_CASE("Health: the sensor's PTP not locked degrades when PTP is its clock source",
          "[health][policy][ptc]") {
  const HealthCounters c;
  HealthGauges g = streaming();
  SensorStatusGauges& st = g.sensor_status;
  st.polled = st.available = true;
  st.interval_seconds = 5;
  st.age_seconds = 1;
  st.motor_rpm = 600;  // turning as expected: the PTP state is the only problem
  st.clock_source_known = st.clock_source_ptp = true;
  for (const auto& [state, name] : {std::pair{0, "free_run"}, std::pair{1, "tracking"},
                                    std::pair{3, "frozen"}, std::pair{9, "unknown"}}) {
    st.ptp_state = static_cast<std::uint8_t>(state);
    classify_health(c, c, kLast, false, "", g);
    CHECK(g.state == HealthState::kDegraded);
    CHECK(g.reason ==
          std::string("sensor clock source is PTP but PTP is ") + name + " (not locked)");
  }
  st.ptp_state = 2;  // locked
  classify_health(c, c, kLast, false, "", g);
  CHECK(g.state == HealthState::kOk);
  // GPS as the clock source: the PTP byte is not the sensor's time, nothing to degrade.
  st.ptp_state = 0;
  st.clock_source_ptp = false;
  classify_health(c, c, kLast, false, "", g);
  CHECK(g.state == HealthState::kOk);
}

TEST_CASE("Health: a sensor status gone stale degrades, one never received does not",
          "[health][policy][ptc]") {
  const HealthCounters c;
  HealthGauges g = streaming();
  SensorStatusGauges& st = g.sensor_status;
  st.polled = true;
  st.interval_seconds = 5;
  st.available = false;  // never answered: reported (age -1, ptc_errors), not degraded
  st.age_seconds = -1;
  classify_health(c, c, kLast, false, "", g);
  CHECK(g.state == HealthState::kOk);
  st.available = st.stale = true;
  st.age_seconds = 16.4;
  st.clock_source_known = st.clock_source_ptp = true;
  st.ptp_state = 1;  // a stale status's PTP state is not reported as current
  classify_health(c, c, kLast, false, "", g);
  CHECK(g.state == HealthState::kDegraded);
  CHECK(g.reason == "sensor status stale: no answer over PTC for 16 s");
  // Silence still wins: no_data says what matters most.
  classify_health(c, c, kLast, true, "", g);
  CHECK(g.state == HealthState::kNoData);
}

TEST_CASE("Health: a sensor clock off from the host's past the bound is degraded, with the offset",
          "[health][policy]") {
  HealthCounters before, now;
  HealthGauges g = streaming();
  g.sensor_clock_offset_known = true;
  // The real capture: the sensor's clock read 2017-09-06 while the host recorded in 2023.
  g.sensor_clock_offset_seconds = -168'035'162.4;
  HealthExpectations bounded = kLast;
  bounded.max_clock_offset_seconds = 1.0;
  classify_health(now, before, bounded, false, "", g);
  CHECK(g.state == HealthState::kDegraded);
  CHECK(g.reason == "sensor clock off by 168035162 s (behind the host): not synchronised?");

  g.sensor_clock_offset_seconds = 1.25;  // small offsets keep their milliseconds
  classify_health(now, before, bounded, false, "", g);
  CHECK(g.reason == "sensor clock off by 1.250 s (ahead of the host): not synchronised?");

  g.sensor_clock_offset_seconds = -0.0004;  // a synchronised sensor: its packet left 0.4 ms ago
  classify_health(now, before, bounded, false, "", g);
  CHECK(g.state == HealthState::kOk);

  g.sensor_clock_offset_seconds = 1e9;
  bounded.max_clock_offset_seconds = 0;  // 0: not checked (replays)
  classify_health(now, before, bounded, false, "", g);
  CHECK(g.state == HealthState::kOk);

  bounded.max_clock_offset_seconds = 1.0;
  g.sensor_clock_offset_known = false;  // no packet with a receive time yet: nothing to judge
  classify_health(now, before, bounded, false, "", g);
  CHECK(g.state == HealthState::kOk);
}

TEST_CASE("Health: a motor that stops is a fault, whatever its tail says", "[health][policy]") {
  struct Case {
    const char* name;
    double rpm_tail;
    std::uint64_t standing, frameless;
    bool arriving;
    const char* reason;
  };
  const Case cases[] = {
      {"the tail says 0", 0, 0, 0, true, "motor stopped: the packets' tail says 0 RPM"},
      {"the tail says 0, no packet this second", 0, 0, 0, false, ""},
      {"standing azimuth, tail normal", 600, 3600, 0, true,
       "motor stopped: azimuth standing in 3600 packets"},
      {"a stop of 8 packets (2.2 ms)", 600, 8, 0, true,
       "motor stopped: azimuth standing in 8 packets"},
      {"fewer standing: copies or glitches", 600, 7, 0, true,
       "7 packets with the azimuth standing"},
      {"frames not closing", 600, 0, 2521, true, "motor stopped: no frame closed in 2521 packets"},
      {"all three", 0, 3600, 2521, true,
       "motor stopped: the packets' tail says 0 RPM, azimuth standing in 3600 packets, no frame "
       "closed in 2521 packets"},
  };
  for (const Case& k : cases) {
    INFO(k.name);
    HealthCounters before, now;
    before.packets_accepted = 1000;
    now.packets_accepted = before.packets_accepted + (k.arriving ? 3600 : 0);
    now.standing_packets = k.standing;
    now.frameless_packets = k.frameless;
    HealthGauges g = streaming();
    g.return_mode = "dual";
    g.rpm_tail = k.rpm_tail;
    classify_health(now, before, HealthExpectations{"dual", 600}, false, "", g);
    CHECK(g.reason == k.reason);
    CHECK(g.state == (*k.reason == '\0' ? HealthState::kOk : HealthState::kDegraded));
  }
}

TEST_CASE("Health: the speed measured from the azimuth is checked when the tail's is fine",
          "[health][policy]") {
  HealthCounters before, now;
  now.packets_accepted = 3600;
  HealthGauges g = streaming();
  g.rpm_measured = 598;  // within 10 %
  classify_health(now, before, kLast, false, "", g);
  CHECK(g.state == HealthState::kOk);
  g.rpm_measured = 300;  // the tail says 600, the azimuth half that
  classify_health(now, before, kLast, false, "", g);
  CHECK(g.reason == "motor measured at 300 RPM (expected 600)");
  g.rpm_tail = 300;  // both off: the tail's is said, once
  classify_health(now, before, kLast, false, "", g);
  CHECK(g.reason == "motor at 300 RPM (expected 600)");
  // An azimuth that barely turns: a stopped motor, whatever the tail says.
  g.rpm_tail = 600;
  g.rpm_measured = 12.5;
  classify_health(now, before, kLast, false, "", g);
  CHECK(g.reason == "motor stopped: azimuth turning at 12.5 RPM");
}

TEST_CASE("Health: a packet rate more than 10 % off the sensor's is a problem of its own",
          "[health][policy]") {
  struct Case {
    const char* mode;
    double rate;
    const char* reason;
  };
  const Case cases[] = {
      {"dual", 3600, ""},
      {"dual", 3300, ""},  // 8 % low: some loss, said elsewhere
      {"dual", 7200, "packet rate 7200/s (expected 3600 in dual return)"},
      {"dual", 3000, "packet rate 3000/s (expected 3600 in dual return)"},
      {"last", 1800, ""},
      {"strongest", 3600, "packet rate 3600/s (expected 1800 in strongest return)"},
      {"dual", 0, ""},  // not known
  };
  for (const Case& k : cases) {
    INFO(k.mode << " at " << k.rate);
    HealthCounters before, now;
    now.packets_accepted = 3600;
    HealthGauges g = streaming();
    g.return_mode = k.mode;
    g.rpm_measured = 600;
    g.packet_rate_hz = k.rate;
    classify_health(now, before, HealthExpectations{"any", 600}, false, "", g);
    CHECK(g.reason == k.reason);
  }
}

TEST_CASE("Health: a second sensor on the port is named with the first", "[health][policy]") {
  HealthCounters before, now;
  now.packets_accepted = 3600;
  now.other_sensor_packets = 3600;
  now.foreign_datagrams = 3600;
  HealthGauges g = streaming();
  g.sensor_source = pack_ipv4_source(0x7F000001, 10000);
  g.other_sensor_source = pack_ipv4_source(0x7F000002, 10001);
  classify_health(now, before, kLast, false, "", g);
  CHECK(g.state == HealthState::kDegraded);
  CHECK(g.reason ==
        "3600 packets from a second sensor at 127.0.0.2:10001 (the sensor is 127.0.0.1:10000): "
        "one sensor per daemon");
  // Foreign datagrams that are not packets are not a second sensor.
  HealthCounters noise = before;
  noise.foreign_datagrams = 50;
  classify_health(noise, before, kLast, false, "", g);
  CHECK(g.state == HealthState::kOk);
  // The lock moved to another source after the sensor's fell silent.
  HealthCounters moved = before;
  moved.sensor_source_changes = 1;
  classify_health(moved, before, kLast, false, "", g);
  CHECK(g.reason == "the sensor's source changed to 127.0.0.1:10000 (127.0.0.2:10001 silent)");
  // Both in one second: the packets dropped came from 127.0.0.1 before the change (a second
  // sensor then) and from 127.0.0.2 after it, and neither is named as the other's role.
  HealthCounters both = now;
  both.sensor_source_changes = 1;
  classify_health(both, before, kLast, false, "", g);
  CHECK(g.reason ==
        "3600 packets from a second sensor (127.0.0.1:10000 or 127.0.0.2:10001: the sensor "
        "changed in this second): one sensor per daemon; the sensor's source changed to "
        "127.0.0.1:10000 (127.0.0.2:10001 silent)");
}

TEST_CASE("Health: while silent, the host's side is said after the losses", "[health][policy]") {
  // Where the health goes and the disk's time left are true whether packets come or not.
  HealthCounters before, now;
  now.packets_rejected = 4;  // about packets: not said while none come
  HealthGauges g = streaming();
  g.seconds_since_last_packet = 3.0;
  g.health_fallback.active = true;
  g.health_fallback.directory = "/run/pandarcap/pandar40p";
  g.health_fallback.error = "Read-only file system";
  classify_health(now, before, kLast, true, "", g);
  CHECK(g.state == HealthState::kNoData);
  CHECK(g.reason ==
        "no packet for 3.0 s; health written to /run/pandarcap/pandar40p (Read-only file system)");
}
