#include "bench/send_command.hpp"

#include <fmt/format.h>

#include <cstdio>
#include <nlohmann/json.hpp>
#include <stdexcept>
#include <string>
#include <string_view>

#include "bench/traffic_options.hpp"
#include "bench/udp_traffic.hpp"
#include "core/sensors/sensor_model_id.hpp"
#include "daemon/cli_args.hpp"

namespace pandarcap::bench {

namespace {

constexpr std::string_view kSendUsageHead = R"(Usage: pandarcap-bench send [OPTIONS]

Sends a sensor's packets over UDP with sendmmsg, paced in batches against CLOCK_MONOTONIC, and
reports the rate actually achieved: the simulated sensor of any supported model (one continuous
rotation whose clock runs, looped every second), or a capture's Pandar40P packets. The
destination is 127.0.0.1 unless --destination names another address; nothing is ever sent
anywhere else.

Options:
  --json                 print one JSON object instead of a line of text
  --sensor-model MODEL   the simulated sensor's model, in any case: Pandar40P (default),
                         Pandar64, PandarXT32, PandarXT16 or PandarQT128
  --destination IP       IPv4 address to send to (default 127.0.0.1)
  --port N               UDP port (default 2368, the sensor's)
  --rate PPS             offered rate of valid packets (default: the model's own in its return
                         mode, e.g. a Pandar40P's 3600 in dual; a capture: 3600)
  --seconds S            how long to send (default 10)
  --batch N              datagrams per sendmmsg call (default 32)
  --no-sequence          the sensor's packets without the UDP sequence: a Pandar40P's 1262
                         bytes, a Pandar64's 1194, a PandarQT128's 1091 (default: with a 4-byte
                         sequence 0, 1, 2, ... written by the generator, so loss is exact:
                         1266, 1198, 1095 bytes). A PandarXT's packets always carry it (1080,
                         568 bytes)
  --first-sequence N     the first packet's sequence (default 0)
)";
constexpr std::string_view kSendUsageTail = R"(  -h, --help             this text

JSON keys: destination, port, sensor_model, traffic, packet_bytes, offered_pps, achieved_pps,
seconds, sent, first_sequence, last_sequence, foreign_sent, malformed_sent, duplicates_sent,
glitches_sent, send_errors, cpu_fraction_of_one_core.
Exit status: 0, 1 if the socket could not be used or a send failed (other than a full buffer,
which is waited out), 64 for a usage error.
)";

}  // namespace

