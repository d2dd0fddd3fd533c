// pandarcap-bench as a user runs it. Only the shape and the correctness of the report are checked
// here (every key the acceptance checks read, no item out of order, consistent ratios); the
// figures themselves are performance claims and belong to the README, not to a test.
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>
#include <string>

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
