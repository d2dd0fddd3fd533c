// The real pandarcapd on the near end of a test's veth pair (support/veth_pair.hpp), reading the
// sensor at the far end's address with either receiver, and the root check the veth tests share.
#pragma once

#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <catch2/catch.hpp>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "bench/child_process.hpp"
#include "bench/udp_traffic.hpp"
#include "daemon/clocks.hpp"
#include "support/test_support.hpp"
#include "support/veth_pair.hpp"

namespace pandarcap::test {

// Making a veth pair takes CAP_NET_ADMIN. CI runs as root: there a test that cannot run is a
// failure, not a skip.
inline bool can_make_links() {
  if (::geteuid() == 0) return true;
  if (std::getenv("CI") != nullptr) FAIL("the veth tests need root (CAP_NET_ADMIN)");
  WARN("not root: the veth tests need CAP_NET_ADMIN for the veth pair: not run");
  return false;
}

struct VethDaemon {
  VethDaemon(const ScratchDir& dir, const VethPair& veth, std::uint16_t port,
             const std::string& extra_toml = "", const std::string& receiver = "packet_ring",
             const std::vector<std::string>& env = {})
      : out(dir / "out") {
    using namespace std::chrono_literals;
    const std::filesystem::path config = dir / "daemon.toml";
    std::ofstream(config) << "[sensor]\nsensor_ip = \"" << veth.far_ip() << "\"\n" << extra_toml;
    std::vector<std::string> args{"-c",         config.string(),      "--receiver",
                                  receiver,     "--interface",        veth.near(),
                                  "--port",     std::to_string(port), "--output-dir",
                                  out.string(), "--max-clock-offset", "0"};
    // The socket receiver needs no privilege, so as root (the tests' links need it) it must be
    // told that root is meant.
    if (receiver == "socket") args.emplace_back("--allow-root");
    process.emplace(binary("pandarcapd"), args, dir / "daemon.log", env);
    const bool ready = harness::wait_until(
        [&] { return process->log().find("ready:") != std::string::npos; }, 20s);
    INFO(process->log());
    REQUIRE(ready);
  }
  // Waits until `total` datagrams are received or dropped by the kernel, stops the daemon, and
  // returns its final health record.
  nlohmann::json stop_after(std::uint64_t total) {
    using namespace std::chrono_literals;
    wait_until_counted(out, total, 20s);
    return stop(SIGTERM);
  }
  // Waits until the loops' warm-up (kWarmUpNs, 2 s) is over, by the health's uptime: from then
  // on their allocations are counted.
  void wait_past_warm_up() {
    using namespace std::chrono_literals;
    REQUIRE(harness::wait_until(
        [&] {
          const auto records = health_records(out);
          return !records.empty() &&
                 records.back().at("gauges").at("uptime_seconds").get<double>() > 2.2;
        },
        10s));
  }
  // Sends `signal` now, waits for a clean exit, and returns the final health record.
  nlohmann::json stop(int signal) {
    using namespace std::chrono_literals;
    process->signal(signal);
    REQUIRE(process->wait_exit(30s) == 0);
    return last_health_record(out);
  }
  std::filesystem::path out;
  std::optional<harness::ChildProcess> process;
};

// The simulated sensor at the far end of `veth`, sending to the near end's `port` at 3600/s
// for `seconds`, `batch` datagrams a sendmmsg (1: evenly, as a sensor sends), on a thread of its
// own from the far end's namespace. sending() until it stops; then silent_from_ns() (Unix ns)
// is its last packet's moment, and after join() sent() what it sent.
class FarSensor {
 public:
  FarSensor(const VethPair& veth, std::uint16_t port, double seconds, int batch)
      : thread_([this, &veth, port, seconds, batch] {
          // What fails here (the namespace, the generator) is said by error(), not thrown out
          // of the thread, which would end the test binary without a report.
          try {
            FarNamespace far(veth.ns());
            bench::GeneratorOptions traffic;
            traffic.destination_ip = veth.near_ip();
            traffic.port = port;
            traffic.rate_pps = 3600;
            traffic.seconds = seconds;
            traffic.batch = batch;
            sent_ = bench::run_generator(bench::TrafficSource::synthetic(SyntheticSensorConfig{}),
                                         traffic);
          } catch (const std::exception& e) {
            error_ = e.what();
          }
          silent_from_ns_ = realtime_ns();
          sending_ = false;
        }) {}
  ~FarSensor() { join(); }
  FarSensor(const FarSensor&) = delete;
  FarSensor& operator=(const FarSensor&) = delete;
  void join() {
    if (thread_.joinable()) thread_.join();
  }
  bool sending() const noexcept { return sending_.load(); }
  std::int64_t silent_from_ns() const noexcept { return silent_from_ns_.load(); }
  const bench::GeneratorResult& sent() const noexcept { return sent_; }
  const std::string& error() const noexcept { return error_; }  // after join(): "" if it sent

 private:
  std::atomic<bool> sending_{true};
  std::atomic<std::int64_t> silent_from_ns_{0};
  bench::GeneratorResult sent_;
  std::string error_;
  std::thread thread_;  // last: it starts once the rest is made
};

}  // namespace pandarcap::test
