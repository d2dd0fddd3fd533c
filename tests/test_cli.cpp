// The binaries, run as a user runs them: pandarcap-inspect --json on real and generated
// captures, pandarcapd --simulate, and their errors for bad input.
#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "support/test_support.hpp"

using namespace pandarcap;
using nlohmann::json;

namespace {

json inspect_json(const std::string& arguments) {
  const auto result =
      test::run_command(test::quoted(test::binary("pandarcap-inspect")) + " --json " + arguments);
  REQUIRE(result.exit_code == 0);
  return json::parse(result.out);
}

}  // namespace

TEST_CASE("inspect --json on the real dual capture", "[cli][real]") {
  const auto capture = test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  const auto calibration = test::real_capture("nebula_Pandar40P_calibration.csv");
  if (!capture || !calibration) return;
  const json j = inspect_json("--calibration " + test::quoted(*calibration) + " --port 2368 " +
                              test::quoted(*capture));
  const json& s = j.at("summary");
  CHECK(s.at("packets") == 1439);
  CHECK(s.at("accepted") == 1439);
  CHECK(s.at("rejected") == 0);
  CHECK(s.at("rejects").at("bad_length") == 0);
  CHECK(s.at("rpm_min").get<int>() >= 598);
  CHECK(s.at("rpm_max").get<int>() <= 602);
  CHECK(s.at("return_mode") == "dual");
  CHECK(s.at("sequence_present") == false);
  CHECK(s.at("sequence_gaps") == 0);
  CHECK(s.at("frames_complete").get<int>() >= 2);
  CHECK(s.at("frames_partial").get<int>() >= 1);
  CHECK(s.at("points_per_complete_frame").size() == s.at("frames_complete").get<std::size_t>());
  CHECK(s.at("capture_status") == "end");
  REQUIRE(j.at("packets").size() == 1439);
  const json& first = j.at("packets").at(0);
  CHECK(first.at("size") == 1262);
  CHECK(first.at("status") == "ok");
  CHECK(first.at("factory") == 0x42);
  CHECK(first.at("utc").get<std::string>().rfind("2017-09-06T", 0) == 0);
  CHECK(first.at("sequence").is_null());
  CHECK(first.at("status_id").is_number());
  CHECK(s.at("model") == "Pandar40P");
  CHECK(s.at("model_source") == "packets");

  // The destination-port filter: nothing in this capture goes to 2369.
  const json other = inspect_json("--port 2369 " + test::quoted(*capture));
  CHECK(other.at("summary").at("packets") == 0);
  CHECK(other.at("summary").at("capture").at("port_filtered") == 1439);
}

TEST_CASE("inspect --json on the real single 1266-byte packet", "[cli][real]") {
  const auto capture = test::real_capture("velocityreport_pandar40p_single_packet_1266B.pcapng");
  if (!capture) return;
  const json s = inspect_json(test::quoted(*capture)).at("summary");
  CHECK(s.at("packets") == 1);
  CHECK(s.at("return_mode") == "last");
  CHECK(s.at("sequence_present") == true);
  CHECK(s.at("rpm_min") == 599);
}

