// The monitoring that ships with the package (systemd/monitoring/): the Grafana dashboard is
// well-formed for Grafana's importer, and every metric the dashboard and the alert rules query
// exists, by that name, in a .prom file pandarcapd really wrote. (The alert rules' behaviour is
// tested by promtool: ctest prometheus_alert_rules.)
#include <catch2/catch.hpp>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <regex>
#include <set>
#include <sstream>
#include <string>

#include "bench/child_process.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

const fs::path kMonitoring = fs::path(PANDARCAP_SOURCE_DIR) / "systemd" / "monitoring";

// Every metric name in a query text: pandarcap's and node_exporter's textfile mtime.
std::set<std::string> metrics_in(const std::string& text) {
  static const std::regex name(R"(\b(pandarcap_[a-z0-9_]+|node_textfile_mtime_seconds)\b)");
  std::set<std::string> names;
  for (auto it = std::sregex_iterator(text.begin(), text.end(), name); it != std::sregex_iterator();
       ++it)
    names.insert((*it)[1]);
  return names;
}

// The metric names a .prom file has samples for.
std::set<std::string> metrics_of_prom(const std::string& prom) {
  std::set<std::string> names;
  static const std::regex sample(R"(^(pandarcap_[a-z0-9_]+)[{ ])");
  std::istringstream lines(prom);
  for (std::string line; std::getline(lines, line);) {
    std::smatch m;
    if (std::regex_search(line, m, sample)) names.insert(m[1]);
  }
  return names;
}

}  // namespace

TEST_CASE("the Grafana dashboard imports: panels, targets, the sensor variable", "[monitoring]") {
  const json d = json::parse(harness::read_file(kMonitoring / "pandarcap-dashboard.json"));
  CHECK(d.at("uid") == "pandarcap");
  CHECK(d.at("schemaVersion").is_number_integer());
  const json& variables = d.at("templating").at("list");
  std::set<std::string> names;
  for (const json& v : variables)
    names.insert(v.at("name").get<std::string>());
  CHECK(names == std::set<std::string>{"datasource", "sensor"});
  const std::set<std::string> panel_types{"timeseries", "state-timeline", "heatmap", "stat"};
  std::set<int> ids;
  std::set<std::string> titles;
  REQUIRE(d.at("panels").size() >= 10);
  for (const json& p : d.at("panels")) {
    INFO(p.dump());
    CHECK(ids.insert(p.at("id").get<int>()).second);  // unique ids
    titles.insert(p.at("title").get<std::string>());
    CHECK(panel_types.count(p.at("type").get<std::string>()) == 1);
    const json& g = p.at("gridPos");
    CHECK(g.at("x").get<int>() + g.at("w").get<int>() <= 24);  // Grafana's 24-column grid
    REQUIRE_FALSE(p.at("targets").empty());
    for (const json& t : p.at("targets")) {
      const std::string expr = t.at("expr");
      CHECK_FALSE(metrics_in(expr).empty());
      // Every pandarcap query follows the sensor chosen at the top.
      if (expr.find("pandarcap_") != std::string::npos)
        CHECK(expr.find("sensor=~\"$sensor\"") != std::string::npos);
    }
  }
  // What the issue asked the dashboard to show.
  for (const char* title : {"Health state", "Packets per second", "Drops per stage", "Motor speed",
                            "Frame latency (receive to PCD in place)", "Upload behind"})
    CHECK(titles.count(title) == 1);
}

TEST_CASE("the dashboard's and the alert rules' metrics are in a real .prom file",
          "[monitoring][daemon][threads]") {
  test::ScratchDir dir("monitoring-metrics");
  // A simulated sensor answering PTC: the sensor's status gauges are in the file too; with
  // --upload, the upload backlog's.
  const auto r = test::run_command(test::pandarcapd_command() +
                                   " --simulate --duration 3 --status-interval 0.5 --upload "
                                   "--output-dir '" +
                                   (dir / "out").string() + "' 2>&1");
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  const std::set<std::string> exported =
      metrics_of_prom(harness::read_file(dir / "out" / "health" / "pandarcap.prom"));
  REQUIRE(exported.size() > 50);

  std::set<std::string> queried =
      metrics_in(harness::read_file(kMonitoring / "pandarcap-dashboard.json"));
  for (const std::string& m : metrics_in(harness::read_file(kMonitoring / "pandarcap-alerts.yml")))
    queried.insert(m);
  REQUIRE(queried.size() > 20);
  for (const std::string& metric : queried) {
    if (metric == "node_textfile_mtime_seconds") continue;  // node_exporter's own
    INFO(metric);
    CHECK(exported.count(metric) == 1);
  }
}
