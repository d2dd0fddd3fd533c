// The traffic options `pandarcap-bench zero-loss` and `send` share: what to send (a capture or
// the simulated sensor at a speed and return mode) and the faults mixed in.
#pragma once

#include <optional>
#include <string>
#include <string_view>

#include "bench/udp_traffic.hpp"
#include "core/sensors/sensor_model_id.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "daemon/cli_args.hpp"

namespace pandarcap::bench {

// The options below, in both usage texts.
inline constexpr std::string_view kTrafficOptions =
    R"(  --capture FILE         send this capture's packets (default: the simulated sensor)
  --rpm N                the simulated sensor's spin rate: 600 or 1200 (default 600)
  --return-mode MODE     the simulated sensor's return mode: dual, or single (= strongest),
                         strongest or last; the XT32, XT16 and QT128 also first, first_last,
                         first_strongest (default dual). A Pandar40P sends 3600 packets/s in
                         dual, 1800 in a single mode
  --burst-factor X       bursts at X times the rate ...
  --burst-ms M           ... lasting M ms ...
  --burst-every S        ... every S seconds (default 1)
  --foreign-fraction F   also send F x the valid packets from 127.0.0.2 (a daemon drops them as
                         foreign when its config sets sensor_ip); 127.x.x.x destinations only
  --malformed-fraction F also send F x the valid packets as random-length random bytes
  --duplicate-fraction F also send a copy of F x the valid packets, right after them (a switch
                         loop; a daemon counts duplicate_packets)
  --glitch-fraction F    give F x the valid packets a tail time minutes off (an isolated clock
                         glitch; a daemon counts outlier_packets)
  --clock-start T        the first packet's sensor time, Unix seconds (default: now). Every
                         packet carries its own time from there: the stream's clock runs
)";

// Parses one of the options above. Returns false when `arg` is not one of them. The speed and
// the return mode are checked against the model afterwards (sensor_problem()): the model may
// come later on the command line.
bool parse_traffic_option(CliArgs& args, std::string_view arg, GeneratorOptions& traffic,
                          SyntheticSensorConfig& sensor, std::string& capture);

// Why the simulated `model` cannot run at `sensor`'s speed and return mode (its kSupportedRpms,
// kReturnModes), or nothing when it can.
std::optional<std::string> sensor_problem(SensorModelId model, const SyntheticSensorConfig& sensor);

}  // namespace pandarcap::bench
