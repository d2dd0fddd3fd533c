// pandarcap-bench: the benchmark harness. One subcommand per thing measured; each prints a short
// table, or one JSON object with --json. Performance figures in docs/performance.md come from here,
// never from timed unit tests.
#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <optional>
#include <stdexcept>
#include <string_view>

#include "bench/decode_bench.hpp"
#include "bench/ring_bench.hpp"
#include "bench/send_command.hpp"
#include "bench/storage_bench.hpp"
#include "bench/traffic_options.hpp"
#include "bench/write_bench.hpp"
#include "bench/zero_loss.hpp"
#include "bench/zero_loss_usage.hpp"
#include "core/ipv4.hpp"
#include "core/sensors/sensor_model_id.hpp"
#include "daemon/cli_args.hpp"

namespace {

constexpr std::string_view kUsage = R"(Usage: pandarcap-bench SUBCOMMAND [OPTIONS]

Subcommands:
  decode    packet decoding per core: the scalar reference and every SIMD target this machine
            runs (sse4, avx2, avx512, ...), on a capture or the simulated sensor looped in
            memory: packets/s, points/s and the ratio to scalar; with --sensor-model, the
            whole stream decoder of each model: packets/s and channel measurements/s.
  zero-loss the highest packet rate the real pandarcapd takes with zero loss (RFC 2544 style
            search), against a bare recvmmsg receiver and a recvfrom receiver searched the same
            way in the same run; the daemon's CPU, latency, RSS and allocations at one sensor's
            rate; a JSON report, a Markdown summary and an SVG plot.
  storage   what each choice of outputs (pcap, pcap.zst, PCD, PCD lzf, decimated, MCAP, the
            vehicle profile) costs the disk and the CPU at one sensor's rate, running the real
            pandarcapd: MB/s, GB/hour, hours per TB, % of a core.
  write     the writer's formats: PCD frames (encode, encode + LZF, encode + write) and pcap
            recording, in points/s, packets/s and MB/s, and what one sensor's stream costs of
            a core.
  ring      SPSC packet ring (batches 1, 8, 32) and typed queue against a mutex + condition
            variable queue measured in the same run: items/s, round-trip latency, and the CPU
            an idle consumer uses at the sensor's packet rate.
  send      the harness's traffic generator on its own: a sensor's packets (any supported model,
            --sensor-model) over UDP at a paced rate (sendmmsg), to 127.0.0.1 unless told
            otherwise, e.g. to drive a daemon or a vendor driver by hand; reports the rate
            actually achieved.

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

constexpr std::string_view kDecodeUsage = R"(Usage: pandarcap-bench decode [OPTIONS]

Options:
  --json               print one JSON object instead of a table
  --capture FILE       pcap/pcapng of Pandar40P packets to loop (default: one second of the
                       simulated sensor in dual return, 3600 packets)
  --calibration FILE   calibration CSV (default: the nominal table)
  --target NAME        measure only this target (repeatable): scalar, sse4, avx2, avx512, ...
                       (default: every target this CPU supports)
  --seconds S          CPU seconds per target per round (default 0.3)
  --rounds N           interleaved rounds; figures are medians (default 5)
  --passes N           no timing: decode the stream N times per target and report the work done
                       (for instruction counts; see bench/callgrind-decode)
  --sensor-model M     instead, the per-model rows: model M's whole stream decoder (validation,
                       packet time, outlier rule, decode with points, frames) on one second of
                       its simulated sensor in dual return at 600 RPM (repeatable; "all": every
                       model, in any case). The Pandar40P's at every --target, the others' scalar:
                       they have no SIMD kernels
  -h, --help           this text

