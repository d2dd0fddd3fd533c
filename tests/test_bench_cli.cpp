// pandarcap-bench as a user runs it. Only the shape and the correctness of the report are checked
// here (every key the acceptance checks read, no item out of order, consistent ratios); the
// figures themselves are performance claims and belong to the README, not to a test.
#include <algorithm>
#include <catch2/catch.hpp>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>

#include "core/decoder_target.hpp"
#include "test_support.hpp"

using namespace pandarcap;
using nlohmann::json;

namespace {

std::string bench() {
  return "'" + test::binary("pandarcap-bench").string() + "'";
}

}  // namespace

TEST_CASE("pandarcap-bench ring --json reports every figure from one run", "[bench][cli]") {
  const auto result =
      test::run_command(bench() +
                        " ring --json --items 20000 --mutex-items 2000 --round-trips 200 --repeat 1"
                        " --idle-seconds 0.2");
  REQUIRE(result.exit_code == 0);
  const json report = json::parse(result.out);
  for (const char* batch : {"1", "8", "32"}) {
    INFO("batch " << batch);
    REQUIRE(report["packet_ring_items_per_s"].contains(batch));
    CHECK(report["packet_ring_items_per_s"][batch].get<double>() > 0);
    REQUIRE(report["round_trip_ns"]["packet_ring"].contains(batch));
  }
  const double mutex = report["mutex_queue_items_per_s"];
  CHECK(mutex > 0);
  CHECK(report["typed_queue_items_per_s"].get<double>() > 0);
  // The headline ratio is batch 32 over the baseline measured in the same run.
  CHECK(report["ratio_vs_mutex"].get<double>() ==
        Approx(report["packet_ring_items_per_s"]["32"].get<double>() / mutex));
  CHECK(report["order_errors"] == 0);
  // The idle consumer received every packet the paced producer sent.
  CHECK(report["idle"]["packets_received"] == report["idle"]["packets_sent"]);
  CHECK(report["idle"]["consumer_cpu_percent"].get<double>() >= 0);
}

TEST_CASE("pandarcap-bench rejects bad usage with status 64", "[bench][cli]") {
  CHECK(test::run_command(bench() + " 2>/dev/null").exit_code == 64);
  CHECK(test::run_command(bench() + " nonsense 2>/dev/null").exit_code == 64);
  CHECK(test::run_command(bench() + " ring --capacity 100 2>/dev/null").exit_code == 64);
  CHECK(test::run_command(bench() + " ring --items many 2>/dev/null").exit_code == 64);
  const auto help = test::run_command(bench() + " ring --help");
  CHECK(help.exit_code == 0);
  CHECK(help.out.find("ratio_vs_mutex") != std::string::npos);
}

TEST_CASE("pandarcap-bench decode --json: every supported target, ratios from one run",
          "[bench][cli][simd]") {
  const auto capture = test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  if (!capture) return;
  const auto result = test::run_command(bench() + " decode --json --seconds 0.02 --rounds 1" +
                                        " --capture '" + capture->string() + "'");
  REQUIRE(result.exit_code == 0);
  const json report = json::parse(result.out);
  CHECK(report["input"]["packets"] == 1439);
  CHECK(report["input"]["return_mode"] == "dual");
  const json& ran = report["targets_ran"];
  REQUIRE(ran.size() == supported_decoder_targets().size());
  const double scalar = report["scalar"]["packets_per_s"];
  REQUIRE(scalar > 0);
  double best = 0;
  std::string best_name;
  for (const auto& name : ran) {
    const json& t = report[name.get<std::string>()];
    INFO(name);
    REQUIRE(t.contains("packets_per_s"));
    REQUIRE(t.contains("points_per_s"));
    const double pps = t["packets_per_s"];
    // Every target decodes the same points, so points per packet agree across targets.
    CHECK(t["points_per_s"].get<double>() / pps ==
          Approx(report["scalar"]["points_per_s"].get<double>() / scalar).epsilon(1e-9));
    CHECK(t["vs_scalar"].get<double>() == Approx(pps / scalar));
    if (pps > best) {
      best = pps;
      best_name = name;
    }
  }
  CHECK(report["best_target"] == best_name);
  CHECK(report["best_vs_scalar"].get<double>() == Approx(best / scalar));

  // Fixed-work mode (for callgrind) reports the work, not a rate.
  const auto passes = test::run_command(bench() + " decode --json --passes 2 --target scalar" +
                                        " --capture '" + capture->string() + "'");
  REQUIRE(passes.exit_code == 0);
  CHECK(json::parse(passes.out)["scalar"]["packets_decoded"] == 2 * 1439);

  // A target this machine cannot run is a usage error, not a silent substitute.
  const auto bad = test::run_command(bench() + " decode --target neon 2>&1");
  const auto supported = supported_decoder_targets();
  if (std::find(supported.begin(), supported.end(), DecoderTarget::kNeon) == supported.end()) {
    CHECK(bad.exit_code == 64);
    CHECK(bad.out.find("decoder 'neon'") != std::string::npos);
  }
}

