// The daemon on every supported model, as a user meets it: a replay of each real capture with its
// model detected from the packets, checked point for point against the project's independent
// reference decoder (tests/reference/, nebula's decode path re-implemented in Python and checked
// against nebula's own reference clouds: docs/sensors.md); and the simulated sensor of each
// model, live over loopback.
#include <netinet/in.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <nlohmann/json.hpp>
#include <string>
#include <thread>

#include "bench/child_process.hpp"
#include "core/ipv4.hpp"
#include "core/sensors/sensor_model_id.hpp"
#include "daemon/pcap/pcap_writer.hpp"
#include "support/mcap_reader.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace pandarcap::test;
using namespace std::chrono_literals;

namespace {

struct ReplayCase {
  const char* capture;
  const char* calibration;
  const char* min_range;
  const char* max_range;
  const char* sensor;  // the health's `sensor`
};

constexpr ReplayCase kReplays[] = {
    {"pandar64_nebula_dual_1198B.pcap", "nebula_Pandar64_calibration.csv", "0.3", "200",
     "pandar64"},
    {"pandarxt32_nebula_dual_1080B.pcap", "nebula_PandarXT32_calibration.csv", "0.05", "120",
     "pandarxt32"},
    {"pandarqt128_nebula_laststrongest_1127B.pcap", "nebula_PandarQT128_calibration.csv", "0.3",
     "300", "pandarqt128"},
    {"pandar40p_nebula_dual_600rpm_1262B.pcap", "nebula_Pandar40P_calibration.csv", "0.3", "200",
     "pandar40p"},
};

std::filesystem::path reference_script(const char* name) {
  return std::filesystem::path(PANDARCAP_SOURCE_DIR) / "tests" / "reference" / name;
}

}  // namespace

TEST_CASE("a replay of each model's capture, its model from the packets, matches the reference",
          "[sensors][replay][threads]") {
  for (const ReplayCase& c : kReplays) {
    CAPTURE(c.capture);
    const auto capture = real_capture(c.capture);
    const auto csv = real_capture(c.calibration);
    if (!capture || !csv) continue;
    ScratchDir dir("model-replay");
    // The acceptance command, as the issue gives it: no --sensor-model.
    const CommandResult run = run_command(
        pandarcapd_command() + " --replay " + quoted(*capture) + " --top-speed --calibration " +
        quoted(*csv) + " --min-range " + c.min_range + " --max-range " + c.max_range +
        " --max-clock-offset 0 --output-dir " + quoted(dir.path()) + " 2>&1");
    INFO(run.out);
    REQUIRE(run.exit_code == 0);
    const nlohmann::json health = last_health_record(dir.path());
    CHECK(health.value("sensor", "") == c.sensor);
    CHECK(health.value("state", "") == "ok");
    CHECK(health_counter(health, "packets_rejected") == 0);
    // sensor.json names the model the packets named.
    const nlohmann::json facts =
        nlohmann::json::parse(harness::read_file(dir / "raw" / "sensor.json"));
    CHECK(facts.value("model", "") == display_name(*parse_sensor_model(c.sensor)));

    const CommandResult compare = run_command(
        "python3 " + quoted(reference_script("compare_frames.py")) + " --capture " +
        quoted(*capture) + " --calibration " + quoted(*csv) + " --min-range " + c.min_range +
        " --max-range " + c.max_range + " --frames " + quoted(dir / "frames") + " --one-to-one");
    INFO(compare.out);
    REQUIRE(compare.exit_code == 0);
    const nlohmann::json verdict = nlohmann::json::parse(compare.out);
    CHECK(verdict.at("pass") == true);
    CHECK(verdict.at("fraction_ours_matched").get<double>() >= 0.99);
    CHECK(verdict.at("fraction_reference_matched").get<double>() >= 0.99);
    CHECK(verdict.at("max_matched_distance_m").get<double>() <= 0.005);
  }
}

TEST_CASE("a fixed sensor.model counts another model's packets as wrong_model, decodes none",
          "[sensors][replay][threads]") {
  const auto capture = real_capture("pandarxt32_nebula_dual_1080B.pcap");
  if (!capture) return;
  ScratchDir dir("model-fixed");
  const CommandResult run = run_command(pandarcapd_command() + " --replay " + quoted(*capture) +
                                        " --top-speed --sensor-model pandar64 --output-dir " +
                                        quoted(dir.path()) + " 2>&1");
  INFO(run.out);
  const nlohmann::json health = last_health_record(dir.path());
  REQUIRE(health.is_object());
  CHECK(health.value("sensor", "") == "pandar64");
  CHECK(health.at("counters").at("rejects").value("wrong_model", std::uint64_t{0}) == 2000);
  CHECK(health_counter(health, "packets_accepted") == 0);
  CHECK(files_ending(dir / "frames", ".pcd").empty());
}