JSON keys: input, one object per target that ran ("scalar", "sse4", "avx2", "avx512", ...) with
packets_per_s, points_per_s, ns_per_packet, channel_measurements_per_s, vs_scalar; targets_ran,
best_target, best_vs_scalar, auto_target, goals, method. With --sensor-model: input, models (one
object per row: sensor_model, target, packets_per_s, channel_measurements_per_s,
ns_per_measurement, ns_per_measurement_vs_pandar40p_scalar, points_per_s, sensor_fraction_of_core,
accepted, rejected, outliers, frames_complete, frames_dropped, points_dropped, ...), method.
Exit status: 0, 2 if the capture cannot be used, 64 for a usage error (or a target this CPU
cannot run).
)";

// Runs a benchmark; when it throws, says so as "pandarcap-bench SUBCOMMAND: what" and returns
// nothing.
template <typename Run>
std::optional<nlohmann::ordered_json> run_reporting_errors(std::string_view subcommand, Run&& run) {
  try {
    return run();
  } catch (const std::exception& e) {
    fmt::print(stderr, "pandarcap-bench {}: {}\n", subcommand, e.what());
    return std::nullopt;
  }
}

// Prints a report: one JSON object with --json, otherwise the subcommand's own rendering.
template <typename Print>
void print_report(const nlohmann::ordered_json& report, bool json, Print&& print) {
  if (json) {
    std::puts(report.dump(2).c_str());
  } else {
    print(report);
  }
}

// The path options together: --veth makes its own interface; --interface is a real one, for the
// packet_ring receiver (the socket receiver takes whatever reaches its address), fed by the
// generator sending to --destination.
void check_zero_loss_path(pandarcap::CliArgs& args, const pandarcap::bench::ZeroLossOptions& o) {
  const bool ring = o.receiver == "packet_ring" || o.compare_receivers;
  if (o.veth && !o.interface.empty()) {
    args.usage_error("--veth makes its own interface: it does not go with --interface");
  }
  if (o.veth && ::geteuid() != 0) {
    args.usage_error("--veth makes a veth pair and a network namespace: run it as root");
  }
  if (!o.interface.empty() && !ring) {
    args.usage_error(
        "--interface names the packet_ring receiver's interface: give --receiver packet_ring "
        "(or --compare-receivers)");
  }
  if (!o.interface.empty() && o.destination.empty()) {
    args.usage_error(
        "--interface needs --destination IP: the address the generator sends to, whose packets "
        "arrive on that interface");
  }
  if (o.traffic.foreign_fraction > 0 && (o.veth || !o.interface.empty())) {
    args.usage_error("--foreign-fraction sends from 127.0.0.2: loopback only");
  }
  if (!o.destination.empty() && o.interface.empty()) {
    args.usage_error("--destination goes with --interface (loopback and --veth set their own)");
  }
  if (!o.destination.empty() && !pandarcap::parse_ipv4_host_order(o.destination)) {
    args.usage_error(fmt::format("--destination is an IPv4 address, got '{}'", o.destination));
  }
}

