#include "bench/storage_bench.hpp"

#include <fmt/format.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <stdexcept>
#include <string_view>
#include <thread>
#include <vector>

#include "bench/child_process.hpp"
#include "bench/median.hpp"

namespace pandarcap::bench {
namespace {

namespace fs = std::filesystem;
using nlohmann::ordered_json;
using namespace std::chrono_literals;

struct Choice {
  const char* name;
  const char* toml;  // the [output] keys that make it
};

// The vehicle profile's outputs: what systemd/front.toml records (kept in step with it; the
// storage doc's table shows this row).
constexpr const char* kVehicleProfile =
    "pcap_compression = \"zstd\"\npcd_compression = \"lzf\"\nframe_decimation = 10\n";

constexpr Choice kChoices[] = {
    {"health only (reference)", "frames = false\npcap = false\n"},
    {"raw: pcap", "frames = false\n"},
    {"raw: pcap.zst (zstd 1)", "frames = false\npcap_compression = \"zstd\"\n"},
    {"raw: pcap.zst (zstd 3)",
     "frames = false\npcap_compression = \"zstd\"\npcap_compression_level = 3\n"},
    {"frames: PCD", "pcap = false\n"},
    {"frames: PCD lzf", "pcap = false\npcd_compression = \"lzf\"\n"},
    {"frames: PCD lzf, every 10th",
     "pcap = false\npcd_compression = \"lzf\"\nframe_decimation = 10\n"},
    {"MCAP (frames, zstd 1)", "frames = false\npcap = false\nmcap = true\n"},
    {"defaults: PCD + pcap", ""},
    {"vehicle profile: pcap.zst + PCD lzf every 10th", kVehicleProfile},
};
constexpr const char* kOutputs[] = {"frames", "raw", "mcap", "health"};

std::uint64_t bytes_under(const fs::path& dir) {
  std::uint64_t total = 0;
  std::error_code ec;
  for (const auto& entry : fs::recursive_directory_iterator(dir, ec)) {
    std::error_code size_ec;
    if (entry.is_regular_file(size_ec)) total += entry.file_size(size_ec);
  }
  return total;
}

// The newest health record's datagram count and time (0, 0 before the first).
struct Received {
  std::uint64_t datagrams = 0;
  std::int64_t unix_time_ns = 0;
};
Received datagrams_received(const fs::path& out) {
  std::ifstream in(out / "health" / "health.jsonl");
  std::string line, last;
  while (std::getline(in, line))
    if (!line.empty()) last = line;
  const auto record = nlohmann::json::parse(last, nullptr, false);
  if (record.is_discarded() || !record.contains("counters")) return {};
  return {record["counters"].value("datagrams_received", std::uint64_t{0}),
          record.value("unix_time_ns", std::int64_t{0})};
}

double cpu_seconds(const std::map<std::string, std::uint64_t>& before,
                   const std::map<std::string, std::uint64_t>& after, bool writer_only) {
  const double tick = static_cast<double>(::sysconf(_SC_CLK_TCK));
  double total = 0;
  for (const auto& [name, ticks] : after) {
    // The simulated sensor stands for the sensor: not the daemon's cost.
    if (name == "pc-simsensor" || (writer_only && name != "pc-writer")) continue;
    const auto start = before.count(name) ? before.at(name) : 0;
    total += static_cast<double>(ticks - start) / tick;
  }
  return total;
}

// One run of one configuration: what grew and what it cost over the window.
ordered_json run_once(const fs::path& daemon, const fs::path& dir, const Choice& choice,
                      double seconds) {
  fs::create_directories(dir);
  const fs::path out = dir / "out";
  const fs::path config = dir / "storage.toml";
  std::ofstream(config) << "[output]\n" << choice.toml;
  std::vector<std::string> args = {"-c", config.string(), "--simulate", "--output-dir",
                                   out.string()};
  if (::geteuid() == 0) args.insert(args.begin(), "--allow-root");
  harness::ChildProcess process(daemon, args, dir / "daemon.log");
  // Warmed up: the first health record is out (the first frames and files too).
  if (!harness::wait_until([&] { return datagrams_received(out).datagrams > 0; }, 20s)) {
    throw std::runtime_error("pandarcapd did not start recording:\n" + process.log());
  }
  std::map<std::string, std::uint64_t> bytes_before;
  for (const char* output : kOutputs)
    bytes_before[output] = bytes_under(out / output);
  const auto cpu_before = harness::thread_cpu_ticks(process.pid());
  const Received packets_before = datagrams_received(out);
  const auto start = std::chrono::steady_clock::now();
  // The measured window: the experiment's variable, not a wait for the daemon.
  std::this_thread::sleep_for(std::chrono::duration<double>(seconds));
  const auto cpu_after = harness::thread_cpu_ticks(process.pid());
  const double wall =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ordered_json per_output;
  double total = 0;
  for (const char* output : kOutputs) {
    const double grew =
        static_cast<double>(bytes_under(out / output)) - static_cast<double>(bytes_before[output]);
    per_output[output] = grew / wall / 1e6;
    total += grew;
  }
  const Received packets_after = datagrams_received(out);
  process.signal(SIGTERM);
  if (process.wait_exit(30s) != 0) {
    throw std::runtime_error("pandarcapd did not stop cleanly:\n" + process.log());
  }
  ordered_json row;
  // Between the two health records the window's ends saw (a record a second): their own times.
  const double between_s =
      static_cast<double>(packets_after.unix_time_ns - packets_before.unix_time_ns) / 1e9;
  row["packets_per_s"] =
      between_s > 0
          ? static_cast<double>(packets_after.datagrams - packets_before.datagrams) / between_s
          : 0.0;
  row["mb_per_s"] = total / wall / 1e6;
  row["mb_per_s_by_output"] = per_output;
  row["cpu_fraction_of_core"] = cpu_seconds(cpu_before, cpu_after, false) / wall;
  row["writer_cpu_fraction_of_core"] = cpu_seconds(cpu_before, cpu_after, true) / wall;
  return row;
}

}  // namespace

ordered_json run_storage_bench(const StorageBenchOptions& o) {
  const fs::path daemon =
      o.daemon.empty() ? harness::beside_this_binary("pandarcapd") : fs::path(o.daemon);
  const bool temporary = o.directory.empty();
  const fs::path work =
      temporary ? fs::temp_directory_path() / fmt::format("pandarcap-storage-{}", ::getpid())
                : fs::path(o.directory);
  std::vector<std::size_t> chosen;
  for (std::size_t i = 0; i < std::size(kChoices); ++i)
    if (i == 0 || std::string_view(kChoices[i].name).find(o.only) != std::string_view::npos)
      chosen.push_back(i);
  std::vector<std::vector<ordered_json>> runs(std::size(kChoices));
  for (int round = 0; round < o.rounds; ++round) {
    for (const std::size_t i : chosen) {
      const fs::path dir = work / fmt::format("round{}_{:02}", round, i);
      runs[i].push_back(run_once(daemon, dir, kChoices[i], o.seconds));
      std::error_code ec;
      fs::remove_all(dir / "out", ec);  // the next run has the disk (and page cache) to itself
    }
  }
  if (temporary) {
    std::error_code ec;
    fs::remove_all(work, ec);
  }
  ordered_json rows = ordered_json::array();
  double reference_cpu = 0;
  for (const std::size_t i : chosen) {
    const auto med = [&](const char* key) {
      std::vector<double> v;
      for (const auto& r : runs[i])
        v.push_back(r[key].get<double>());
      return median(v);
    };
    ordered_json row;
    row["name"] = kChoices[i].name;
    row["config"] = kChoices[i].toml;
    row["packets_per_s"] = med("packets_per_s");
    const double mb = med("mb_per_s");
    row["mb_per_s"] = mb;
    ordered_json by_output;
    for (const char* output : kOutputs) {
      std::vector<double> v;
      for (const auto& r : runs[i])
        v.push_back(r["mb_per_s_by_output"][output].get<double>());
      by_output[output] = median(v);
    }
    row["mb_per_s_by_output"] = by_output;
    row["gb_per_hour"] = mb * 3600 / 1000;
    row["hours_per_tb"] = mb > 0 ? 1e6 / mb / 3600 : 0.0;
    const double cpu = med("cpu_fraction_of_core");
    if (i == 0) reference_cpu = cpu;
    row["cpu_fraction_of_core"] = cpu;
    row["cpu_over_reference"] = cpu - reference_cpu;
    row["writer_cpu_fraction_of_core"] = med("writer_cpu_fraction_of_core");
    rows.push_back(row);
  }
  ordered_json report;
  report["seconds"] = o.seconds;
  report["rounds"] = o.rounds;
  report["rows"] = rows;
  report["method"] =
      "pandarcapd --simulate (3600 packets/s, dual return, 600 RPM) per configuration; bytes "
      "the output directories grew by over the window; CPU of every daemon thread but the "
      "simulated sensor's (/proc/PID/task/*/stat), in fractions of one core; medians over the "
      "rounds";
  return report;
}

void print_storage_report(const ordered_json& report) {
  std::printf(
      "| outputs | MB/s | GB/hour | hours per TB | CPU %% of a core | over health only | "
      "writer thread |\n|---|---|---|---|---|---|---|\n");
  for (const auto& row : report["rows"]) {
    std::printf("| %s | %.2f | %.1f | %.0f | %.1f | %+.1f | %.1f |\n",
                row["name"].get<std::string>().c_str(), row["mb_per_s"].get<double>(),
                row["gb_per_hour"].get<double>(), row["hours_per_tb"].get<double>(),
                100 * row["cpu_fraction_of_core"].get<double>(),
                100 * row["cpu_over_reference"].get<double>(),
                100 * row["writer_cpu_fraction_of_core"].get<double>());
  }
  std::printf("(%g s windows, %d round(s); packets/s measured: %.0f)\n",
              report["seconds"].get<double>(), report["rounds"].get<int>(),
              report["rows"][0]["packets_per_s"].get<double>());
}

}  // namespace pandarcap::bench
