// Privileges: pandarcapd captures as an unprivileged user holding no capability, and refuses to
// run as root unless told to (--allow-root). Real binary, real loopback socket.
//
// The tests work whoever runs them: as root (CI) the unprivileged run drops to uid/gid 65534
// (nobody) through setpriv; as an ordinary user the root run happens in a user namespace where
// that user is uid 0 (unshare --map-root-user), which is what pandarcapd's check sees.
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <catch2/catch.hpp>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "bench/child_process.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace std::chrono_literals;
namespace fs = std::filesystem;

namespace {

// The value of `field` ("CapEff", "Uid", ...) in /proc/PID/status, "" if absent.
std::string status_field(int pid, const std::string& field) {
  std::istringstream in(harness::read_file("/proc/" + std::to_string(pid) + "/status"));
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind(field + ":", 0) == 0) {
      const auto value = line.find_first_not_of(" \t", field.size() + 1);
      return value == std::string::npos ? "" : line.substr(value);
    }
  }
  return "";
}

}  // namespace

TEST_CASE("as root without --allow-root: refused with 77 before any socket or file",
          "[daemon][privileges][threads]") {
  test::ScratchDir dir("privileges-root");
  const fs::path out = dir / "out";
  const std::string daemon = test::binary("pandarcapd").string();
  const std::string as_root = ::geteuid() == 0 ? "" : "unshare --user --map-root-user ";
  if (!as_root.empty() && test::run_command(as_root + "true").exit_code != 0) {
    WARN("cannot become uid 0 here (no root, user namespaces disabled): not tested");
    return;
  }
  const auto refused = test::run_command(
      as_root + daemon + " --simulate --duration 1 --output-dir '" + out.string() + "' 2>&1");
  INFO(refused.out);
  CHECK(refused.exit_code == 77);
  CHECK(refused.out.find("refusing to run as root") != std::string::npos);
  CHECK(refused.out.find("--allow-root") != std::string::npos);
  CHECK_FALSE(fs::exists(out));  // nothing was created

  // Told to, it runs (and says so).
  const auto allowed =
      test::run_command(as_root + daemon + " --allow-root --simulate --duration 1 --output-dir '" +
                        out.string() + "' 2>&1");
  INFO(allowed.out);
  CHECK(allowed.exit_code == 0);
  CHECK(allowed.out.find("running as root (--allow-root)") != std::string::npos);
  CHECK(fs::exists(out / "health" / "health.jsonl"));
  // Configuration checks need no privilege and are not refused.
  CHECK(test::run_command(as_root + daemon + " --check-config").exit_code == 0);

  // The packet ring needs CAP_NET_RAW, which root has (a user namespace's root has not, for the
  // host's interfaces): live or simulated over lo, it runs as root without --allow-root, and
  // says so; a replay of a file is refused as any other run.
  if (::geteuid() == 0) {
    const auto ring = test::run_command(
        daemon + " --simulate --receiver packet_ring --interface lo --duration 1 --output-dir '" +
        (dir / "ring").string() + "' 2>&1");
    INFO(ring.out);
    CHECK(ring.exit_code == 0);
    CHECK(ring.out.find("running as root for input.receiver = \"packet_ring\"") !=
          std::string::npos);
    const auto replay = test::run_command(
        daemon + " --receiver packet_ring --interface lo --replay '" +
        (fs::path(PANDARCAP_SOURCE_DIR) / "tests" / "data" / "none.pcap").string() +
        "' --output-dir '" + (dir / "replay").string() + "' 2>&1");
    INFO(replay.out);
    CHECK(replay.exit_code == 77);
    CHECK(replay.out.find("refusing to run as root") != std::string::npos);
  }
}

TEST_CASE("an unprivileged user captures with no capability (CapEff 0)",
          "[daemon][privileges][threads]") {
  test::ScratchDir dir("privileges-user");
  const fs::path out = dir / "out";
  std::vector<std::string> args = {"--simulate", "--output-dir", out.string()};
  fs::path program = test::binary("pandarcapd");
  if (::geteuid() == 0) {
    // Drop to nobody the way a service manager does: uid, gid and groups, so the kernel clears
    // the permitted and effective sets. The scratch directory must be its.
    REQUIRE(::chown(dir.path().c_str(), 65534, 65534) == 0);
    args.insert(args.begin(),
                {"--reuid=65534", "--regid=65534", "--clear-groups", "--", program.string()});
    program = "/usr/bin/setpriv";
  }
  harness::ChildProcess daemon(program, args, dir / "log.txt");
  // Capturing: packets from the simulated sensor arrive over its UDP socket.
  const bool receiving = harness::wait_until(
      [&] {
        const nlohmann::json last = test::last_health_record(out);
        return !last.is_null() && test::health_counter(last, "packets_accepted") > 0;
      },
      15s);
  INFO(daemon.log());
  REQUIRE(receiving);
  // Real, effective, saved and file-system uid: none is root.
  std::istringstream uids(status_field(daemon.pid(), "Uid"));
  int uid = -1, count = 0;
  while (uids >> uid) {
    ++count;
    CHECK(uid != 0);
  }
  CHECK(count == 4);
  CHECK(status_field(daemon.pid(), "CapEff") == "0000000000000000");
  CHECK(status_field(daemon.pid(), "CapPrm") == "0000000000000000");
  CHECK(status_field(daemon.pid(), "CapAmb") == "0000000000000000");
  CHECK(daemon.log().find("running as root") == std::string::npos);
  daemon.signal(SIGTERM);
  CHECK(daemon.wait_exit(15s) == 0);
}