int run_zero_loss(int argc, char** argv) {
  const std::string usage =
      fmt::format("{}{}{}", pandarcap::bench::kZeroLossUsageHead, pandarcap::bench::kTrafficOptions,
                  pandarcap::bench::kZeroLossUsageTail);
  pandarcap::CliArgs args(argc, argv, usage);
  pandarcap::bench::ZeroLossOptions options;
  bool json = false;
  std::string report_dir, from_report;
  while (args.more()) {
    const std::string_view arg = args.next();
    if (arg == "--json") {
      json = true;
    } else if (arg == "--report-dir") {
      report_dir = std::string(args.value(arg));
    } else if (arg == "--trial-seconds") {
      options.trial_seconds = args.number(arg, 0.2, 3600);
    } else if (arg == "--min-rate") {
      options.min_rate = args.number(arg, 1, 1e8);
    } else if (arg == "--max-rate") {
      options.max_rate = args.number(arg, 1, 1e8);
    } else if (arg == "--steps") {
      options.steps = static_cast<int>(args.integer(arg, 0, 30));
    } else if (arg == "--max-gap") {
      options.max_gap = args.number(arg, 0, 1000);
    } else if (arg == "--sensor-rate") {
      options.sensor_rate = args.number(arg, 1, 1e8);
    } else if (arg == "--daemon") {
      options.daemon = std::string(args.value(arg));
    } else if (arg == "--config") {
      options.daemon_config = std::string(args.value(arg));
    } else if (pandarcap::bench::parse_traffic_option(args, arg, options.traffic, options.sensor,
                                                      options.capture)) {
    } else if (arg == "--work-dir") {
      options.work_dir = std::string(args.value(arg));
    } else if (arg == "--daemon-only") {
      options.skip_references = true;
    } else if (arg == "--sensor-rate-only") {
      options.sensor_rate_only = true;
    } else if (arg == "--latency-budget-ms") {
      options.latency_budget_ms = static_cast<std::uint32_t>(args.integer(arg, 0, 1000));
    } else if (arg == "--compare-budget-0") {
      options.compare_budget_0 = true;
    } else if (arg == "--compare-mcap") {
      options.compare_mcap = true;
    } else if (arg == "--sensor-rate-rounds") {
      options.sensor_rate_rounds = static_cast<int>(args.integer(arg, 1, 9));
      // An even count has two middle rounds, and either would flatter or blame one of them.
      if (options.sensor_rate_rounds % 2 == 0) {
        args.usage_error(
            "--sensor-rate-rounds: an odd number (1, 3, 5, 7 or 9), so that one "
            "round is the median");
      }
    } else if (arg == "--compare-tcpdump") {
      options.tcpdump_rounds = static_cast<int>(args.integer(arg, 1, 100));
    } else if (arg == "--receiver-command") {
      options.receiver_command = std::string(args.value(arg));
    } else if (arg == "--receiver-port") {
      options.receiver_port = static_cast<std::uint16_t>(args.integer(arg, 1, 65535));
    } else if (arg == "--from-report") {
      from_report = std::string(args.value(arg));
    } else if (arg == "--receiver") {
      options.receiver = std::string(args.value(arg));
      if (options.receiver != "socket" && options.receiver != "packet_ring") {
        args.usage_error(
            fmt::format("--receiver is socket or packet_ring, got '{}'", options.receiver));
      }
    } else if (arg == "--compare-receivers") {
      options.compare_receivers = true;
    } else if (arg == "--veth") {
      options.veth = true;
    } else if (arg == "--interface") {
      options.interface = std::string(args.value(arg));
    } else if (arg == "--destination") {
      options.destination = std::string(args.value(arg));
    } else {
      args.unknown_option(arg);
    }
  }
  if (options.max_rate < options.min_rate) args.usage_error("--max-rate is below --min-rate");
  check_zero_loss_path(args, options);
  // The daemon it measures is configured for a Pandar40P.
  if (const auto problem =
          pandarcap::bench::sensor_problem(pandarcap::SensorModelId::kPandar40P, options.sensor)) {
    args.usage_error(*problem);
  }
  if (options.receiver_command.empty() != (options.receiver_port == 0)) {
    args.usage_error("--receiver-command and --receiver-port go together");
  }
  const auto result = run_reporting_errors("zero-loss", [&] {
    if (from_report.empty()) return pandarcap::bench::run_zero_loss(options);
    std::ifstream saved(from_report);
    if (!saved) throw std::runtime_error(fmt::format("cannot read '{}'", from_report));
    try {
      return nlohmann::ordered_json::parse(saved);
    } catch (const nlohmann::ordered_json::parse_error& e) {
      throw std::runtime_error(fmt::format("'{}' is not JSON: {}", from_report, e.what()));
    }
  });
  if (!result) return 1;
  const nlohmann::ordered_json& report = *result;
  // Rendered once each, before anything is written: a saved report without a key the renderers
  // read (one written by an older pandarcap-bench, or edited) is an error naming the file.
  std::string markdown, svg;
  try {
    markdown = pandarcap::bench::zero_loss_markdown(report);
    svg = pandarcap::bench::zero_loss_svg(report);
  } catch (const nlohmann::ordered_json::exception& e) {
    const std::string source = from_report.empty() ? "this run's report" : "'" + from_report + "'";
    fmt::print(stderr,
               "pandarcap-bench zero-loss: {} is not a zero-loss report this version can render: "
               "{}\n",
               source, e.what());
    return 1;
  }
  if (!report_dir.empty()) {
    std::filesystem::create_directories(report_dir);
    std::ofstream(std::filesystem::path(report_dir) / "report.json") << report.dump(2) << "\n";
    std::ofstream(std::filesystem::path(report_dir) / "summary.md") << markdown;
    std::ofstream(std::filesystem::path(report_dir) / "plot.svg") << svg;
  }
  print_report(report, json,
               [&](const nlohmann::ordered_json&) { std::fputs(markdown.c_str(), stdout); });
  return 0;
}

