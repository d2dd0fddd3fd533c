// pandarcap-bench: the benchmark harness. One subcommand per thing measured; each prints a short
// table, or one JSON object with --json. Performance figures in the README come from here, never
// from timed unit tests.
#include <cstdio>
#include <string_view>

#include "bench/ring_bench.hpp"
#include "daemon/cli_args.hpp"

namespace {

constexpr std::string_view kUsage = R"(Usage: pandarcap-bench SUBCOMMAND [OPTIONS]

Subcommands:
  ring      SPSC packet ring (batches 1, 8, 32) and typed queue against a mutex + condition
            variable queue measured in the same run: items/s, round-trip latency, and the CPU
            an idle consumer uses at the sensor's packet rate.

Run 'pandarcap-bench SUBCOMMAND --help' for its options.
)";

constexpr std::string_view kRingUsage = R"(Usage: pandarcap-bench ring [OPTIONS]

Options:
  --json               print one JSON object instead of a table
  --items N            items per ring / typed-queue throughput run (default 20000000)
  --mutex-items N      items per mutex-queue run (default 2000000)
  --round-trips N      round trips per latency run (default 100000; mutex: a tenth)
  --repeat N           report the median of N runs of each measurement (default 3)
  --capacity N         slots per ring and queue, a power of two (default 1024)
  --idle-seconds S     length of the idle-CPU measurement (default 2)
  -h, --help           this text

JSON keys: packet_ring_items_per_s {"1","8","32"}, typed_queue_items_per_s,
mutex_queue_items_per_s, ratio_vs_mutex (packet ring at batch 32 / mutex),
ratio_vs_mutex_per_batch, typed_queue_ratio_vs_mutex, round_trip_ns, idle, order_errors, goals.
Exit status: 0, 1 if any item arrived out of order, 64 for a usage error.
)";

int run_ring(int argc, char** argv) {
  pandarcap::CliArgs args(argc, argv, kRingUsage);
  pandarcap::bench::RingBenchOptions options;
  bool json = false;
  while (args.more()) {
    const std::string_view arg = args.next();
    if (arg == "--json") {
      json = true;
    } else if (arg == "--items") {
      options.ring_items = static_cast<std::uint64_t>(args.integer(arg, 1000, 1'000'000'000'000));
    } else if (arg == "--mutex-items") {
      options.mutex_items = static_cast<std::uint64_t>(args.integer(arg, 1000, 1'000'000'000'000));
    } else if (arg == "--round-trips") {
      options.round_trips = static_cast<std::uint64_t>(args.integer(arg, 100, 1'000'000'000));
    } else if (arg == "--repeat") {
      options.repeat = static_cast<int>(args.integer(arg, 1, 100));
    } else if (arg == "--capacity") {
      const auto capacity = static_cast<std::size_t>(args.integer(arg, 32, 1 << 24));
      if ((capacity & (capacity - 1)) != 0) {
        args.usage_error("--capacity must be a power of two (and at least 32, the largest batch)");
      }
      options.capacity = capacity;
    } else if (arg == "--idle-seconds") {
      options.idle_seconds = args.number(arg, 0.1, 3600);
    } else {
      args.usage_error(fmt::format("unknown option '{}'", arg));
    }
  }
  const nlohmann::ordered_json report = pandarcap::bench::run_ring_bench(options);
  if (json) {
    std::puts(report.dump(2).c_str());
  } else {
    pandarcap::bench::print_ring_report(report);
  }
  return report["order_errors"].get<std::uint64_t>() == 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  pandarcap::CliArgs args(argc, argv, kUsage);
  if (!args.more()) args.usage_error("a subcommand is required (ring)");
  const std::string_view subcommand = args.next();
  // The subcommand parses the rest, with "pandarcap-bench SUBCOMMAND" as its program name.
  static char ring_name[] = "pandarcap-bench ring";
  if (subcommand == "ring") {
    argv[1] = ring_name;
    return run_ring(argc - 1, argv + 1);
  }
  args.usage_error(fmt::format("unknown subcommand '{}'", subcommand));
}
