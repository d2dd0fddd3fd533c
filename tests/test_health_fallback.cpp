// Health that stays true when its own disk cannot be written (docs/reliability.md, "Health on a
// failing disk"): the daemon in its default layout on a file system of the test's own, which then
// fails as a vehicle's disk does: ext4 forced read-only by an error (EROFS), ext4 shut down (EIO),
// a btrfs subvolume set read-only and then read-write again. Each time the health goes to
// health.fallback_directory, fresh (never more than 2 s old) and saying degraded with why, the
// supervisor's STATUS= carries it, and it comes home when the disk does. Root only.
#include <signal.h>

#include <catch2/catch.hpp>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <optional>
#include <string>
#include <thread>

#include "bench/child_process.hpp"
#include "support/loop_file_system.hpp"
#include "support/notify_listener.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using namespace std::chrono_literals;
namespace fs = std::filesystem;

namespace {

// Seconds since `file` was last replaced or written; nullopt when it is not there.
std::optional<double> age_seconds(const fs::path& file) {
  std::error_code ec;
  const auto written = fs::last_write_time(file, ec);
  if (ec) return std::nullopt;
  return std::chrono::duration<double>(fs::file_time_type::clock::now() - written).count();
}

enum class Failure { kReadOnly, kShutDown, kSubvolumeReadOnly, kFrozen };

struct Case {
  const char* name;
  const char* type;
  const char* mount_options;
  Failure failure;
  bool comes_back;  // the disk takes writes again (btrfs: the subvolume set read-write)
  // health.fallback_directory names a path that cannot be a directory (under a regular file):
  // the next of the defaults takes the files ($XDG_RUNTIME_DIR/pandarcap/SENSOR here).
  bool configured_unusable = false;
};

void fallback_case(const Case& c) {
  INFO(c.name);
  test::ScratchDir dir(std::string("health-fallback-") + c.name);
  test::LoopFileSystem disk(dir / "disk.img", dir / "mnt", 512ull << 20, c.type, c.mount_options);
  if (!disk.available()) return;
  fs::path base = disk.mount_point();
  if (c.failure == Failure::kSubvolumeReadOnly) {
    base /= "sub";
    REQUIRE(test::shell("btrfs subvolume create '" + base.string() + "'"));
  }
  const fs::path out = base / "o";
  const fs::path configured =
      c.configured_unusable ? dir / "a-file" / "fallback" : dir / "fallback";
  if (c.configured_unusable) std::ofstream(dir / "a-file") << "not a directory\n";
  // Not there yet: made at the first need.
  const fs::path fallback =
      c.configured_unusable ? dir / "xdg" / "pandarcap" / "pandar40p" : configured;
  const fs::path config = dir / "health.toml";
  std::ofstream(config) << "[health]\nfallback_directory = \"" << configured.string() << "\"\n";
  test::NotifyListener notify(dir / "notify.sock");
  harness::ChildProcess daemon(
      test::binary("pandarcapd"),
      {"--allow-root", "-c", config.string(), "--simulate", "--output-dir", out.string()},
      dir / "log.txt",
      {"NOTIFY_SOCKET=" + (dir / "notify.sock").string(),
       "XDG_RUNTIME_DIR=" + (dir / "xdg").string()});
  INFO(daemon.log());
  const fs::path home_prom = out / "health" / "pandarcap.prom";
  REQUIRE(notify.wait_for(
      [&] {
        const auto record = test::last_health_record(out);
        return !record.is_null() && record.at("state") == "ok";
      },
      20s));
  CHECK_FALSE(fs::exists(fallback / "pandarcap.prom"));

  switch (c.failure) {
    case Failure::kReadOnly:
      REQUIRE(disk.force_read_only());
      break;
    case Failure::kShutDown:
      REQUIRE(disk.shut_down());
      break;
    case Failure::kSubvolumeReadOnly:
      REQUIRE(test::shell("btrfs property set -ts '" + base.string() + "' ro true"));
      break;
    case Failure::kFrozen:
      REQUIRE(test::shell("fsfreeze -f '" + disk.mount_point().string() + "'"));
      break;
  }
  const auto failed_at = std::chrono::steady_clock::now();
  INFO(daemon.log());
  const fs::path prom = fallback / "pandarcap.prom";
  // Within 2 s the fallback holds the health, and says why. A disk that hangs (frozen) fails no
  // call: the writer stands still in one, and the main thread says so once it stood 2 s.
  const bool frozen = c.failure == Failure::kFrozen;
  const auto within = frozen ? 3500ms : 2500ms;
  REQUIRE(notify.wait_for([&] { return fs::exists(prom); }, within));
  CHECK(std::chrono::steady_clock::now() - failed_at < within);
  // And stays fresh and true for the next seconds: never more than 2 s old, degraded, naming it.
  while (std::chrono::steady_clock::now() - failed_at < 6s) {
    notify.receive();
    const std::optional<double> age = age_seconds(prom);
    REQUIRE(age.has_value());
    CHECK(*age <= 2.0);
    const auto samples = test::prom_samples(harness::read_file(prom));
    CHECK(samples.at("pandarcap_state{sensor=\"pandar40p\",state=\"degraded\"}") == "1");
    CHECK(samples.at("pandarcap_health_fallback{sensor=\"pandar40p\"}") == "1");
    std::this_thread::sleep_for(200ms);  // the probe's period, not a synchronisation
  }
  const auto lines = test::json_lines(fallback / "health.jsonl");
  REQUIRE_FALSE(lines.empty());
  const std::string reason = lines.back().at("reason");
  INFO(lines.back().dump());
  CHECK(reason.find(frozen ? "writer stalled for" : "health written to " + fallback.string()) !=
        std::string::npos);
  CHECK(lines.back().at("health_fallback").at("active") == true);
  // The supervisor is told too: systemctl status shows it.
  CHECK(notify.count("STATUS=degraded") >= 1);
  CHECK(notify.count(frozen ? "writer stalled" : "health written to") >= 1);
  // The journal says so at once, and every 10 s after.
  CHECK(daemon.log().find(frozen ? "a report of it in " + fallback.string()
                                 : "writing the health files to " + fallback.string()) !=
        std::string::npos);
  if (frozen) {
    const auto samples = test::prom_samples(harness::read_file(prom));
    CHECK(samples.count("pandarcap_writer_stalled_seconds{sensor=\"pandar40p\"}") == 1);
  }

  if (c.comes_back) {
    REQUIRE(test::shell(frozen ? "fsfreeze -u '" + disk.mount_point().string() + "'"
                               : "btrfs property set -ts '" + base.string() + "' ro false"));
    // Home again: the home file fresh, the fallback's .prom gone, the state ok once the
    // outputs' own write errors are a second old.
    REQUIRE(notify.wait_for(
        [&] {
          const std::optional<double> age = age_seconds(home_prom);
          return !fs::exists(prom) && age && *age < 1.5;
        },
        5s));
    REQUIRE(notify.wait_for(
        [&] {
          const auto record = test::last_health_record(out);
          return !record.is_null() && record.at("state") == "ok" &&
                 record.at("health_fallback").at("active") == false;
        },
        5s));
    CHECK(daemon.log().find(frozen ? "the writer is back" : "the health files are back there") !=
          std::string::npos);
  }
  daemon.signal(SIGTERM);
  // Ends whatever its disk does (a shut-down one fails every write and sync).
  CHECK(daemon.wait_exit(30s).has_value());
}

}  // namespace

TEST_CASE("health on a disk that fails: ext4 forced read-only by an error (EROFS)",
          "[fallback][reliability][threads]") {
  fallback_case({"ext4-errors-read-only", "ext4", "errors=remount-ro", Failure::kReadOnly, false});
}

TEST_CASE("health on a disk that fails: ext4 shut down (EIO), the configured fallback unusable",
          "[fallback][reliability][threads]") {
  // Its configured fallback unusable too: the next default takes the files.
  fallback_case({"ext4-shut-down", "ext4", "", Failure::kShutDown, false, true});
}

TEST_CASE("health on a disk that fails: a btrfs subvolume read-only, then read-write: home again",
          "[fallback][reliability][threads]") {
  fallback_case({"btrfs-subvolume-read-only", "btrfs", "", Failure::kSubvolumeReadOnly, true});
}

TEST_CASE("health on a disk that hangs: frozen (fsfreeze), the writer stuck, then thawed",
          "[fallback][reliability][threads]") {
  fallback_case({"ext4-frozen", "ext4", "", Failure::kFrozen, true});
}
