#include "daemon/pandarcapd_command_line.hpp"

#include "config/command_line.hpp"
#include "core/sensors/packet.hpp"
#include "daemon/cli_args.hpp"
#include "daemon/pandarcapd_usage.hpp"

namespace pandarcap {

CommandLine parse_command_line(int argc, char** argv) {
  CliArgs args(argc, argv, kPandarcapdUsage);
  CommandLine o;
  bool simulate = false;
  std::optional<std::string> replay;
  while (args.more()) {
    const std::string_view arg = args.next();
    if (arg == "-c" || arg == "--config") {
      o.config_path = std::string(args.value(arg));
    } else if (arg == "--check-config") {
      o.check_config = true;
    } else if (arg == "--print-config") {
      o.print_config = true;
    } else if (arg == "--print-calibration") {
      o.print_calibration = true;
    } else if (arg == "--simulate") {
      simulate = true;
    } else if (arg == "--allow-root") {
      o.allow_root = true;
    } else if (arg == "--replay") {
      replay = std::string(args.value(arg));
    } else if (arg == "--top-speed") {
      o.source.rate.reset();
    } else if (arg == "--rate") {
      o.source.rate = args.number(arg, 0.001, 1000);
    } else if (arg == "--duration") {
      o.duration_s = args.number(arg, 0.1, 1e7);
    } else if (arg == "--udp-sequence") {
      o.source.simulated_udp_sequence = true;
    } else if (arg == "--mcap-only") {
      // Conversion: the frames (and packets, with output.mcap_packets) go to MCAP only.
      o.overrides.emplace_back("output.mcap", "true");
      o.overrides.emplace_back("output.frames", "false");
      o.overrides.emplace_back("output.pcap", "false");
    } else if (arg == "--foxglove-port") {
      // The live view on, at this port (live.port's range).
      const std::string text(args.value(arg));
      if (const auto problem = key_option_problem(KeyOption{arg, "live.port"}, text)) {
        args.usage_error(*problem);
      }
      o.overrides.emplace_back("live.foxglove", "true");
      o.overrides.emplace_back("live.port", text);
    } else if (const KeyOption* key = find_key_option(arg)) {
      // A configuration key: its type and range are the file's (config/command_line.hpp).
      const std::string text(key->flag ? "true" : args.value(arg));
      if (const auto problem = key_option_problem(*key, text)) args.usage_error(*problem);
      if (arg == "--port") o.source.port_given = true;
      if (arg == "--ptc-port") o.source.ptc_port_given = true;
      if (arg == "--rpm") {
        // Also the simulated sensor's speed; a Pandar40P turns at one of two.
        o.source.simulated_rpm = std::stoi(text);
        if (o.source.simulated_rpm != 600 && o.source.simulated_rpm != 1200) {
          args.usage_error("--rpm takes 600 or 1200");
        }
      }
      if (arg == "--return-mode") {
        // Also the simulated sensor's mode, which must be one a sensor sends ("any" is not).
        const auto mode = return_mode_from_string(text);
        if (!mode || !mode_listed(kPandar40PReturnModes, *mode))
          args.usage_error("--return-mode takes dual, strongest or last");
        o.source.simulated_mode = *mode;
      }
      o.overrides.emplace_back(key->key, text);
    } else {
      args.unknown_option(arg);
    }
  }
  if (simulate && replay) args.usage_error("--simulate and --replay exclude each other");
  if (o.source.rate && !replay) args.usage_error("--rate applies to --replay only");
  if (simulate) o.source.kind = RunSource::Kind::kSimulated;
  if (replay) {
    o.source.kind = RunSource::Kind::kReplay;
    o.source.replay_path = *replay;
  }
  return o;
}

}  // namespace pandarcap