TEST_CASE("an MCAP of a simulated PandarXT32 names its model and replays as one",
          "[sensors][mcap][simulate][threads]") {
  ScratchDir dir("model-mcap");
  const CommandResult run =
      run_command(pandarcapd_command() +
                  " --simulate --sensor-model pandarxt32 --mcap --mcap-packets --duration 2 "
                  "--output-dir " +
                  quoted(dir / "live") + " 2>&1");
  INFO(run.out);
  REQUIRE(run.exit_code == 0);
  const nlohmann::json live_facts =
      nlohmann::json::parse(harness::read_file(dir / "live" / "raw" / "sensor.json"));
  CHECK(live_facts.value("model", "") == "PandarXT32");
  const auto files = files_ending(dir / "live" / "mcap", ".mcap");
  REQUIRE(files.size() == 1);
  const nlohmann::json live_health = last_health_record(dir / "live");
  const std::uint64_t recorded = health_counter(live_health, "packets_accepted");
  // Left out of the MCAP: by its compression thread, or with no raw batch free (both counted as
  // the MCAP's; the second also as the pcap's).
  const std::uint64_t not_recorded = health_counter(live_health, "mcap_messages_not_recorded");
  REQUIRE(recorded > 1000);

  // What a reader finds, with the MCAP project's own reader: the packets channel's metadata and
  // the file's pandarcap record name the model.
  const auto read = read_mcap_independently(files.front());
  if (!read.reader_missing) {
    INFO(read.error);
    REQUIRE(read.file);
    bool named = false;
    for (const nlohmann::json& channel : read.file->at("channels")) {
      if (channel.at("topic") != "/pandar/packets") continue;
      CHECK(channel.at("metadata") == nlohmann::json{{"sensor_model", "PandarXT32"}});
      named = true;
    }
    CHECK(named);
    CHECK(read.file->at("metadata").at(0).at("entries").at("sensor_model") == "PandarXT32");
  }

  // pandarcap-inspect names it, and counts the packets in the file.
  const CommandResult inspect = run_command(quoted(binary("pandarcap-inspect")) +
                                            " --json --summary " + quoted(files.front()));
  REQUIRE(inspect.exit_code == 0);
  const nlohmann::json summary = nlohmann::json::parse(inspect.out).at("summary");
  CHECK(summary.at("model") == "PandarXT32");
  CHECK(summary.at("model_source") == "packets");
  CHECK(summary.at("rejected") == 0);
  // Every packet the run received, but any a busy machine left out (counted above; the MCAP's
  // count has frames and health among them).
  const std::uint64_t in_file = summary.at("accepted").get<std::uint64_t>();
  CHECK(in_file <= recorded);
  CHECK(in_file + not_recorded >= recorded);

  // Replayed with no --sensor-model: decoded as the XT32 it is, every packet accepted.
  const CommandResult replay =
      run_command(pandarcapd_command() + " --replay " + quoted(files.front()) +
                  " --top-speed --output-dir " + quoted(dir / "replay") + " 2>&1");
  INFO(replay.out);
  REQUIRE(replay.exit_code == 0);
  const nlohmann::json health = last_health_record(dir / "replay");
  CHECK(health.value("sensor", "") == "pandarxt32");
  CHECK(health_counter(health, "packets_rejected") == 0);
  CHECK(health_counter(health, "packets_accepted") == in_file);
  const nlohmann::json replay_facts =
      nlohmann::json::parse(harness::read_file(dir / "replay" / "raw" / "sensor.json"));
  CHECK(replay_facts.value("model", "") == "PandarXT32");
}