namespace {
std::string md_text(const std::filesystem::path& report_dir) {
  std::stringstream md;
  md << std::ifstream(report_dir / "summary.md").rdbuf();
  return md.str();
}
}  // namespace

TEST_CASE("pandarcap-bench zero-loss: a short smoke run of the whole harness", "[bench][cli]") {
  test::ScratchDir dir("zero-loss");
  const auto report_dir = dir / "report";
  const auto result = test::run_command(
      bench() + " zero-loss --json --trial-seconds 0.5 --min-rate 1000 --max-rate 3000 --steps 1" +
      " --sensor-rate 1800 --report-dir '" + report_dir.string() + "' 2>&1");
  INFO(result.out);
  REQUIRE(result.exit_code == 0);
  const json report = json::parse(result.out);
  for (const char* key : {"daemon_zero_loss_pps", "bare_recvmmsg_zero_loss_pps",
                          "recvfrom_zero_loss_pps", "daemon_vs_bare"}) {
    INFO(key);
    REQUIRE(report.contains(key));
  }
  // At 1000 packets/s every receiver takes everything, the daemon with all its outputs on.
  CHECK(report["daemon_zero_loss_pps"].get<double>() >= 900);
  CHECK(report["bare_recvmmsg_zero_loss_pps"].get<double>() >= 900);
  CHECK(report["recvfrom_zero_loss_pps"].get<double>() >= 900);
  CHECK(report["daemon_vs_bare"].get<double>() ==
        Approx(report["daemon_zero_loss_pps"].get<double>() /
               report["bare_recvmmsg_zero_loss_pps"].get<double>()));
  const json& first = report["trials"]["daemon"][0];
  CHECK(first["sent"].get<std::uint64_t>() == first["accepted"].get<std::uint64_t>());
  // The generator keeps its pace (within 10 %) at a low rate.
  CHECK(first["achieved_pps"].get<double>() == Approx(1000).epsilon(0.1));

  const json& s = report["at_sensor_rate"];
  for (const char* key :
       {"cpu_fraction_of_one_core", "latency_p99_us", "hot_path_allocations", "peak_rss_bytes"}) {
    INFO(key);
    REQUIRE(s.contains(key));
  }
  CHECK(s["lost"] == 0);
  CHECK(s["cpu_fraction_of_one_core"].get<double>() > 0);
  // The floor beside it: a bare receiver under the same traffic, measured in the same run.
  CHECK(s["bare_recvmmsg_cpu_fraction_of_one_core"].get<double>() > 0);
  CHECK_THAT(md_text(report_dir), Catch::Contains("The floor on this machine"));
  CHECK(s["latency_p99_us"].get<double>() > 0);
  CHECK(s["peak_rss_bytes"].get<std::uint64_t>() > (1u << 20));
  CHECK(report["environment"]["cores"].get<int>() >= 1);

  // The report directory: the same JSON, a Markdown summary and an SVG plot.
  CHECK(json::parse(std::ifstream(report_dir / "report.json")) == report);
  std::stringstream md, svg;
  md << std::ifstream(report_dir / "summary.md").rdbuf();
  svg << std::ifstream(report_dir / "plot.svg").rdbuf();
  CHECK_THAT(md.str(), Catch::Contains("zero-loss rate"));
  CHECK(svg.str().rfind("<svg ", 0) == 0);
  CHECK_THAT(svg.str(), Catch::Contains("</svg>") && Catch::Contains("<polyline"));
}

TEST_CASE("pandarcap-bench write --json: PCD and pcap rates from one run", "[bench][cli]") {
  const auto result = test::run_command(bench() + " write --json --frames 3 --packets 5000");
  REQUIRE(result.exit_code == 0);
  const json report = json::parse(result.out);
  CHECK(report["points_per_frame"].get<std::size_t>() > 50'000);  // one simulated revolution
  for (const char* key : {"pcd_encode", "pcd_encode_and_write", "pcap_write"}) {
    INFO(key);
    CHECK(report[key]["items_per_s"].get<double>() > 0);
    CHECK(report[key]["mb_per_s"].get<double>() > 0);
  }
  // The sensor's share follows from the rates: 10 frames/s and 3600 packets/s.
  CHECK(report["sensor_pcap_cpu_fraction"].get<double>() ==
        Approx(3600.0 / report["pcap_write"]["items_per_cpu_s"].get<double>()));
}
