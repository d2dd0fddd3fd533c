// The frame arenas' memory at the edge of what the machine gives: a configuration whose arenas
// do not fit under the process's memory limit (ulimit -v, systemd's LimitAS=) must stop the start
// with an error that says what did not fit and which keys size it, not a bare "std::bad_alloc".
// Real binary, a real capture, the limit set by util-linux's prlimit. Not [threads]: the daemon
// stops before its first thread (the thread census says so), and TSan cannot run under the limit.
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
