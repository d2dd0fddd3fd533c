// pandarcap-bench storage as a user runs it: the shape of the report and the relations that must
// hold whatever the machine (a compressed recording is smaller than the pcap; the reference
// writes no data). The figures themselves belong to docs/storage.md.
#include <catch2/catch.hpp>
#include <nlohmann/json.hpp>
#include <string>

#include "support/test_support.hpp"

using namespace pandarcap;
using nlohmann::json;

TEST_CASE("pandarcap-bench storage --json: rows from the real daemon, compressed raw smaller",
          "[bench][cli][zstd][threads]") {
  const auto result = test::run_command("'" + test::binary("pandarcap-bench").string() +
                                        "' storage --json --seconds 1.5 --only 'raw:' 2>&1");
  INFO(result.out);
  REQUIRE(result.exit_code == 0);
  const json report = json::parse(result.out);
  const json& rows = report.at("rows");
  REQUIRE(rows.size() == 4);  // the reference and the three raw choices
  CHECK(rows[0].at("name") == "health only (reference)");
  CHECK(rows[0].at("cpu_over_reference").get<double>() == 0);
  double cpu_sum = 0;
  for (const json& row : rows) {
    INFO(row.dump());
    // The simulated sensor's rate reached the daemon.
    CHECK(row.at("packets_per_s").get<double>() > 1000);
    // Measured in 10 ms ticks, 1.5 s a row: a row that decodes no points (frames off) may take
    // less than one tick; the rows together cannot (checked after the loop).
    CHECK(row.at("cpu_fraction_of_core").get<double>() >= 0);
    cpu_sum += row.at("cpu_fraction_of_core").get<double>();
    for (const char* key :
         {"mb_per_s", "gb_per_hour", "hours_per_tb", "writer_cpu_fraction_of_core"})
      CHECK(row.contains(key));
    CHECK(row.at("gb_per_hour").get<double>() == Approx(row.at("mb_per_s").get<double>() * 3.6));
  }
  CHECK(cpu_sum > 0);
  const double pcap = rows[1].at("mb_per_s_by_output").at("raw").get<double>();
  const double zst = rows[2].at("mb_per_s_by_output").at("raw").get<double>();
  CHECK(rows[1].at("name") == "raw: pcap");
  CHECK(pcap > 3.0);  // ~4.7 MB/s of pcap at 3600 packets/s
  CHECK(zst < pcap / 2);
  CHECK(rows[0].at("mb_per_s_by_output").at("raw").get<double>() == 0);
}