constexpr std::string_view kWriteUsage = R"(Usage: pandarcap-bench write [OPTIONS]

Options:
  --json               print one JSON object instead of a table
  --frames N           PCD frames to write (default 50; one simulated revolution each)
  --packets N          pcap records to write (default 200000)
  --dir DIR            write the files there (default: a temporary directory, removed)
  -h, --help           this text

JSON keys: points_per_frame, pcd_encode, pcd_encode_and_write, pcd_encode_lzf (encoded and
compressed as DATA binary_compressed, not written), pcap_write (each with items_per_s, mb_per_s
(uncompressed), items_per_cpu_s, cpu_fraction_of_wall), pcd_lzf_size_ratio,
pcd_cpu_us_per_frame {binary, lzf}, sensor_pcd_cpu_fraction, sensor_pcap_cpu_fraction, method.
)";

int run_write(int argc, char** argv) {
  pandarcap::CliArgs args(argc, argv, kWriteUsage);
  pandarcap::bench::WriteBenchOptions options;
  bool json = false;
  while (args.more()) {
    const std::string_view arg = args.next();
    if (arg == "--json") {
      json = true;
    } else if (arg == "--frames") {
      options.frames = static_cast<int>(args.integer(arg, 1, 100'000));
    } else if (arg == "--packets") {
      options.packets = static_cast<int>(args.integer(arg, 1, 100'000'000));
    } else if (arg == "--dir") {
      options.directory = std::string(args.value(arg));
    } else {
      args.unknown_option(arg);
    }
  }
  const auto report =
      run_reporting_errors("write", [&] { return pandarcap::bench::run_write_bench(options); });
  if (!report) return 1;
  print_report(*report, json, pandarcap::bench::print_write_report);
  return 0;
}

int run_storage(int argc, char** argv) {
  pandarcap::CliArgs args(argc, argv, pandarcap::bench::kStorageUsage);
  pandarcap::bench::StorageBenchOptions options;
  bool json = false;
  while (args.more()) {
    const std::string_view arg = args.next();
    if (arg == "--json") {
      json = true;
    } else if (arg == "--seconds") {
      options.seconds = args.number(arg, 1, 3600);
    } else if (arg == "--rounds") {
      options.rounds = static_cast<int>(args.integer(arg, 1, 100));
    } else if (arg == "--dir") {
      options.directory = std::string(args.value(arg));
    } else if (arg == "--daemon") {
      options.daemon = std::string(args.value(arg));
    } else if (arg == "--only") {
      options.only = std::string(args.value(arg));
    } else {
      args.unknown_option(arg);
    }
  }
  const auto report =
      run_reporting_errors("storage", [&] { return pandarcap::bench::run_storage_bench(options); });
  if (!report) return 1;
  print_report(*report, json, pandarcap::bench::print_storage_report);
  return 0;
}

int run_decode(int argc, char** argv) {
  pandarcap::CliArgs args(argc, argv, kDecodeUsage);
  pandarcap::bench::DecodeBenchOptions options;
  bool json = false;
  while (args.more()) {
    const std::string_view arg = args.next();
    if (arg == "--json") {
      json = true;
    } else if (arg == "--capture") {
      options.capture = std::string(args.value(arg));
    } else if (arg == "--calibration") {
      options.calibration = std::string(args.value(arg));
    } else if (arg == "--target") {
      const pandarcap::DecoderChoice choice = pandarcap::choose_decoder_target(args.value(arg));
      if (!choice.target) args.usage_error(choice.error);
      options.targets.push_back(*choice.target);
    } else if (arg == "--seconds") {
      options.seconds = args.number(arg, 0.001, 3600);
    } else if (arg == "--rounds") {
      options.rounds = static_cast<int>(args.integer(arg, 1, 1000));
    } else if (arg == "--passes") {
      options.passes = static_cast<int>(args.integer(arg, 1, 1'000'000));
    } else if (arg == "--sensor-model") {
      const std::string_view name = args.value(arg);
      const auto model = pandarcap::parse_sensor_model(name);
      if (name == "all" || name == "ALL") {
        options.models.assign(pandarcap::kSensorModelIds.begin(), pandarcap::kSensorModelIds.end());
      } else if (!model) {
        args.usage_error(fmt::format(
            "--sensor-model is Pandar40P, Pandar64, PandarXT32, PandarXT16, PandarQT128 (in any "
            "case) or all, got '{}'",
            name));
      } else if (std::find(options.models.begin(), options.models.end(), *model) ==
                 options.models.end()) {
        options.models.push_back(*model);
      }
    } else {
      args.unknown_option(arg);
    }
  }
  if (!options.models.empty() &&
      (!options.capture.empty() || !options.calibration.empty() || options.passes)) {
    args.usage_error(
        "--sensor-model decodes each model's simulated sensor with its nominal table, timed: "
        "--capture, --calibration and --passes go with the Pandar40P's target rows");
  }
  const auto report =
      run_reporting_errors("decode", [&] { return pandarcap::bench::run_decode_bench(options); });
  if (!report) return 2;
  print_report(*report, json, pandarcap::bench::print_decode_report);
  return 0;
}

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
      args.unknown_option(arg);
    }
  }
  const nlohmann::ordered_json report = pandarcap::bench::run_ring_bench(options);
  print_report(report, json, pandarcap::bench::print_ring_report);
  return report["order_errors"].get<std::uint64_t>() == 0 ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  pandarcap::CliArgs args(argc, argv, kUsage);
  if (!args.more()) {
    args.usage_error("a subcommand is required (decode, ring, send, storage, write, zero-loss)");
  }
  const std::string_view subcommand = args.next();
  // The subcommand parses the rest, with "pandarcap-bench SUBCOMMAND" as its program name.
  static char ring_name[] = "pandarcap-bench ring";
  static char decode_name[] = "pandarcap-bench decode";
  static char zero_loss_name[] = "pandarcap-bench zero-loss";
  static char write_name[] = "pandarcap-bench write";
  static char send_name[] = "pandarcap-bench send";
  static char storage_name[] = "pandarcap-bench storage";
  if (subcommand == "storage") {
    argv[1] = storage_name;
    return run_storage(argc - 1, argv + 1);
  }
  if (subcommand == "send") {
    argv[1] = send_name;
    return pandarcap::bench::run_send(argc - 1, argv + 1);
  }
  if (subcommand == "write") {
    argv[1] = write_name;
    return run_write(argc - 1, argv + 1);
  }
  if (subcommand == "zero-loss") {
    argv[1] = zero_loss_name;
    return run_zero_loss(argc - 1, argv + 1);
  }
  if (subcommand == "decode") {
    argv[1] = decode_name;
    return run_decode(argc - 1, argv + 1);
  }
  if (subcommand == "ring") {
    argv[1] = ring_name;
    return run_ring(argc - 1, argv + 1);
  }
  args.usage_error(fmt::format("unknown subcommand '{}'", subcommand));
}