TEST_CASE("inspect on each model's real capture: the model named, every packet, counts that add up",
          "[cli][real][sensors]") {
  struct Case {
    const char* capture;
    const char* calibration;
    const char* model;
    std::uint64_t packets;
    std::uint64_t points_per_packet;  // blocks x channels: each a point or a filtered return
  };
  const Case cases[] = {
      {"pandar64_nebula_dual_1198B.pcap", "nebula_Pandar64_calibration.csv", "Pandar64", 2400,
       6 * 64},
      {"pandarxt32_nebula_dual_1080B.pcap", "nebula_PandarXT32_calibration.csv", "PandarXT32", 2000,
       8 * 32},
      {"pandarqt128_nebula_laststrongest_1127B.pcap", "nebula_PandarQT128_calibration.csv",
       "PandarQT128", 1800, 2 * 128},
  };
  for (const Case& c : cases) {
    CAPTURE(c.capture);
    const auto capture = test::real_capture(c.capture);
    const auto calibration = test::real_capture(c.calibration);
    if (!capture || !calibration) continue;
    const json j =
        inspect_json("--calibration " + test::quoted(*calibration) + " " + test::quoted(*capture));
    const json& s = j.at("summary");
    CHECK(s.at("model") == c.model);
    CHECK(s.at("model_source") == "packets");
    CHECK(s.at("calibration_source") == "file");
    CHECK(s.at("capture_status") == "end");
    CHECK(s.at("packets") == c.packets);
    CHECK(s.at("accepted") == c.packets);
    CHECK(s.at("rejected") == 0);
    CHECK(s.at("sequence_present") == true);
    CHECK(s.at("sequence_gaps") == 0);
    // Every return of every accepted packet is a point or counted by why it is not.
    std::uint64_t filtered = 0;
    for (const json& n : s.at("filtered"))
      filtered += n.get<std::uint64_t>();
    CHECK(s.at("points").get<std::uint64_t>() + filtered == c.packets * c.points_per_packet);
    // The frames hold every point; complete and partial ones are all listed.
    std::uint64_t frame_points = 0;
    for (const json& f : j.at("frames"))
      frame_points += f.at("points").get<std::uint64_t>();
    CHECK(frame_points == s.at("points"));
    CHECK(j.at("frames").size() ==
          s.at("frames_complete").get<std::size_t>() + s.at("frames_partial").get<std::size_t>());
    CHECK(s.at("points_per_complete_frame").size() == s.at("frames_complete").get<std::size_t>());
    // One line per packet, each with its model's fields.
    REQUIRE(j.at("packets").size() == c.packets);
    std::uint64_t ok = 0;
    for (const json& p : j.at("packets"))
      ok += p.at("status") == "ok" ? 1 : 0;
    CHECK(ok == c.packets);
    const json& first = j.at("packets").at(0);
    CHECK(first.at("sequence").is_number());
    CHECK(first.at("rpm").get<int>() >= 590);
    CHECK(first.at("rpm").get<int>() <= 610);
    CHECK(first.at("utc").get<std::string>().rfind("20", 0) == 0);
    CHECK_FALSE(first.contains("status_id"));  // the 40P's tail only
    CHECK(first.contains("mode_flag") == (std::string(c.model) == "PandarQT128"));
    if (std::string(c.model) == "PandarQT128") {
      // The capture's mode flag alternates every packet; its functional safety is fine (0-2).
      CHECK(first.at("mode_flag") != j.at("packets").at(1).at("mode_flag"));
      CHECK(first.at("functional_safety_state").get<int>() <= 2);
    }

    // The text: the model named, and a frame drawn as a PNG.
    test::ScratchDir dir("inspect-model");
    const auto text =
        test::run_command(test::quoted(test::binary("pandarcap-inspect")) + " --summary --png " +
                          test::quoted(dir / "frame.png") + " " + test::quoted(*capture) + " 2>&1");
    INFO(text.out);
    CHECK(text.exit_code == 0);
    CHECK(text.out.find(std::string("model ") + c.model + " (named by its packets)") !=
          std::string::npos);
    CHECK(text.out.find("the nominal " + std::string(c.model) + " table is used") !=
          std::string::npos);
    std::ifstream png(dir / "frame.png", std::ios::binary);
    char signature[8] = {};
    png.read(signature, sizeof signature);
    CHECK(std::string(signature + 1, 3) == "PNG");
    CHECK(std::filesystem::file_size(dir / "frame.png") > 1000);
  }

  // --sensor-model names another: every packet is that model's wrong_model, nothing decoded.
  const auto xt32 = test::real_capture("pandarxt32_nebula_dual_1080B.pcap");
  if (!xt32) return;
  const json s =
      inspect_json("--summary --sensor-model PANDAR64 " + test::quoted(*xt32)).at("summary");
  CHECK(s.at("model") == "Pandar64");
  CHECK(s.at("model_source") == "sensor-model");
  CHECK(s.at("accepted") == 0);
  CHECK(s.at("rejects").at("wrong_model") == 2000);
  CHECK(test::run_command(test::quoted(test::binary("pandarcap-inspect")) +
                          " --sensor-model pandar20 x.pcap 2>/dev/null")
            .exit_code == 64);
}

