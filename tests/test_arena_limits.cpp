// The frame arenas' memory at the edge of what the machine gives: a configuration whose arenas
// do not fit under the process's memory limit (ulimit -v, systemd's LimitAS=) must stop the start
// with an error that says what did not fit and which keys size it, not a bare "std::bad_alloc".
// Real binary, a real capture, the limit set by util-linux's prlimit. Only the thread-stack case
// is [threads] (the others stop before the daemon's first thread); none runs under a sanitizer,
// whose runtime an address-space limit stops first.
#include <catch2/catch.hpp>
#include <fstream>
#include <string>

#include "support/test_support.hpp"

using namespace pandarcap;

TEST_CASE("arenas larger than the address-space limit: a clear error naming them, no crash",
          "[daemon][arena]") {
  if (test::kSanitizerBuild) {
    // ASan and TSan reserve terabytes of address space at start: any RLIMIT_AS stops them first.
    WARN("sanitizer build: an address-space limit stops the runtime itself; not tested");
    return;
  }
  const auto capture = test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  if (!capture) return;
  test::ScratchDir dir("arena-limits");
  // 64 arenas of 10 000 000 points of the widest layout: ~20 GB, refused at once under 1 GiB
  // (nothing is touched, so the machine's own memory is never at stake).
  const auto config = dir / "pandarcap.toml";
  std::ofstream(config) << "[arenas]\ncount = 64\npoints_per_frame = 10000000\n"
                           "[output]\npcd_fields = \"autoware\"\n";
  const auto run =
      test::run_command("prlimit --as=1073741824 " + test::pandarcapd_command() + " -c " +
                        test::quoted(config) + " --output-dir " + test::quoted(dir / "out") +
                        " --replay " + test::quoted(*capture) + " 2>&1");
  INFO(run.out);
  CHECK(run.exit_code > 0);  // refused, not killed by a signal (-1)
  CHECK(run.exit_code < 128);
  // What did not fit, and what to lower: a bare "pandarcapd: std::bad_alloc" says neither.
  CHECK(run.out.find("std::bad_alloc") == std::string::npos);
  CHECK(run.out.find("arenas") != std::string::npos);
  CHECK(run.out.find("points_per_frame") != std::string::npos);
}

// The arenas' neighbours, sized by other keys, under the same kind of limit: the packet ring
// (ring.slots: 2^20 x 1472 B, 1.5 GB) and the raw batches (arenas.packets_per_frame: 64 x 65 536
// packets), each with arenas that fit. Their refusal says as much as the arenas' does.
TEST_CASE("a ring or raw batches larger than the address-space limit: a clear error naming them",
          "[daemon][arena]") {
  if (test::kSanitizerBuild) {
    WARN("sanitizer build: an address-space limit stops the runtime itself; not tested");
    return;
  }
  const auto capture = test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  if (!capture) return;
  struct Case {
    const char* config;
    const char* key;
  };
  for (const Case& c : {Case{"[ring]\nslots = 1048576\n", "ring.slots"},
                        Case{"[arenas]\ncount = 64\npoints_per_frame = 1000\n"
                             "packets_per_frame = 65536\n",
                             "packets_per_frame"}}) {
    test::ScratchDir dir("arena-neighbours-limits");
    const auto config = dir / "pandarcap.toml";
    std::ofstream(config) << c.config;
    const auto run =
        test::run_command("prlimit --as=1073741824 " + test::pandarcapd_command() + " -c " +
                          test::quoted(config) + " --output-dir " + test::quoted(dir / "out") +
                          " --replay " + test::quoted(*capture) + " 2>&1");
    INFO(c.config);
    INFO(run.out);
    CHECK(run.exit_code > 0);
    CHECK(run.exit_code < 128);
    CHECK(run.out.find("std::bad_alloc") == std::string::npos);
    CHECK(run.out.find(c.key) != std::string::npos);
  }
}

// Memory enough for every buffer but not for every thread's stack (the limit counts stacks:
// prlimit --stack=1GiB makes each one 1 GiB, and --as=3GiB leaves room for two of them): a
// thread that cannot start must stop the start with an error. Bounded by `timeout -s KILL`, since
// SIGTERM is not enough to end what it must not become (137: killed).
TEST_CASE("a thread refused its stack at the start: an error and an exit, not a hang",
          "[daemon][arena][threads]") {
  if (test::kSanitizerBuild) {
    WARN("sanitizer build: an address-space limit stops the runtime itself; not tested");
    return;
  }
  const auto capture = test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  if (!capture) return;
  test::ScratchDir dir("thread-stack-limits");
  const auto run =
      test::run_command("timeout -s KILL 30 prlimit --stack=1073741824 --as=3221225472 " +
                        test::pandarcapd_command() + " --output-dir " + test::quoted(dir / "out") +
                        " --replay " + test::quoted(*capture) + " 2>&1");
  INFO(run.out);
  CHECK(run.exit_code > 0);    // it cannot run all its threads: not a success
  CHECK(run.exit_code < 128);  // 137: still there after 30 s, killed
  CHECK(run.out.find("pandarcapd: ") != std::string::npos);
}

// The writer's buffers follow the arenas' points (the lzf compressor, the MCAP chunk buffers and
// messages: arena_points), so they are as large as the arenas and more: 2 arenas of 10 000 000
// autoware points fit under 2 GB, the MCAP and lzf buffers for such frames do not. Their refusal
// must name what sizes them, and is not an output directory's fault (73 says "not writable").
TEST_CASE("the writer's frame buffers larger than the address-space limit: named, not exit 73",
          "[daemon][arena][threads]") {
  if (test::kSanitizerBuild) {
    WARN("sanitizer build: an address-space limit stops the runtime itself; not tested");
    return;
  }
  const auto capture = test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  if (!capture) return;
  test::ScratchDir dir("writer-buffer-limits");
  const auto config = dir / "pandarcap.toml";
  std::ofstream(config) << "[arenas]\ncount = 2\npoints_per_frame = 10000000\n"
                           "[output]\npcd_fields = \"autoware\"\nmcap = true\n"
                           "pcd_compression = \"lzf\"\n";
  const auto run = test::run_command("timeout -s KILL 30 prlimit --as=2000000000 " +
                                     test::pandarcapd_command() + " -c " + test::quoted(config) +
                                     " --output-dir " + test::quoted(dir / "out") + " --replay " +
                                     test::quoted(*capture) + " 2>&1");
  INFO(run.out);
  CHECK(run.exit_code > 0);
  CHECK(run.exit_code < 128);
  CHECK(run.exit_code != 73);  // EX_CANTCREAT: the output directory is not at fault
  CHECK(run.out.find("std::bad_alloc") == std::string::npos);
  CHECK(run.out.find("points_per_frame") != std::string::npos);
}