TEST_CASE("the simulated sensor of each model: its packets arrive, frames whole, nothing lost",
          "[sensors][simulate][threads]") {
  for (const char* model : {"pandar64", "PandarXT32", "pandarxt16", "PANDARQT128"}) {
    CAPTURE(model);
    ScratchDir dir("model-simulate");
    const CommandResult run =
        run_command(pandarcapd_command() + " --simulate --sensor-model " + model +
                    " --duration 3 --output-dir " + quoted(dir.path()) + " 2>&1");
    INFO(run.out);
    REQUIRE(run.exit_code == 0);
    const nlohmann::json health = last_health_record(dir.path());
    REQUIRE(health.is_object());
    std::string lower = model;
    for (char& ch : lower)
      ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
    CHECK(health.value("sensor", "") == lower);
    const std::uint64_t overruns = check_ring_overruns(health);
    // A TSan build's receiver, starved on a loaded machine, may lose datagrams in the kernel's
    // buffer as its decoder may overrun the ring: counted, and the sequence then has gaps.
    const std::uint64_t drops = health_counter(health, "kernel_drops");
    if (!kThreadSanitizerBuild) CHECK(drops == 0);
    CHECK(health_counter(health, "packets_rejected") == 0);
    // Every gap is a datagram lost where it was counted (none in release).
    CHECK(health_counter(health, "sequence_gaps") <= drops + overruns);
    CHECK(health_counter(health, "packets_accepted") + overruns > 1000);
    std::size_t partial = 0;
    for (const auto& f : files_ending(dir / "frames", ".pcd"))
      partial += f.filename().string().find("_partial") != std::string::npos;
    if (overruns == 0 && drops == 0) {
      CHECK(health_counter(health, "points_missing") == 0);
      // 30 revolutions in 3 s; a sanitizer build's simulated sensor, starved, sends fewer.
      CHECK(health_counter(health, "frames_complete") >= (kSlowBuild ? 5U : 20U));
      CHECK(health_counter(health, "outlier_packets") == 0);
      // Whole frames on disk, none partial but the first and the last.
      CHECK(partial <= 2);
    } else {
      // A TSan decoder that fell behind (check_ring_overruns): the frames that lost packets are
      // counted partial, and each record whose second had overruns does not say ok.
      CHECK(health_counter(health, "frames_partial") + 2 >= partial);
      std::uint64_t before = 0;
      for (const nlohmann::json& r : health_records(dir.path())) {
        const std::uint64_t overrun = health_counter(r, "ring_overruns");
        if (overrun > before) CHECK(r.value("state", "") != "ok");
        before = overrun;
      }
    }
  }
}

TEST_CASE("live with sensor.model auto: the first packets name the model, and it is decoded as it",
          "[sensors][daemon][threads]") {
  struct LiveCase {
    const char* capture;
    const char* calibration;  // "" : none (the nominal table of the model the packets name)
    const char* sensor;
    int packets_per_second;
    const char* said;           // in a degraded record's reason; "" : none is degraded
    int unsupported_first = 0;  // AT128 headers sent before the stream: counted across the switch
  };
  const LiveCase cases[] = {
      // 30 AT128 headers first: counted (unsupported_model) across the switch, and said.
      {"pandarxt32_nebula_dual_1080B.pcap", "", "pandarxt32", 5000, "packets rejected", 30},
      {"pandar64_nebula_dual_1198B.pcap", "nebula_Pandar64_calibration.csv", "pandar64", 6000, ""},
      // A table of another model than the packets: the packets' model is decoded, with its
      // nominal table, and the health says so.
      {"pandarxt32_nebula_dual_1080B.pcap", "nebula_Pandar64_calibration.csv", "pandarxt32", 5000,
       "the calibration has 64 channels, the packets are a PandarXT32's (32): its nominal table "
       "is used"},
  };
  for (const LiveCase& c : cases) {
    CAPTURE(c.capture);
    const auto capture = real_capture(c.capture);
    if (!capture) continue;
    std::optional<std::filesystem::path> csv;
    if (*c.calibration != 0) {
      csv = real_capture(c.calibration);
      if (!csv) continue;
    }
    const auto payloads = capture_payloads(*capture);
    ScratchDir dir("model-live");
    const std::uint16_t port = harness::free_udp_port();
    std::vector<std::string> args = {"--allow-root",
                                     "--port",
                                     std::to_string(port),
                                     "--max-clock-offset",
                                     "0",
                                     "--duration",
                                     "4",
                                     "--calibration-source",
                                     csv ? "file" : "nominal",
                                     "--output-dir",
                                     (dir / "out").string()};
    if (csv) args.insert(args.end(), {"--calibration", csv->string()});
    harness::ChildProcess daemon(binary("pandarcapd"), args, dir / "log.txt");
    INFO(daemon.log());
    REQUIRE(
        harness::wait_until([&] { return daemon.log().find("ready:") != std::string::npos; }, 20s));
    // The capture at the sensor's pace (paced, not synchronised: 10 ms of packets at a time).
    const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    REQUIRE(fd >= 0);
    const sockaddr_in to = ipv4_endpoint("127.0.0.1", port, "daemon");
    std::vector<std::uint8_t> at128(1118, 0x33);
    at128[0] = 0xEE, at128[1] = 0xFF, at128[2] = 4, at128[3] = 1;
    for (int i = 0; i < c.unsupported_first; ++i) {
      ::sendto(fd, at128.data(), at128.size(), 0, reinterpret_cast<const sockaddr*>(&to),
               sizeof to);
    }
    const auto start = std::chrono::steady_clock::now();
    const std::size_t step = static_cast<std::size_t>(c.packets_per_second / 100);
    for (std::size_t k = 0; k < payloads.size(); ++k) {
      if (k % step == 0) std::this_thread::sleep_until(start + (k / step) * 10ms);
      ::sendto(fd, payloads[k].data(), payloads[k].size(), 0,
               reinterpret_cast<const sockaddr*>(&to), sizeof to);
    }
    ::close(fd);
    REQUIRE(daemon.wait_exit(30s) == 0);
    const nlohmann::json h = last_health_record(dir / "out");
    INFO(h.dump());
    REQUIRE(h.is_object());
    const std::uint64_t overruns = check_ring_overruns(h);
    CHECK(h.value("sensor", "") == c.sensor);
    const auto unsupported = static_cast<std::uint64_t>(c.unsupported_first);
    CHECK(health_counter(h, "packets_rejected") + overruns >= unsupported);
    CHECK(health_counter(h, "packets_rejected") <= unsupported);
    CHECK(h.at("counters").at("rejects").value("unsupported_model", std::uint64_t{0}) ==
          health_counter(h, "packets_rejected"));
    CHECK(health_counter(h, "packets_accepted") + health_counter(h, "packets_rejected") +
              overruns ==
          payloads.size() + unsupported);
    CHECK(health_counter(h, "datagrams_received") ==
          health_counter(h, "packets_accepted") + health_counter(h, "packets_rejected") +
              health_counter(h, "duplicate_packets") + overruns);
    CHECK(health_counter(h, "kernel_drops") == 0);
    if (overruns == 0) CHECK(health_counter(h, "frames_complete") >= 2);
    bool said = false, degraded = false;
    for (const nlohmann::json& record : health_records(dir / "out")) {
      degraded = degraded || record.value("state", "") == "degraded";
      said = said || (record.value("state", "") == "degraded" &&
                      record.value("reason", "").find(c.said) != std::string::npos);
    }
    CHECK(degraded == (*c.said != 0));
    CHECK(said == (*c.said != 0));
    CHECK(daemon.log().find("sensor model: auto") != std::string::npos);
  }
}

