// pandarcapd as the live-traffic tests run it: on 127.0.0.1:port, taking packets only from
// 127.0.0.1, outputs in a scratch directory; the simulated sensor's stream sent to it by the
// harness's paced generator; stopped once it has counted everything.
#pragma once

#include <signal.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "bench/child_process.hpp"
#include "bench/udp_traffic.hpp"
#include "support/test_support.hpp"

namespace pandarcap::test {

// The daemon on 127.0.0.1:port taking packets only from 127.0.0.1, with `extra` TOML (keys of
// [sensor] first, then any other tables), and `args` added to its command line.
struct LiveDaemon {
  LiveDaemon(const ScratchDir& dir, const std::string& extra,
             const std::vector<std::string>& args = {})
      : out(dir / "out"), port(harness::free_udp_port()) {
    const std::filesystem::path config = dir / "daemon.toml";
    std::ofstream(config) << "[sensor]\nhost_ip = \"127.0.0.1\"\nsensor_ip = \"127.0.0.1\"\n"
                          << "data_port = " << port << "\n"
                          << extra;
    // The generator loops one second of the simulated stream, its clock fixed at 2026-11-22:
    // that is no sensor clock to judge, so the clock-offset check is off.
    std::vector<std::string> all{
        "--allow-root",       "-c", config.string(), "--output-dir", out.string(),
        "--max-clock-offset", "0"};
    all.insert(all.end(), args.begin(), args.end());
    process.emplace(binary("pandarcapd"), all, dir / "log.txt");
  }
  bool ready() const {
    return harness::wait_until([&] { return process->log().find("ready:") != std::string::npos; },
                               std::chrono::seconds(20));
  }
  // Sends the simulated sensor's stream (dual return) to the daemon as `traffic` says, then ends
  // it with 0.2 s more at a gentle `tail_pps` (1000 packets/s), continuing its sequence, so that
  // its last packet certainly arrives and the sequence tracker sees every gap (a loss at the very
  // end of a stream is invisible to sequence numbers). `sent` counts the tail's packets too.
  bench::GeneratorResult send(bench::GeneratorOptions traffic, double tail_pps = 1000) {
    const auto source = bench::TrafficSource::synthetic(SyntheticSensorConfig{});
    traffic.port = port;
    bench::GeneratorResult sent = bench::run_generator(source, traffic);
    REQUIRE(sent.send_errors == 0);
    bench::GeneratorOptions tail;
    tail.port = port;
    tail.rate_pps = tail_pps;
    tail.seconds = 0.2;
    tail.first_sequence = sent.sent;
    sent.sent += bench::run_generator(source, tail).sent;
    return sent;
  }
  // Waits until the daemon has seen or counted as dropped `total` datagrams, then stops it and
  // returns the final health record.
  nlohmann::json stop_after(std::uint64_t total) {
    wait_until_counted(out, total, std::chrono::seconds(15));
    process->signal(SIGTERM);
    exit_status = process->wait_exit(std::chrono::seconds(30));
    return last_health_record(out);
  }

  std::filesystem::path out;
  std::uint16_t port;
  std::optional<harness::ChildProcess> process;
  std::optional<int> exit_status;
};

}  // namespace pandarcap::test