int run_send(int argc, char** argv) {
  const std::string usage = fmt::format("{}{}{}", kSendUsageHead, kTrafficOptions, kSendUsageTail);
  CliArgs args(argc, argv, usage);
  GeneratorOptions options;
  SyntheticSensorConfig sensor;
  SensorModelId model = SensorModelId::kPandar40P;
  std::string capture;
  bool json = false, rate_given = false, model_given = false;
  while (args.more()) {
    const std::string_view arg = args.next();
    if (arg == "--json") {
      json = true;
    } else if (arg == "--sensor-model") {
      const std::string_view name = args.value(arg);
      const auto parsed = parse_sensor_model(name);
      if (!parsed) {
        args.usage_error(fmt::format(
            "--sensor-model is Pandar40P, Pandar64, PandarXT32, PandarXT16 or PandarQT128 (in "
            "any case), got '{}'",
            name));
      }
      model = *parsed;
      model_given = true;
    } else if (arg == "--destination") {
      options.destination_ip = std::string(args.value(arg));
    } else if (arg == "--port") {
      options.port = static_cast<std::uint16_t>(args.integer(arg, 1, 65535));
    } else if (arg == "--rate") {
      options.rate_pps = args.number(arg, 1, 1e8);
      rate_given = true;
    } else if (arg == "--seconds") {
      options.seconds = args.number(arg, 0.01, 86'400);
    } else if (arg == "--batch") {
      options.batch = static_cast<int>(args.integer(arg, 1, 1024));
    } else if (arg == "--no-sequence") {
      options.udp_sequence = false;
    } else if (arg == "--first-sequence") {
      options.first_sequence = static_cast<std::uint64_t>(args.integer(arg, 0, 0xFFFF'FFFF));
    } else if (parse_traffic_option(args, arg, options, sensor, capture)) {
    } else {
      args.unknown_option(arg);
    }
  }
  // Checked before sending, so that a request the generator would refuse is a usage error.
  if (const auto problem = generator_options_problem(options)) args.usage_error(*problem);
  if (const auto problem = sensor_problem(model, sensor)) args.usage_error(*problem);
  if (!capture.empty() && model_given && model != SensorModelId::kPandar40P) {
    args.usage_error(
        "--capture sends a capture's Pandar40P packets; --sensor-model chooses the "
        "simulated sensor's model");
  }
  if (!options.udp_sequence &&
      (model == SensorModelId::kPandarXT32 || model == SensorModelId::kPandarXT16)) {
    args.usage_error(fmt::format("--no-sequence: a {}'s packets always carry the UDP sequence",
                                 display_name(model)));
  }
  const auto report = [&]() -> std::optional<nlohmann::ordered_json> {
    try {
      const TrafficSource source =
          capture.empty() ? TrafficSource::synthetic_model(model, sensor.rpm, sensor.return_mode,
                                                           options.udp_sequence)
                          : TrafficSource::from_capture(capture);
      // The sensor's own rate unless told otherwise (a capture's: one dual-return 40P's).
      if (!rate_given && source.packets_per_second > 0) {
        options.rate_pps = source.packets_per_second;
      }
      const GeneratorResult r = run_generator(source, options);
      return nlohmann::ordered_json{
          {"destination", options.destination_ip},
          {"port", options.port},
          {"sensor_model", std::string(lower_case_name(source.model))},
          {"traffic", source.description},
          {"packet_bytes", source.datagram_bytes(options.udp_sequence)},
          {"offered_pps", options.rate_pps},
          {"achieved_pps", r.achieved_pps},
          {"seconds", r.seconds},
          {"sent", r.sent},
          {"first_sequence", options.first_sequence},
          {"last_sequence", r.sent > 0 ? nlohmann::ordered_json(options.first_sequence + r.sent - 1)
                                       : nlohmann::ordered_json(nullptr)},
          {"foreign_sent", r.foreign_sent},
          {"malformed_sent", r.malformed_sent},
          {"duplicates_sent", r.duplicates_sent},
          {"glitches_sent", r.glitches_sent},
          {"send_errors", r.send_errors},
          {"cpu_fraction_of_one_core", r.seconds > 0 ? r.cpu_seconds / r.seconds : 0.0}};
    } catch (const std::exception& e) {
      fmt::print(stderr, "pandarcap-bench send: {}\n", e.what());
      return std::nullopt;
    }
  }();
  if (!report) return 1;
  const nlohmann::ordered_json& r = *report;
  if (json) {
    std::puts(r.dump(2).c_str());
  } else {
    fmt::print(
        "sent {} packets ({} B, {}) to {}:{} in {:.2f} s: {:.1f} packets/s achieved of {:.1f} "
        "offered; {} foreign, {} malformed, {} send errors; generator CPU {:.1f} % of one core\n",
        r["sent"].get<std::uint64_t>(), r["packet_bytes"].get<std::size_t>(),
        r["traffic"].get<std::string>(), r["destination"].get<std::string>(), r["port"].get<int>(),
        r["seconds"].get<double>(), r["achieved_pps"].get<double>(), r["offered_pps"].get<double>(),
        r["foreign_sent"].get<std::uint64_t>(), r["malformed_sent"].get<std::uint64_t>(),
        r["send_errors"].get<std::uint64_t>(), 100 * r["cpu_fraction_of_one_core"].get<double>());
  }
  return r["send_errors"].get<std::uint64_t>() == 0 ? 0 : 1;
}

}  // namespace pandarcap::bench