TEST_CASE("a replay's model is its packets', whatever look-alikes or junk come first",
          "[sensors][replay][threads]") {
  const auto capture = real_capture("pandar64_nebula_dual_1198B.pcap");
  const auto csv = real_capture("nebula_Pandar64_calibration.csv");
  if (!capture || !csv) return;
  const auto payloads = capture_payloads(*capture);
  const Endpoint sensor{0xC0A801C9, 2368}, host{0xC0A8010A, 2368};
  // Before the Pandar64's packets: one datagram whose first bytes look like an OT128's header,
  // one AT128 header; or more junk than the start looks through (25 000 datagrams).
  std::vector<std::uint8_t> ot128(16, 0), at128(1118, 0x33);
  ot128[0] = 0xEE, ot128[1] = 0xFF, ot128[2] = 1, ot128[3] = 4;
  at128[0] = 0xEE, at128[1] = 0xFF, at128[2] = 4, at128[3] = 1;
  const std::vector<std::uint8_t> junk(100, 0x5A);
  struct Case {
    const char* name;
    std::vector<std::vector<std::uint8_t>> before;
  };
  const Case cases[] = {{"look-alikes", {ot128, at128}},
                        {"25000 junk", std::vector<std::vector<std::uint8_t>>(25'000, junk)}};
  for (const Case& c : cases) {
    CAPTURE(c.name);
    ScratchDir dir("model-replay-junk");
    {
      PcapWriter pcap((dir / "in.pcap").string());
      std::int64_t t = 1'593'086'530'000'000'000;
      for (const auto& p : c.before)
        pcap.write(p, t += 1000, sensor, host);
      for (const auto& p : payloads)
        pcap.write(p, t += 166'000, sensor, host);
    }
    const CommandResult run =
        run_command(pandarcapd_command() + " --replay " + quoted(dir / "in.pcap") +
                    " --top-speed " + "--calibration " + quoted(*csv) +
                    " --max-clock-offset 0 --output-dir " + quoted(dir / "out") + " 2>&1");
    INFO(run.out);
    REQUIRE(run.exit_code == 0);
    const nlohmann::json h = last_health_record(dir / "out");
    CHECK(h.value("sensor", "") == "pandar64");
    CHECK(health_counter(h, "packets_accepted") == payloads.size());
    CHECK(health_counter(h, "packets_rejected") == c.before.size());
    CHECK(health_counter(h, "datagrams_received") == payloads.size() + c.before.size());
    CHECK(health_counter(h, "frames_complete") >= 2);
  }
}