TEST_CASE("pandarcapd --simulate records a capture that inspect decodes",
          "[cli][simulate][realtime][threads]") {
  test::ScratchDir dir("simulate");
  const auto result = test::run_command(test::quoted(test::binary("pandarcapd")) + " --allow-root" +
                                        " --simulate --duration 1 --rpm 1200 --return-mode last "
                                        "--udp-sequence --log-level warn --output-dir " +
                                        test::quoted(dir.path()) + " 2>&1");
  INFO(result.out);
  REQUIRE(result.exit_code == 0);
  std::vector<std::filesystem::path> captures;
  for (const auto& entry : std::filesystem::directory_iterator(dir / "raw")) {
    if (entry.path().extension() == ".pcap") captures.push_back(entry.path());
  }
  REQUIRE(captures.size() == 1);
  // The daemon's own count of what it received and recorded, from its last health line.
  std::ifstream health_file(dir / "health/health.jsonl");
  std::string line;
  std::string last;
  while (std::getline(health_file, line)) {
    if (!line.empty()) last = line;
  }
  REQUIRE_FALSE(last.empty());
  const json counters = json::parse(last).at("counters");

  const json s = inspect_json("--summary " + test::quoted(captures.front())).at("summary");
  // 1800 packets/s in single return whatever the RPM, sent in real time for about a second;
  // the recording holds exactly what the daemon says it received (sanitizer builds: less what
  // it counted as not recorded or dropped, see kSlowBuild).
  const auto counted = [&](const char* name) {
    return test::kSlowBuild ? counters.at(name).get<std::uint64_t>() : 0;
  };
  const std::uint64_t not_recorded = counted("pcap_packets_not_recorded");
  const std::uint64_t frames_dropped = counted("frames_dropped_no_arena");
  CHECK(s.at("packets").get<std::uint64_t>() + not_recorded == counters.at("datagrams_received"));
  CHECK(s.at("packets") == counters.at("pcap_packets_written"));
  // (A sanitizer build's simulated sensor, starved on a loaded machine, sends fewer in the time.)
  const int packets = s.at("packets").get<int>();
  CHECK(packets >= (test::kSlowBuild ? 600 : 1500));
  CHECK(s.at("packets").get<int>() <= 1900);
  CHECK(s.at("rejected") == 0);
  CHECK(s.at("return_mode") == "last");
  CHECK(s.at("sequence_present") == true);
  // A packet the daemon did not record leaves a gap in the recording's sequence, and a frame it
  // dropped a hole in its revolutions: counted losses a sanitizer build on a busy machine may
  // have (kSlowBuild). Otherwise the recording is gapless and its frames whole.
  const bool lossless = not_recorded == 0 && frames_dropped == 0;
  if (lossless) CHECK(s.at("sequence_gaps") == 0);
  CHECK(s.at("rpm_min").get<int>() >= 1198);
  CHECK(s.at("rpm_max").get<int>() <= 1202);
  // About 1 s at 20 Hz: 20 revolutions, of which the first and last are partial (channels with
  // a positive azimuth offset crossed the cut before the stream began; channels with a negative
  // one have not reached it when the stream ends).
  // Starved, fewer revolutions were sent: 90 packets each.
  if (lossless)
    CHECK(s.at("frames_complete").get<int>() >= (test::kSlowBuild ? packets / 90 - 2 : 15));
  CHECK(s.at("frames_complete").get<int>() <= 20);
  if (lossless) CHECK(s.at("frames_complete") == counters.at("frames_complete"));
  for (const json& points : s.at("points_per_complete_frame")) {
    // 900 firing rounds per revolution at 1200 RPM, 40 channels, minus the doorway's no-returns.
    CHECK(points.get<int>() > 30000);
    CHECK(points.get<int>() <= 36000);
  }
}

TEST_CASE("bad command lines and bad files give clear errors and exit codes", "[cli][threads]") {
  const std::string inspect = test::quoted(test::binary("pandarcap-inspect"));
  const std::string daemon = test::quoted(test::binary("pandarcapd"));
  CHECK(test::run_command(inspect + " 2>/dev/null").exit_code == 64);
  CHECK(test::run_command(inspect + " --port 0 x.pcap 2>/dev/null").exit_code == 64);
  CHECK(test::run_command(inspect + " --bogus x.pcap 2>/dev/null").exit_code == 64);
  CHECK(test::run_command(daemon + " --bogus 2>/dev/null").exit_code == 64);
  CHECK(test::run_command(daemon + " --simulate --replay x.pcap 2>/dev/null").exit_code == 64);
  CHECK(test::run_command(daemon + " --simulate --rpm 700 2>/dev/null").exit_code == 64);
  const auto help = test::run_command(inspect + " --help");
  CHECK(help.exit_code == 0);
  CHECK(help.out.find("--calibration") != std::string::npos);

  const auto missing = test::run_command(inspect + " /nonexistent/file.pcap 2>&1");
  CHECK(missing.exit_code == 2);
  CHECK(missing.out.find("/nonexistent/file.pcap") != std::string::npos);

  test::ScratchDir dir("badcal");
  {
    std::ofstream bad(dir / "bad.csv");
    bad << "Laser id,Elevation,Azimuth\n1,15,-1.042\n2,eleven,-1.042\n";
  }
  const auto calibration = test::run_command(daemon + " --simulate --duration 1 --output-dir " +
                                             test::quoted(dir.path()) + " --calibration " +
                                             test::quoted(dir / "bad.csv") + " 2>&1");
  CHECK(calibration.exit_code == 78);
  CHECK(calibration.out.find("bad.csv:3:3: elevation is not a number") != std::string::npos);
}
