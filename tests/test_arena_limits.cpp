// The frame arenas' memory at the edge of what the machine gives: a configuration whose arenas
// do not fit under the process's memory limit (ulimit -v, systemd's LimitAS=) must stop the start
// with an error that says what did not fit and which keys size it, not a bare "std::bad_alloc".
// Real binary, a real capture, the limit set by util-linux's prlimit. Only the thread-stack case
// is [threads] (the others stop before the daemon's first thread); none runs under a sanitizer,
// whose runtime an address-space limit stops first.
#include <catch2/catch.hpp>
#include <fstream>
#include <optional>
#include <string>

#include "support/test_support.hpp"

using namespace pandarcap;

namespace {

// pandarcapd replaying the real 40P capture with `config_text` under `limits` (prlimit's options),
// at most 30 s (killed after: 137). nullopt: no run (a sanitizer build, whose runtime an
// address-space limit stops first, or no capture where that may skip).
std::optional<test::CommandResult> run_under_limits(const char* name, const std::string& limits,
                                                    const std::string& config_text) {
  if (test::kSanitizerBuild) {
    WARN("sanitizer build: an address-space limit stops the runtime itself; not tested");
    return std::nullopt;
  }
  const auto capture = test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  if (!capture) return std::nullopt;
  test::ScratchDir dir(name);
  const auto config = dir / "pandarcap.toml";
  std::ofstream(config) << config_text;
  return test::run_command("timeout -s KILL 30 prlimit " + limits + " " +
                           test::pandarcapd_command() + " -c " + test::quoted(config) +
                           " --output-dir " + test::quoted(dir / "out") + " --replay " +
                           test::quoted(*capture) + " 2>&1");
}

// Refused, with an exit status (not killed: -1, 128 and up), and never a bare "std::bad_alloc",
// which names neither what did not fit nor what to lower.
void check_refused_naming(const test::CommandResult& run, const std::string& key) {
  INFO(run.out);
  CHECK(run.exit_code > 0);
  CHECK(run.exit_code < 128);
  CHECK(run.out.find("std::bad_alloc") == std::string::npos);
  CHECK(run.out.find(key) != std::string::npos);
}

}  // namespace

TEST_CASE("arenas larger than the address-space limit: a clear error naming them, no crash",
          "[daemon][arena]") {
  // 64 arenas of 10 000 000 points of the widest layout: ~20 GB, refused at once under 1 GiB
  // (nothing is touched, so the machine's own memory is never at stake).
  const auto run = run_under_limits("arena-limits", "--as=1073741824",
                                    "[arenas]\ncount = 64\npoints_per_frame = 10000000\n"
                                    "[output]\npcd_fields = \"autoware\"\n");
  if (!run) return;
  check_refused_naming(*run, "arenas");
  check_refused_naming(*run, "points_per_frame");
}

// The arenas' neighbours, sized by other keys, under the same kind of limit: the packet ring
// (ring.slots: 2^20 x 1472 B, 1.5 GB) and the raw batches (arenas.packets_per_frame: 64 x 65 536
// packets), each with arenas that fit. Their refusal says as much as the arenas' does.
TEST_CASE("a ring or raw batches larger than the address-space limit: a clear error naming them",
          "[daemon][arena]") {
  struct Case {
    const char* config;
    const char* key;
  };
  for (const Case& c : {Case{"[ring]\nslots = 1048576\n", "ring.slots"},
                        Case{"[arenas]\ncount = 64\npoints_per_frame = 1000\n"
                             "packets_per_frame = 65536\n",
                             "packets_per_frame"}}) {
    INFO(c.config);
    const auto run = run_under_limits("arena-neighbours-limits", "--as=1073741824", c.config);
    if (!run) return;
    check_refused_naming(*run, c.key);
  }
}

// Memory enough for every buffer but not for every thread's stack (the limit counts stacks:
// prlimit --stack=1GiB makes each one 1 GiB, and --as=3GiB leaves room for two of them): a
// thread that cannot start must stop the start with an error naming it. Before, the threads
// started waited for the one that did not, for good (SIGTERM did not end it; 137: killed).
TEST_CASE("a thread refused its stack at the start: an error and an exit, not a hang",
          "[daemon][arena][threads]") {
  const auto run =
      run_under_limits("thread-stack-limits", "--stack=1073741824 --as=3221225472", "");
  if (!run) return;
  check_refused_naming(*run, "cannot start thread pc-");
}

// The writer's buffers follow the arenas' points (the lzf compressor, the MCAP chunk buffers and
// messages: arena_points), so they are as large as the arenas and more: 2 arenas of 10 000 000
// autoware points fit under 2 GB, the MCAP and lzf buffers for such frames do not. Their refusal
// must name what sizes them, and is not an output directory's fault (73 says "not writable").
TEST_CASE("the writer's frame buffers larger than the address-space limit: named, not exit 73",
          "[daemon][arena][threads]") {
  const auto run = run_under_limits("writer-buffer-limits", "--as=2000000000",
                                    "[arenas]\ncount = 2\npoints_per_frame = 10000000\n"
                                    "[output]\npcd_fields = \"autoware\"\nmcap = true\n"
                                    "pcd_compression = \"lzf\"\n");
  if (!run) return;
  check_refused_naming(*run, "points_per_frame");
  CHECK(run->exit_code != 73);  // EX_CANTCREAT: the output directory is not at fault
}
