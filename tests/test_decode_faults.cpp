// The decode faults against the real daemon: pandarcapd replaying recordings made of the real
// capture re-timed with a sensor's clock (support/retimed_capture.hpp) with the faults in them,
// at top speed, each run carrying several cases; and one live run as a user (and the issue's
// acceptance checks) runs it: `pandarcapd --port P --rpm 600 --return-mode dual
// --max-clock-offset 0 --duration 11`, fed over loopback. The checks are the user's: the exit
// summary's "frames N complete, M partial", the PCD files, the health records' state, reason and
// counters. The matrices of the rules themselves, case by case, are in test_stream_faults.cpp.
#include <netinet/in.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <array>
#include <catch2/catch.hpp>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>
#include <regex>
#include <string>
#include <vector>

#include "bench/child_process.hpp"
#include "core/decode/calibration.hpp"
#include "core/decode/decoder_target.hpp"
#include "core/decode/stream_decoder.hpp"
#include "core/frames/frame_collector.hpp"
#include "core/ipv4.hpp"
#include "core/units.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "daemon/pcap/pcap_writer.hpp"
#include "support/retimed_capture.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace std::chrono_literals;
using nlohmann::json;
using test::health_counter;
using test::RetimedCapture;
namespace fs = std::filesystem;

namespace {

const Endpoint kSensorA{0xC0A801C9, 10000};  // 192.168.1.201:10000
const Endpoint kSensorB{0xC0A801CA, 10000};  // 192.168.1.202:10000
const Endpoint kFaultsHost{0xC0A8010A, 2368};
// A revolution of the capture is about 56 700 points (dual return, or one of its returns as a
// single-return stream); a frame never holds more than a revolution and a quarter.
constexpr std::uint64_t kMostPoints = 57'000 * 5 / 4;

// A glitch of one of six kinds, by number (bursts cycle through them).
void glitch(int kind, std::span<std::uint8_t> p, std::int64_t t_ns, std::uint32_t seed) {
  switch (kind % 6) {
    case 0:
      test::set_time(p, t_ns - 500 * kNsPerMillisecond);
      break;
    case 1:
      test::set_time(p, t_ns + 500 * kNsPerMillisecond);
      break;
    case 2:
      test::date_second_back(p);
      break;
    case 3:
      test::zero_time(p);
      break;
    case 4:
      test::garbage_time(p, seed);
      break;
    default:
      test::shift_azimuth(p, seed % 2 == 0 ? 9000 : -4500);
      break;
  }
}

// What a recording's faults were, as the test made them.
struct Faults {
  std::uint64_t packets = 0, glitched = 0, lost = 0, standing = 0, resets = 0;
};

// A recording of `seconds` of the stream from `from`, packet k changed by `alter` (false: lost).
using Alter = std::function<bool(std::uint64_t k, std::span<std::uint8_t> packet)>;
void record(PcapWriter& pcap, const RetimedCapture& stream, std::uint64_t packets, Endpoint from,
            bool sequence, const Alter& alter) {
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  for (std::uint64_t k = 0; k < packets; ++k) {
    std::optional<std::uint32_t> number;
    if (sequence) number = static_cast<std::uint32_t>(k);
    const auto bytes = std::span(buffer).first(stream.packet(k, buffer, number));
    if (!alter(k, bytes)) continue;
    pcap.write(bytes, stream.time_ns(k) + 300'000, from, kFaultsHost);
  }
}

// The same file through the core (as pandarcap-inspect would): its frame counts.
AssemblerStats core_frames(const fs::path& capture) {
  FrameCollector frames(3, kDefaultFrameCapacityPoints, [](const Frame&) {});
  StreamDecoderConfig config;
  config.decoder_target = best_decoder_target();
  StreamDecoder decoder(Calibration::nominal(), config, frames);
  CaptureReader reader(capture.string());
  CaptureRecord record;
  while (reader.next(record) == CaptureStatus::kRecord)
    decoder.process(record.payload);
  decoder.flush();
  return decoder.frames();
}

struct Summary {
  std::uint64_t complete = 0, partial = 0;
};
Summary summary_frames(const std::string& log) {
  std::smatch m;
  REQUIRE(std::regex_search(log, m, std::regex(R"(frames ([0-9]+) complete, ([0-9]+) partial)")));
  return {std::stoull(m[1].str()), std::stoull(m[2].str())};
}

// The POINTS of a PCD file's header.
std::uint64_t pcd_points(const fs::path& pcd) {
  std::ifstream in(pcd, std::ios::binary);
  for (std::string line; std::getline(in, line);) {
    if (line.rfind("POINTS ", 0) == 0) return std::stoull(line.substr(7));
    if (line.rfind("DATA", 0) == 0) break;
  }
  FAIL("no POINTS in " << pcd);
  return 0;
}

// Every reason the run's health records gave, joined.
std::string all_reasons(const fs::path& out) {
  std::string reasons;
  for (const json& record : test::health_records(out))
    reasons += record.at("reason").get<std::string>() + "\n";
  return reasons;
}

void check_decode_identity(const json& h) {
  INFO(h.dump());
  CHECK(health_counter(h, "datagrams_received") ==
        health_counter(h, "packets_accepted") + health_counter(h, "packets_rejected") +
            health_counter(h, "duplicate_packets") + health_counter(h, "foreign_datagrams") +
            health_counter(h, "ring_overruns"));
  // Every channel slot of an accepted packet a point or a filtered count.
  std::uint64_t filtered = 0;
  for (const auto& [reason, n] : h.at("counters").at("filtered_points").items())
    filtered += n.get<std::uint64_t>();
  CHECK(health_counter(h, "points") + filtered ==
        health_counter(h, "packets_accepted") * kBlocks * kChannels);
}

}  // namespace

TEST_CASE(
    "replayed: glitch bursts of every kind, losses, a standing motor and a reboot in one "
    "recording: whole revolutions kept, the rest partial, all of it said",
    "[daemon][faults][threads]") {
  for (const ReturnMode mode : {ReturnMode::kDual, ReturnMode::kLast}) {
    const auto stream = RetimedCapture::load(mode);
    if (!stream) return;
    INFO(to_string(mode));
    test::ScratchDir dir("decode-faults-replay");
    const fs::path capture = dir / "faults.pcap";
    const std::uint64_t rate = stream->packets_per_second();
    const std::uint64_t revolution = rate / 10;
    Faults f;
    f.packets = 9 * rate;  // 9 s, 90 revolutions
    {
      PcapWriter pcap(capture.string());
      int burst = 0;
      std::uint16_t stood_at = 0;
      record(pcap, *stream, f.packets, kSensorA, true, [&](std::uint64_t k, auto p) {
        const std::uint64_t second = k / rate;
        // 5 lost in the 3rd second, 50 in the 4th, mid-revolution.
        const std::uint64_t in_second = k % rate;
        if (second == 2 && in_second >= revolution / 2 && in_second < revolution / 2 + 5) {
          ++f.lost;
          return false;
        }
        if (second == 3 && in_second >= revolution / 2 && in_second < revolution / 2 + 50) {
          ++f.lost;
          return false;
        }
        // Standing from 5 s to 7 s, its tail saying 0 RPM.
        if (k == 5 * rate) stood_at = test::first_azimuth(p);
        if (second == 5 || second == 6) {
          test::set_azimuth(p, stood_at);
          test::set_rpm(p, 0);
          ++f.standing;
          return true;
        }
        // A reboot at 8 s: the counter starts again at 0.
        if (k >= 8 * rate) {
          const auto number = static_cast<std::uint32_t>(k - 8 * rate);
          std::memcpy(p.data() + kPacketBytes, &number, 4);
        }
        // A burst every 500 packets, 1 to 16 long, of the six kinds in turn (not where the other
        // faults are, so each costs only what it should).
        const std::uint64_t length = std::array<std::uint64_t, 6>{1, 2, 3, 5, 10, 16}[burst % 6];
        if (k % 500 >= 250 && k % 500 < 250 + length && second != 2 && second != 3 && second != 4 &&
            second != 7) {
          glitch(burst / 6, p, stream->time_ns(k), static_cast<std::uint32_t>(k));
          ++f.glitched;
        }
        if (k % 500 == 250 + length) ++burst;
        return true;
      });
      pcap.close();
    }
    f.resets = 1;
    const AssemblerStats core = core_frames(capture);
    const fs::path out = dir / "out";
    const auto r =
        test::run_command(test::pandarcapd_command() + " --replay " + test::quoted(capture) +
                          " --top-speed --rpm 600 --return-mode " + std::string(to_string(mode)) +
                          " --max-clock-offset 0 --output-dir " + test::quoted(out) + " 2>&1");
    INFO(r.out);
    REQUIRE(r.exit_code == 0);
    const json h = test::last_health_record(out);
    INFO(h.dump());
    check_decode_identity(h);
    // The frames: the daemon's are the core's, and they are what the faults leave. 90
    // revolutions: the first and last partial; the two with a loss partial; 20 stood still,
    // and the ones the stop and the start cut; the bursts cost none.
    const Summary frames = summary_frames(r.out);
    CHECK(frames.complete == core.frames_complete);
    CHECK(frames.partial == core.frames_partial);
    CHECK(frames.complete >= 90 - 2 - 2 - 20 - 3);
    CHECK(frames.complete <= 90 - 2 - 2 - 20);
    // (50 single-return packets are 100° of azimuth: a discontinuity rather than a hole.)
    CHECK(core.frames_holed == (mode == ReturnMode::kDual ? 2 : 1));
    // The counters.
    CHECK(health_counter(h, "packets_accepted") == f.packets - f.lost);
    CHECK(health_counter(h, "outlier_packets") == f.glitched);
    CHECK(health_counter(h, "standing_packets") + 1 >= f.standing);
    CHECK(health_counter(h, "points_missing") == f.lost * kBlocks * kChannels);
    CHECK(health_counter(h, "sequence_lost") == f.lost);
    CHECK(health_counter(h, "sequence_resets") == f.resets);
    CHECK(health_counter(h, "duplicate_packets") == 0);
    CHECK(health_counter(h, "frameless_packets") > 0);
    // The PCD files: one per frame written, complete ones a revolution of points, none more
    // than a revolution and a quarter.
    std::uint64_t complete_files = 0;
    for (const fs::path& pcd : test::files_ending(out / "frames", ".pcd")) {
      const std::uint64_t points = pcd_points(pcd);
      INFO(pcd.filename().string() << ": " << points << " points");
      CHECK(points <= kMostPoints);
      if (pcd.filename().string().find("_partial") != std::string::npos) continue;
      ++complete_files;
      CHECK(points > 50'000u);
    }
    CHECK(complete_files == frames.complete);
    // What it said: each fault by name (the records' reasons together: a replay at top speed
    // gives few).
    const std::string reasons = all_reasons(out);
    INFO(reasons);
    CHECK(reasons.find("isolated outlier packets") != std::string::npos);
    CHECK(reasons.find("motor stopped") != std::string::npos);
    CHECK(reasons.find("points missing") != std::string::npos);
    CHECK(reasons.find("sequence resets") != std::string::npos);
    CHECK(r.out.find(std::to_string(health_counter(h, "standing_packets")) +
                     " standing packets (motor not turning; left out)") != std::string::npos);
  }
}

TEST_CASE("replayed: two sensors on one port: the first kept, the other named, never merged",
          "[daemon][faults][threads]") {
  const auto stream = RetimedCapture::load(ReturnMode::kDual);
  if (!stream) return;
  test::ScratchDir dir("decode-faults-sources");
  // Sensor A for 3 s; sensor B, phase-locked with it and 180° on, from 1 s to the end (or, in
  // the second recording, A falls silent at 1.5 s and B goes on to 4 s).
  const auto write = [&](const fs::path& path, std::uint64_t a_until, std::uint64_t b_until) {
    PcapWriter pcap(path.string());
    std::array<std::uint8_t, kMaxPacketBytes> a{}, b{};
    std::uint64_t b_sent = 0;
    for (std::uint64_t k = 0; k < std::max(a_until, b_until); ++k) {
      const auto first = std::span(a).first(stream->packet(k, a));
      if (k < a_until) pcap.write(first, stream->time_ns(k) + 300'000, kSensorA, kFaultsHost);
      if (k >= 3600 && k < b_until) {
        const auto second = std::span(b).first(stream->packet(k + 700, b));
        test::set_time(second, stream->time_ns(k));
        test::shift_azimuth(second,
                            18000 - (test::first_azimuth(second) - test::first_azimuth(first)));
        pcap.write(second, stream->time_ns(k) + 310'000, kSensorB, kFaultsHost);
        ++b_sent;
      }
    }
    pcap.close();
    return b_sent;
  };
  const fs::path both = dir / "both.pcap";
  const std::uint64_t b_packets = write(both, 3 * 3600, 3 * 3600);
  const fs::path alone = dir / "alone.pcap";
  write(alone, 3 * 3600, 0);
  const AssemblerStats clean = core_frames(alone);

  const auto replay = [&](const fs::path& capture, const std::string& extra, const fs::path& out) {
    const auto r =
        test::run_command(test::pandarcapd_command() + " --replay " + test::quoted(capture) +
                          " --top-speed --rpm 600 --return-mode dual "
                          "--max-clock-offset 0" +
                          extra + " --output-dir " + test::quoted(out) + " 2>&1");
    INFO(r.out);
    REQUIRE(r.exit_code == 0);
    return std::make_pair(test::last_health_record(out), r.out);
  };
  const std::string a = "192.168.1.201:10000", b = "192.168.1.202:10000";
  for (const auto& [extra, a_is_sensor] :
       {std::pair{std::string(), true}, std::pair{std::string(" --sensor-ip 192.168.1.201"), true},
        std::pair{std::string(" --sensor-ip 192.168.1.202"), false}}) {
    const std::string& sensor = a_is_sensor ? a : b;
    const std::string& other = a_is_sensor ? b : a;
    INFO("sensor_ip:" << (extra.empty() ? " none" : extra));
    const fs::path out = dir / ("out" + std::to_string(std::hash<std::string>{}(extra)));
    const auto [h, log] = replay(both, extra, out);
    INFO(h.dump());
    check_decode_identity(h);
    const std::uint64_t others = a_is_sensor ? b_packets : 3 * 3600;
    CHECK(health_counter(h, "other_sensor_packets") == others);
    CHECK(health_counter(h, "foreign_datagrams") == others);
    CHECK(h.at("gauges").at("sensor_source") == sensor);
    CHECK(h.at("gauges").at("other_sensor_source") == other);
    const std::string reasons = all_reasons(out);
    INFO(reasons);
    CHECK(reasons.find(std::string("packets from a second sensor at ") + other +
                       " (the sensor is " + sensor + "): one sensor per daemon") !=
          std::string::npos);
    // Never merged: the sensor's frames are its own, whole.
    if (a_is_sensor) CHECK(summary_frames(log).complete == clean.frames_complete);
    CHECK(health_counter(h, "outlier_packets") == 0);
    CHECK(health_counter(h, "standing_packets") == 0);
  }
  // A falls silent at 1.5 s, B sends on: a second later B is taken as the sensor, and said.
  const fs::path moved = dir / "moved.pcap";
  write(moved, 3600 + 1800, 4 * 3600);
  const auto [h, log] = replay(moved, "", dir / "out-moved");
  INFO(h.dump());
  check_decode_identity(h);
  CHECK(health_counter(h, "sensor_source_changes") == 1);
  CHECK(h.at("gauges").at("sensor_source") == "192.168.1.202:10000");
  // B's packets from 1 s (packet 3600) until a second after A's last (packet 5399): packet
  // 8999 is the first a second later, by the recording's times.
  CHECK(health_counter(h, "other_sensor_packets") == 8999 - 3600);
  const std::string reasons = all_reasons(dir / "out-moved");
  INFO(reasons);
  CHECK(reasons.find("the sensor's source changed to 192.168.1.202:10000 (192.168.1.201:10000 "
                     "silent)") != std::string::npos);
}

namespace {

// A UDP socket bound to `from` (127.0.0.1 or 127.0.0.2), for sending.
int sender(const char* from) {
  const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  REQUIRE(fd >= 0);
  const sockaddr_in local = ipv4_endpoint(from, 0, "test sender");
  REQUIRE(::bind(fd, reinterpret_cast<const sockaddr*>(&local), sizeof local) == 0);
  return fd;
}

std::int64_t realtime() {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

}  // namespace

TEST_CASE(
    "live, as the issue runs it: bursts, a loss, a motor that stops and restarts, a second "
    "sensor, each said within 2 s and counted",
    "[daemon][faults][threads]") {
  const auto stream = RetimedCapture::load(ReturnMode::kDual);
  if (!stream) return;
  test::ScratchDir dir("decode-faults-live");
  const fs::path out = dir / "out";
  const std::uint16_t port = harness::free_udp_port();
  harness::ChildProcess daemon(
      test::binary("pandarcapd"),
      {"--allow-root", "--port", std::to_string(port), "--rpm", "600", "--return-mode", "dual",
       "--max-clock-offset", "0", "--duration", "11", "--output-dir", out.string()},
      dir / "log.txt");
  INFO(daemon.log());
  REQUIRE(
      harness::wait_until([&] { return daemon.log().find("ready:") != std::string::npos; }, 20s));

  // 9 s at the sensor's pace, in 10 ms steps: bursts every 500 packets (the six kinds, 1 to 16
  // long), 50 lost at 2.05 s, the motor standing from 4 s to 6 s (its tail 0), a second sensor
  // (127.0.0.2, phase-locked, 180° on) from 7 s to 8 s.
  const int a = sender("127.0.0.1");
  const int b = sender("127.0.0.2");
  const sockaddr_in to = ipv4_endpoint("127.0.0.1", port, "daemon");
  std::array<std::uint8_t, kMaxPacketBytes> buffer{}, other{};
  Faults f;
  std::uint64_t b_sent = 0;
  std::uint16_t stood_at = 0;
  int burst = 0;
  std::int64_t stop_sent_ns = 0, second_sensor_ns = 0;
  const std::int64_t start = realtime();
  const std::uint64_t total = 9 * 3600;
  for (std::uint64_t k = 0; k < total; ++k) {
    if (k % 36 == 0) {
      // Pacing (not synchronisation): the next 10 ms of packets at their due time.
      const std::int64_t due = start + static_cast<std::int64_t>(k) * 1'000'000'000 / 3600;
      const timespec at{due / 1'000'000'000, due % 1'000'000'000};
      ::clock_nanosleep(CLOCK_REALTIME, TIMER_ABSTIME, &at, nullptr);
    }
    const auto p = std::span(buffer).first(stream->packet(k, buffer));
    const std::uint64_t second = k / 3600;
    if (k >= 2 * 3600 + 180 && k < 2 * 3600 + 230) {
      ++f.lost;
      continue;
    }
    if (k == 4 * 3600) {
      stood_at = test::first_azimuth(p);
      stop_sent_ns = realtime();
    }
    if (second == 4 || second == 5) {
      test::set_azimuth(p, stood_at);
      test::set_rpm(p, 0);
      ++f.standing;
    } else {
      const std::uint64_t length = std::array<std::uint64_t, 6>{1, 2, 3, 5, 10, 16}[burst % 6];
      if (k % 500 >= 250 && k % 500 < 250 + length && second != 2 && second != 3 && second != 6) {
        glitch(burst / 6, p, stream->time_ns(k), static_cast<std::uint32_t>(k));
        ++f.glitched;
      }
      if (k % 500 == 250 + length) ++burst;
    }
    ::sendto(a, p.data(), p.size(), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
    ++f.packets;
    if (second == 7) {
      if (k == 7 * 3600) second_sensor_ns = realtime();
      const auto q = std::span(other).first(stream->packet(k + 700, other));
      test::set_time(q, stream->time_ns(k));
      test::shift_azimuth(q, 18000 - (test::first_azimuth(q) - test::first_azimuth(p)));
      ::sendto(b, q.data(), q.size(), 0, reinterpret_cast<const sockaddr*>(&to), sizeof to);
      ++b_sent;
    }
  }
  ::close(a);
  ::close(b);
  REQUIRE(daemon.wait_exit(30s) == 0);

  const auto records = test::health_records(out);
  REQUIRE_FALSE(records.empty());
  const json& h = records.back();
  INFO(h.dump());
  check_decode_identity(h);
  const std::uint64_t overruns = test::check_ring_overruns(h);
  CHECK(health_counter(h, "kernel_drops") == 0);
  CHECK(health_counter(h, "datagrams_received") == f.packets + b_sent);
  // Each fault said, and soon: the motor within 2 s of stopping (a second more where a
  // sanitizer slows the decoder), the second sensor while it sends, named with the first.
  const auto said = [&](const std::string& text, std::int64_t from_ns) -> std::optional<double> {
    for (const json& record : records) {
      if (record.at("reason").get<std::string>().find(text) != std::string::npos) {
        return static_cast<double>(record.at("unix_time_ns").get<std::int64_t>() - from_ns) / 1e9;
      }
    }
    return std::nullopt;
  };
  const auto motor = said("motor stopped", stop_sent_ns);
  REQUIRE(motor);
  CHECK(*motor >= 0);
  CHECK(*motor <= (test::kSlowBuild ? 3.0 : 2.0));
  const auto second = said("packets from a second sensor at 127.0.0.2:", second_sensor_ns);
  REQUIRE(second);
  CHECK(*second <= (test::kSlowBuild ? 3.0 : 2.0));
  for (const json& record : records) {
    const std::string reason = record.at("reason").get<std::string>();
    if (reason.find("second sensor") != std::string::npos) {
      CHECK(reason.find("(the sensor is 127.0.0.1:") != std::string::npos);
      CHECK(record.at("state") == "degraded");
    }
  }
  CHECK(said("isolated outlier packets", start).has_value());
  CHECK(said("points missing", start).has_value());
  // The counters (a datagram a sanitizer's ring overran is lost, and may have been any).
  CHECK(health_counter(h, "other_sensor_packets") <= b_sent);
  CHECK(health_counter(h, "other_sensor_packets") + overruns >= b_sent);
  CHECK(health_counter(h, "standing_packets") + 1 + overruns >= f.standing);
  CHECK(health_counter(h, "outlier_packets") + overruns >= f.glitched);
  CHECK(health_counter(h, "outlier_packets") <= f.glitched);
  CHECK(health_counter(h, "points_missing") >= f.lost * kBlocks * kChannels);
  // The frames: of 90 revolutions, the first and last partial, the lossy one, the 20 the motor
  // stood for and the two its stop and start cut; the bursts cost none. A revolution that lost a
  // datagram to a sanitizer's overrun is partial too.
  const Summary frames = summary_frames(daemon.log());
  CHECK(frames.complete + std::min<std::uint64_t>(overruns, 90) >= 90 - 2 - 1 - 20 - 3);
  CHECK(frames.complete <= 90 - 2 - 1 - 20);
  CHECK(health_counter(h, "frames_complete") == frames.complete);
  for (const fs::path& pcd : test::files_ending(out / "frames", ".pcd")) {
    INFO(pcd.filename().string());
    CHECK(pcd_points(pcd) <= kMostPoints);
  }
}
