// pandarcap-bench as a user runs it. Only the shape and the correctness of the report are checked
// here (every key the acceptance checks read, no item out of order, consistent ratios); the
// figures themselves are performance claims and belong to docs/performance.md, not to a test.
#include <fcntl.h>
#include <fmt/format.h>
#include <linux/fs.h>
#include <netinet/in.h>
#include <sys/ioctl.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <span>
#include <sstream>
#include <string>
#include <type_traits>
#include <vector>

#include "bench/child_process.hpp"
#include "core/decode/any_stream_decoder.hpp"
#include "core/decode/decoder_target.hpp"
#include "core/frames/frame_collector.hpp"
#include "core/sensors/packet.hpp"
#include "core/sensors/sensor_models.hpp"
#include "support/test_support.hpp"

using namespace pandarcap;
using nlohmann::json;

namespace {

std::string bench() {
  return "'" + test::binary("pandarcap-bench").string() + "'";
}

// A zero-loss --json run: the report on standard output, what the harness warned about on
// standard error, kept apart. Merged, a warning the run may or may not print (a dear work
// directory in a busy /tmp, which the suite itself makes) broke the report's parse.
struct ReportRun {
  int exit_code = -1;
  std::string out;
  std::string err;
};
ReportRun run_report(const test::ScratchDir& dir, const std::string& command) {
  const auto err = dir / "bench.stderr";
  const auto result = test::run_command(command + " 2>" + test::quoted(err));
  return {result.exit_code, result.out, harness::read_file(err)};
}

}  // namespace

TEST_CASE("pandarcap-bench ring --json reports every figure from one run",
          "[bench][cli][threads]") {
  const auto result =
      test::run_command(bench() +
                        " ring --json --items 20000 --mutex-items 2000 --round-trips 200 --repeat 1"
                        " --idle-seconds 0.2");
  REQUIRE(result.exit_code == 0);
  const json report = json::parse(result.out);
  for (const char* batch : {"1", "8", "32"}) {
    INFO("batch " << batch);
    REQUIRE(report["packet_ring_items_per_s"].contains(batch));
    CHECK(report["packet_ring_items_per_s"][batch].get<double>() > 0);
    REQUIRE(report["round_trip_ns"]["packet_ring"].contains(batch));
  }
  const double mutex = report["mutex_queue_items_per_s"];
  CHECK(mutex > 0);
  CHECK(report["typed_queue_items_per_s"].get<double>() > 0);
  // The headline ratio is batch 32 over the baseline measured in the same run.
  CHECK(report["ratio_vs_mutex"].get<double>() ==
        Approx(report["packet_ring_items_per_s"]["32"].get<double>() / mutex));
  CHECK(report["order_errors"] == 0);
  // The idle consumer received every packet the paced producer sent.
  CHECK(report["idle"]["packets_received"] == report["idle"]["packets_sent"]);
  CHECK(report["idle"]["consumer_cpu_percent"].get<double>() >= 0);
}

TEST_CASE("pandarcap-bench rejects bad usage with status 64", "[bench][cli]") {
  CHECK(test::run_command(bench() + " 2>/dev/null").exit_code == 64);
  CHECK(test::run_command(bench() + " nonsense 2>/dev/null").exit_code == 64);
  CHECK(test::run_command(bench() + " ring --capacity 100 2>/dev/null").exit_code == 64);
  CHECK(test::run_command(bench() + " ring --items many 2>/dev/null").exit_code == 64);
  const auto help = test::run_command(bench() + " ring --help");
  CHECK(help.exit_code == 0);
  CHECK(help.out.find("ratio_vs_mutex") != std::string::npos);
}

TEST_CASE("pandarcap-bench decode --json: every supported target, ratios from one run",
          "[bench][cli][simd]") {
  const auto capture = test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  if (!capture) return;
  const auto result = test::run_command(bench() + " decode --json --seconds 0.02 --rounds 1" +
                                        " --capture '" + capture->string() + "'");
  REQUIRE(result.exit_code == 0);
  const json report = json::parse(result.out);
  CHECK(report["input"]["packets"] == 1439);
  CHECK(report["input"]["return_mode"] == "dual");
  const json& ran = report["targets_ran"];
  REQUIRE(ran.size() == supported_decoder_targets().size());
  const double scalar = report["scalar"]["packets_per_s"];
  REQUIRE(scalar > 0);
  double best = 0;
  std::string best_name;
  for (const auto& name : ran) {
    const json& t = report[name.get<std::string>()];
    INFO(name);
    REQUIRE(t.contains("packets_per_s"));
    REQUIRE(t.contains("points_per_s"));
    const double pps = t["packets_per_s"];
    // Every target decodes the same points, so points per packet agree across targets.
    CHECK(t["points_per_s"].get<double>() / pps ==
          Approx(report["scalar"]["points_per_s"].get<double>() / scalar).epsilon(1e-9));
    CHECK(t["vs_scalar"].get<double>() == Approx(pps / scalar));
    if (pps > best) {
      best = pps;
      best_name = name;
    }
  }
  CHECK(report["best_target"] == best_name);
  CHECK(report["best_vs_scalar"].get<double>() == Approx(best / scalar));

  // Fixed-work mode (for callgrind) reports the work, not a rate.
  const auto passes = test::run_command(bench() + " decode --json --passes 2 --target scalar" +
                                        " --capture '" + capture->string() + "'");
  REQUIRE(passes.exit_code == 0);
  CHECK(json::parse(passes.out)["scalar"]["packets_decoded"] == 2 * 1439);

  // A target this machine cannot run is a usage error, not a silent substitute.
  const auto bad = test::run_command(bench() + " decode --target neon 2>&1");
  const auto supported = supported_decoder_targets();
  if (std::find(supported.begin(), supported.end(), DecoderTarget::kNeon) == supported.end()) {
    CHECK(bad.exit_code == 64);
    CHECK(bad.out.find("decoder 'neon'") != std::string::npos);
  }
}

TEST_CASE("pandarcap-bench decode --sensor-model all: a stream-decoder row per model, one run",
          "[bench][cli]") {
  const auto result = test::run_command(bench() +
                                        " decode --json --sensor-model all --target scalar"
                                        " --seconds 0.005 --rounds 1 2>&1");
  INFO(result.out);
  REQUIRE(result.exit_code == 0);
  const json report = json::parse(result.out);
  const json& rows = report["models"];
  REQUIRE(rows.size() == kSensorModelIds.size());  // the 40P at the one target asked for
  for (std::size_t i = 0; i < rows.size(); ++i) {
    const json& row = rows[i];
    const SensorModelId model = kSensorModelIds[i];
    INFO(lower_case_name(model));
    CHECK(row["sensor_model"] == std::string(lower_case_name(model)));
    CHECK(row["target"] == "scalar");
    with_model(model, [&]<class M>(std::type_identity<M>) {
      // One second of the model's own stream in dual return, every packet through its decoder.
      CHECK(row["packets"] == std::llround(M::packets_per_second(2)));
      CHECK(row["slots_per_packet"] == M::kBlocks * M::kChannels);
    });
    CHECK(row["accepted"] == row["packets"]);
    CHECK(row["rejected"] == 0);
    CHECK(row["outliers"] == 0);
    CHECK(row["points_per_pass"].get<std::uint64_t>() > 0);
    CHECK(row["frames_complete"].get<std::uint64_t>() >= 8);  // ten turns, the first and last cut
    CHECK(row["frames_dropped"] == 0);
    CHECK(row["points_dropped"] == 0);
    const double pps = row["packets_per_s"];
    CHECK(row["channel_measurements_per_s"].get<double>() ==
          Approx(pps * row["slots_per_packet"].get<double>()));
    CHECK(row["ns_per_measurement"].get<double>() ==
          Approx(1e9 / row["channel_measurements_per_s"].get<double>()));
  }
  CHECK(rows[0]["ns_per_measurement_vs_pandar40p_scalar"] == 1.0);
  // The per-model rows decode the simulated sensors: a capture is the 40P's target rows' input.
  const auto mixed =
      test::run_command(bench() + " decode --sensor-model pandar64 --capture x.pcap 2>&1");
  CHECK(mixed.exit_code == 64);
  CHECK(test::run_command(bench() + " decode --sensor-model velodyne 2>&1").exit_code == 64);
}

namespace {
std::string md_text(const std::filesystem::path& report_dir) {
  std::stringstream md;
  md << std::ifstream(report_dir / "summary.md").rdbuf();
  return md.str();
}
}  // namespace

TEST_CASE("pandarcap-bench zero-loss: a short smoke run of the whole harness",
          "[bench][cli][threads]") {
  test::ScratchDir dir("zero-loss");
  const auto report_dir = dir / "report";
  const auto result = run_report(
      dir,
      bench() + " zero-loss --json --trial-seconds 0.5 --min-rate 1000 --max-rate 3000 --steps 1" +
          " --sensor-rate 1800 --sensor-rate-rounds 1 --report-dir '" + report_dir.string() + "'");
  INFO(result.out);
  INFO(result.err);
  REQUIRE(result.exit_code == 0);
  const json report = json::parse(result.out);
  for (const char* key : {"daemon_zero_loss_pps", "bare_recvmmsg_zero_loss_pps",
                          "recvfrom_zero_loss_pps", "daemon_vs_bare"}) {
    INFO(key);
    REQUIRE(report.contains(key));
  }
  // At 1000 packets/s every receiver takes everything, the daemon with all its outputs on.
  CHECK(report["daemon_zero_loss_pps"].get<double>() >= 900);
  CHECK(report["bare_recvmmsg_zero_loss_pps"].get<double>() >= 900);
  CHECK(report["recvfrom_zero_loss_pps"].get<double>() >= 900);
  CHECK(report["daemon_vs_bare"].get<double>() ==
        Approx(report["daemon_zero_loss_pps"].get<double>() /
               report["bare_recvmmsg_zero_loss_pps"].get<double>()));
  const json& first = report["trials"]["daemon"][0];
  CHECK(first["sent"].get<std::uint64_t>() == first["accepted"].get<std::uint64_t>());
  // The generator keeps its pace (within 10 %) at a low rate.
  CHECK(first["achieved_pps"].get<double>() == Approx(1000).epsilon(0.1));

  const json& s = report["at_sensor_rate"];
  for (const char* key :
       {"cpu_fraction_of_one_core", "latency_p99_us", "hot_path_allocations", "peak_rss_bytes"}) {
    INFO(key);
    REQUIRE(s.contains(key));
  }
  CHECK(s["lost"] == 0);
  CHECK(s["cpu_fraction_of_one_core"].get<double>() > 0);
  // The floor beside it: a bare receiver under the same traffic, measured in the same run.
  CHECK(s["bare_recvmmsg_cpu_fraction_of_one_core"].get<double>() > 0);
  CHECK_THAT(md_text(report_dir), Catch::Contains("bare recvmmsg loop (wakes per datagram"));
  CHECK(s["latency_p99_us"].get<double>() > 0);
  CHECK(s["peak_rss_bytes"].get<std::uint64_t>() > (1u << 20));
  CHECK(report["environment"]["cores"].get<int>() >= 1);
  // What a file's creation cost the daemon where it wrote (its own health's count), and that
  // place: $TMPDIR's, else /var/tmp's (not /tmp, a test suite's churn), removed at the end.
  const json& work = report["environment"]["work_dir"];
  CHECK(s["files_created"].get<std::uint64_t>() >= 2);  // a frame and a recording at least
  CHECK(s["file_create_us"].get<double>() > 0);
  CHECK(work["file_create_us_at_sensor_rate"] == s["file_create_us"]);
  CHECK(work["removed_at_exit"] == true);
  const char* tmpdir = std::getenv("TMPDIR");
  const std::string parent = tmpdir != nullptr && *tmpdir != '\0' ? tmpdir : "/var/tmp";
  CHECK(std::filesystem::equivalent(
      std::filesystem::path(work["path"].get<std::string>()).parent_path(), parent));
  CHECK_FALSE(std::filesystem::exists(work["path"].get<std::string>()));
  CHECK_THAT(md_text(report_dir), Catch::Contains("where creating one cost it"));

  // The report directory: the same JSON, a Markdown summary and an SVG plot.
  CHECK(json::parse(std::ifstream(report_dir / "report.json")) == report);
  std::stringstream md, svg;
  md << std::ifstream(report_dir / "summary.md").rdbuf();
  svg << std::ifstream(report_dir / "plot.svg").rdbuf();
  CHECK_THAT(md.str(), Catch::Contains("zero-loss rate"));
  CHECK(svg.str().rfind("<svg ", 0) == 0);
  CHECK_THAT(svg.str(), Catch::Contains("</svg>") && Catch::Contains("<polyline"));
  // The plot's x is what was sent; and no two neighbouring trials of a receiver are more than
  // --max-gap (2) apart, so the lines join measured points only.
  CHECK_THAT(svg.str(), Catch::Contains("sent packets/s (achieved)"));
  CHECK(report["settings"]["max_gap"] == 2.0);
  for (const char* who : {"daemon", "bare_recvmmsg", "recvfrom"}) {
    std::vector<double> rates;
    for (const json& t : report["trials"][who])
      rates.push_back(t["offered_pps"].get<double>());
    std::sort(rates.begin(), rates.end());
    INFO(who << ": " << report["trials"][who].size() << " trials");
    REQUIRE(rates.size() >= 2);  // 1000 and 3000 at least
    for (std::size_t i = 1; i < rates.size(); ++i)
      CHECK(rates[i] <= 2 * rates[i - 1] + 1);
  }
}

TEST_CASE(
    "pandarcap-bench zero-loss --from-report renders a saved report, refuses an incomplete one",
    "[bench][cli]") {
  test::ScratchDir dir("from-report");
  const auto saved =
      std::filesystem::path(PANDARCAP_SOURCE_DIR) / "bench/results/zero-loss/report.json";
  const auto rendered = test::run_command(bench() + " zero-loss --from-report '" + saved.string() +
                                          "' --report-dir '" + (dir / "ok").string() + "' 2>&1");
  INFO(rendered.out);
  REQUIRE(rendered.exit_code == 0);
  CHECK_THAT(rendered.out, Catch::Contains("zero-loss rate"));
  CHECK(std::filesystem::file_size(dir / "ok" / "plot.svg") > 0);

  // The same report without a key the renderers read: an error naming the file and the key,
  // and nothing written.
  json report = json::parse(std::ifstream(saved));
  report["at_sensor_rate"].erase("frame_latency_p99_ms");
  const auto incomplete = dir / "incomplete.json";
  std::ofstream(incomplete) << report.dump();
  const auto refused =
      test::run_command(bench() + " zero-loss --from-report '" + incomplete.string() +
                        "' --report-dir '" + (dir / "bad").string() + "' 2>&1");
  INFO(refused.out);
  CHECK(refused.exit_code == 1);
  CHECK_THAT(refused.out,
             Catch::Contains(incomplete.string()) && Catch::Contains("frame_latency_p99_ms"));
  CHECK_FALSE(std::filesystem::exists(dir / "bad"));

  // Not JSON at all: the file and the parser's line and column.
  const auto cut = dir / "cut.json";
  std::ofstream(cut) << "{\"trials\":\n";
  const auto unparsed =
      test::run_command(bench() + " zero-loss --from-report '" + cut.string() + "' 2>&1");
  INFO(unparsed.out);
  CHECK(unparsed.exit_code == 1);
  CHECK_THAT(unparsed.out, Catch::Contains(cut.string() + "' is not JSON") &&
                               Catch::Contains("line 2, column 1"));
}

TEST_CASE("pandarcap-bench zero-loss --daemon-only: the daemon alone, on single-return traffic",
          "[bench][cli][threads][measures]") {
  test::ScratchDir dir("zero-loss-daemon-only");
  const auto work = dir / "work";
  const auto result = run_report(
      dir, bench() + " zero-loss --json --daemon-only --trial-seconds 0.5 --min-rate 1000" +
               " --max-rate 2000 --steps 0 --sensor-rate 1000 --rpm 1200 --return-mode single" +
               " --work-dir '" + work.string() + "'");
  INFO(result.out);
  INFO(result.err);
  REQUIRE(result.exit_code == 0);
  const json report = json::parse(result.out);
  CHECK(report["trials"]["bare_recvmmsg"].empty());
  CHECK(report["trials"]["recvfrom"].empty());
  CHECK(report["bare_recvmmsg_zero_loss_pps"].get<double>() == 0);
  CHECK(report["daemon_vs_bare"].get<double>() == 0);
  CHECK(report["daemon_zero_loss_pps"].get<double>() >= 900);
  CHECK(report["at_sensor_rate"]["bare_recvmmsg_cpu_fraction_of_one_core"].get<double>() == 0);
  CHECK(report["at_sensor_rate"]["cpu_fraction_of_one_core"].get<double>() > 0);
  // The traffic options reach the generator, and the daemon takes that stream whole.
  CHECK(report["settings"]["traffic"] == "simulated Pandar40P, strongest return, 1200 RPM");
  const json& first = report["trials"]["daemon"][0];
  CHECK(first["sent"].get<std::uint64_t>() == first["accepted"].get<std::uint64_t>());
  CHECK(first["generator_cpu_fraction_of_one_core"].get<double>() > 0);
  // A work directory given is kept, with each trial's log; the trials' outputs (emptied after
  // each trial, so that the next does not pay for removing them) are gone at the end.
  CHECK(report["environment"]["work_dir"]["removed_at_exit"] == false);
  std::size_t trials = 0;
  for (const auto& entry : std::filesystem::directory_iterator(work)) {
    if (entry.path().filename().string().rfind("daemon_", 0) != 0) continue;
    ++trials;
    INFO(entry.path());
    CHECK_FALSE(std::filesystem::exists(entry.path() / "out"));
  }
  CHECK(trials == report["trials"]["daemon"].size() + 2);  // + the two at the sensor's rate
  // On ext4 its subdirectories are spread (chattr +T: each trial away from removals nearby).
  const int fd = ::open(work.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  REQUIRE(fd >= 0);
  int flags = 0;
  const bool has_flags = ::ioctl(fd, FS_IOC_GETFLAGS, &flags) == 0;
  ::close(fd);
  if (has_flags && test::run_command("stat -f -c %T '" + work.string() + "'").out == "ext2/ext3\n")
    CHECK((flags & FS_TOPDIR_FL) != 0);
}

TEST_CASE(
    "pandarcap-bench zero-loss at the sensor's rate: both budgets, the bare loop and "
    "another receiver in one run",
    "[bench][cli][threads][measures]") {
  test::ScratchDir dir("zero-loss-budget");
  // Any receiver a user wants to compare: here a few lines of Python that count datagrams and
  // print "received N" when stopped, the line the harness reads for loss. SIGTERM only sets a
  // flag: a datagram read just before it is still counted, and what is queued is read.
  const auto receiver = dir / "receiver.py";
  std::ofstream(receiver) << "import signal, socket, sys\n"
                             "s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)\n"
                             "s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)\n"
                             "s.bind(('127.0.0.1', int(sys.argv[1])))\n"
                             "s.settimeout(0.05)\n"
                             "n = 0\n"
                             "stopping = False\n"
                             "def stop(*_):\n"
                             "    global stopping\n"
                             "    stopping = True\n"
                             "signal.signal(signal.SIGTERM, stop)\n"
                             "while not stopping:\n"
                             "    try:\n"
                             "        s.recv(2048)\n"
                             "        n += 1\n"
                             "    except socket.timeout:\n"
                             "        pass\n"
                             "s.setblocking(False)\n"
                             "try:\n"
                             "    while True:\n"
                             "        s.recv(2048)\n"
                             "        n += 1\n"
                             "except BlockingIOError:\n"
                             "    pass\n"
                             "print('received', n, flush=True)\n";
  const std::string port = std::to_string(harness::free_udp_port());
  const auto result = run_report(
      dir, bench() + " zero-loss --json --sensor-rate-only --trial-seconds 1 --sensor-rate 1800" +
               " --latency-budget-ms 10 --receiver-command 'python3 " + receiver.string() + " " +
               port + "' --receiver-port " + port + " --report-dir '" + (dir / "report").string() +
               "'");
  INFO(result.out);
  INFO(result.err);
  REQUIRE(result.exit_code == 0);
  const json report = json::parse(result.out);
  CHECK(report["trials"]["daemon"].empty());  // no search
  const json& s = report["at_sensor_rate"];
  CHECK(s["budget_ms"] == 10);
  CHECK(s["budget_0"]["budget_ms"] == 0);
  for (const json* t : {&s, &s["budget_0"]}) {
    CHECK((*t)["lost"] == 0);
    for (const std::string thread : {"receive", "decode", "writer"}) {
      INFO(thread);
      const double wakeups = (*t)["wakeups_per_second"][thread].get<double>();
      // A decoder that is behind for the whole second never finds the ring empty, so never
      // waits: under TSan on a busy machine it is (frame latency in the hundreds of ms).
      if (thread == "decode" && test::kThreadSanitizerBuild) {
        CHECK(wakeups >= 0);
      } else {
        CHECK(wakeups > 0);
      }
    }
    CHECK((*t)["frame_latency_p99_ms"].get<double>() > 0);
    CHECK((*t)["daemon_vs_bare_cpu"].get<double>() ==
          Approx((*t)["cpu_fraction_of_one_core"].get<double>() /
                 s["bare_recvmmsg_cpu_fraction_of_one_core"].get<double>()));
  }
  // The bare loop and the daemon alternated three times (the default): the summary is the
  // median round's, its ratio the median of the three.
  const json& rounds = s["rounds"];
  REQUIRE(rounds.size() == 3);
  std::vector<double> ratios;
  int medians = 0;
  for (const json& round : rounds) {
    INFO(round.dump());
    CHECK(round["bare_recvmmsg_cpu_fraction_of_one_core"].get<double>() > 0);
    CHECK(round["daemon_vs_bare_cpu"].get<double>() ==
          Approx(round["daemon_cpu_fraction_of_one_core"].get<double>() /
                 round["bare_recvmmsg_cpu_fraction_of_one_core"].get<double>()));
    ratios.push_back(round["daemon_vs_bare_cpu"].get<double>());
    if (round["median"] == true) {
      ++medians;
      CHECK(round["daemon_cpu_fraction_of_one_core"] == s["cpu_fraction_of_one_core"]);
      CHECK(round["bare_recvmmsg_cpu_fraction_of_one_core"] ==
            s["bare_recvmmsg_cpu_fraction_of_one_core"]);
    }
  }
  CHECK(medians == 1);
  std::sort(ratios.begin(), ratios.end());
  CHECK(s["daemon_vs_bare_cpu"].get<double>() == Approx(ratios[1]));
  CHECK_THAT(md_text(dir / "report"),
             Catch::Contains(fmt::format("**{:.2f}x**, the median of 3 alternated rounds",
                                         s["daemon_vs_bare_cpu"].get<double>())));
  // The budget is why: fewer receive wake-ups than with budget 0 under the same traffic.
  CHECK(s["wakeups_per_second"]["receive"].get<double>() <
        s["budget_0"]["wakeups_per_second"]["receive"].get<double>());
  const json& other = s["other_receiver"];
  CHECK(other["received"].get<std::uint64_t>() == other["sent"].get<std::uint64_t>());
  CHECK(other["lost"] == 0);
  CHECK(other["peak_rss_bytes"].get<std::uint64_t>() > 0);
  CHECK(other["cpu_fraction_of_one_core"].get<double>() >= 0);
  // Bad pairs are usage errors.
  CHECK(test::run_command(bench() + " zero-loss --receiver-command true 2>/dev/null").exit_code ==
        64);
  CHECK(test::run_command(bench() + " zero-loss --latency-budget-ms 1001 2>/dev/null").exit_code ==
        64);
  for (const char* bad : {"0", "2", "4", "10", "x"}) {
    INFO(bad);
    CHECK(test::run_command(bench() + " zero-loss --sensor-rate-rounds " + bad + " 2>/dev/null")
              .exit_code == 64);
  }
}

namespace {

// A UDP socket on 127.0.0.1 with room for everything a short `send` run offers, read after the
// sender has exited.
class LoopbackSink {
 public:
  LoopbackSink() : fd_(::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0)) {
    REQUIRE(fd_ >= 0);
    const int buffer = 16 << 20;
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUFFORCE, &buffer, sizeof buffer);
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &buffer, sizeof buffer);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    REQUIRE(::bind(fd_, reinterpret_cast<sockaddr*>(&address), sizeof address) == 0);
    socklen_t length = sizeof address;
    ::getsockname(fd_, reinterpret_cast<sockaddr*>(&address), &length);
    port_ = ntohs(address.sin_port);
  }
  ~LoopbackSink() { ::close(fd_); }
  LoopbackSink(const LoopbackSink&) = delete;
  LoopbackSink& operator=(const LoopbackSink&) = delete;

  int port() const { return port_; }
  // Every datagram queued now (the sender has finished, so nothing more is coming).
  std::vector<std::vector<std::uint8_t>> take_all() const {
    std::vector<std::vector<std::uint8_t>> datagrams;
    std::vector<std::uint8_t> buffer(65536);
    for (;;) {
      const ssize_t n = ::recv(fd_, buffer.data(), buffer.size(), MSG_DONTWAIT);
      if (n < 0) break;
      datagrams.emplace_back(buffer.begin(), buffer.begin() + n);
    }
    return datagrams;
  }

 private:
  int fd_;
  int port_ = 0;
};

}  // namespace

TEST_CASE("pandarcap-bench send: the generator on its own, checked packet by packet",
          "[bench][cli]") {
  LoopbackSink sink;
  SECTION("single return at 1200 RPM, with UDP sequences") {
    const auto result = test::run_command(
        bench() + " send --json --rate 2000 --seconds 0.5 --rpm 1200 --return-mode single" +
        " --first-sequence 7 --port " + std::to_string(sink.port()) + " 2>&1");
    INFO(result.out);
    REQUIRE(result.exit_code == 0);
    const json report = json::parse(result.out);
    CHECK(report["destination"] == "127.0.0.1");
    CHECK(report["packet_bytes"] == kPacketWithSequenceBytes);
    CHECK(report["achieved_pps"].get<double>() == Approx(2000).epsilon(0.1));
    const auto sent = report["sent"].get<std::uint64_t>();
    CHECK(report["last_sequence"].get<std::uint64_t>() == 7 + sent - 1);

    const auto datagrams = sink.take_all();
    REQUIRE(datagrams.size() == sent);
    int previous_azimuth = -1;
    for (std::size_t i = 0; i < datagrams.size(); ++i) {
      INFO("packet " << i);
      const auto view = PacketView::make(datagrams[i]);
      REQUIRE(view);
      const PacketView& packet = *view;
      REQUIRE(packet.sequence() == std::optional<std::uint32_t>(7 + i));
      CHECK(packet.return_mode() == ReturnMode::kStrongest);
      CHECK(packet.motor_rpm() == Approx(1200).margin(5));  // measured, so it wanders a little
      // 1200 RPM: 1200/60 x 360 deg x 55.56 us = 0.40 deg per block, ten blocks per packet.
      const int step = (packet.azimuth_cdeg(9) - packet.azimuth_cdeg(0) + 36000) % 36000;
      CHECK(step == Approx(360).margin(2));
      if (previous_azimuth >= 0) {
        CHECK((packet.azimuth_cdeg(0) - previous_azimuth + 36000) % 36000 == Approx(400).margin(2));
      }
      previous_azimuth = packet.azimuth_cdeg(0);
    }
  }
  SECTION("dual return at 600 RPM, plain 1262-byte packets") {
    const auto result =
        test::run_command(bench() + " send --json --rate 1000 --seconds 0.3" +
                          " --no-sequence --port " + std::to_string(sink.port()) + " 2>&1");
    INFO(result.out);
    REQUIRE(result.exit_code == 0);
    const json report = json::parse(result.out);
    CHECK(report["packet_bytes"] == kPacketBytes);
    const auto datagrams = sink.take_all();
    REQUIRE(datagrams.size() == report["sent"].get<std::uint64_t>());
    for (const auto& datagram : datagrams) {
      const auto view = PacketView::make(datagram);
      REQUIRE(view);
      const PacketView& packet = *view;
      CHECK_FALSE(packet.has_sequence());
      CHECK(packet.return_mode() == ReturnMode::kDual);
      CHECK(packet.motor_rpm() == Approx(600).margin(5));
      // Dual return: blocks 2k and 2k+1 share one firing and so one azimuth.
      CHECK(packet.azimuth_cdeg(0) == packet.azimuth_cdeg(1));
    }
  }
  SECTION("bad requests are usage errors, and nothing is sent") {
    for (const std::string& options :
         {std::string(" send --destination 10.0.0.1 --foreign-fraction 0.5"),
          std::string(" send --destination sensor.local"), std::string(" send --rpm 900"),
          std::string(" send --return-mode triple"), std::string(" send --rate 0")}) {
      INFO(options);
      const auto result = test::run_command(bench() + options + " --seconds 0.2 --port " +
                                            std::to_string(sink.port()) + " 2>&1");
      CHECK(result.exit_code == 64);
      CHECK_THAT(result.out, Catch::Contains("Try 'pandarcap-bench send --help'"));
    }
    CHECK(sink.take_all().empty());
  }
}

TEST_CASE("pandarcap-bench write --json: PCD and pcap rates from one run", "[bench][cli]") {
  const auto result = test::run_command(bench() + " write --json --frames 3 --packets 5000");
  REQUIRE(result.exit_code == 0);
  const json report = json::parse(result.out);
  CHECK(report["points_per_frame"].get<std::size_t>() > 50'000);  // one simulated revolution
  for (const char* key : {"pcd_encode", "pcd_encode_and_write", "pcd_encode_lzf", "pcap_write"}) {
    INFO(key);
    CHECK(report[key]["items_per_s"].get<double>() > 0);
    CHECK(report[key]["mb_per_s"].get<double>() > 0);
  }
  // The frame cut's encoding, scalar and SIMD, for every layout (rates only: no timing claim).
  CHECK_FALSE(report["pcd_encode_simd"]["target"].get<std::string>().empty());
  for (const char* layout : {"pcl", "pandarcap", "velodyne", "autoware"}) {
    INFO(layout);
    CHECK(report["pcd_encode_simd"][layout]["scalar_points_per_cpu_s"].get<double>() > 0);
    CHECK(report["pcd_encode_simd"][layout]["simd_points_per_cpu_s"].get<double>() > 0);
  }
  // Both encodings' CPU a frame are measured, and LZF shrinks the simulated frame. Which costs
  // more is the bench's figure, not this test's claim: 3 frames on a loaded CI machine ordered
  // them the other way (5975 us for LZF against 6068, 2026-11-30).
  CHECK(report["pcd_cpu_us_per_frame"]["lzf"].get<double>() > 0);
  CHECK(report["pcd_cpu_us_per_frame"]["binary"].get<double>() > 0);
  CHECK(report["pcd_lzf_size_ratio"].get<double>() > 0);
  CHECK(report["pcd_lzf_size_ratio"].get<double>() < 1);
  // The sensor's share follows from the rates: 10 frames/s and 3600 packets/s.
  CHECK(report["sensor_pcap_cpu_fraction"].get<double>() ==
        Approx(3600.0 / report["pcap_write"]["items_per_cpu_s"].get<double>()));
}

TEST_CASE(
    "pandarcap-bench zero-loss: every sensor-rate summary shows what fell behind, and it adds up",
    "[bench][cli][threads][measures]") {
  test::ScratchDir dir("zero-loss-behind");
  // Far above one sensor's rate, so that stages may fall behind; the keys must be there either
  // way, and agree with the trials' per-stage loss.
  const auto result = run_report(
      dir, bench() + " zero-loss --json --sensor-rate-only --compare-mcap --sensor-rate 50000" +
               " --trial-seconds 1 --sensor-rate-rounds 1 --report-dir '" +
               (dir / "report").string() + "'");
  INFO(result.out);
  INFO(result.err);
  REQUIRE(result.exit_code == 0);
  const json report = json::parse(result.out);
  const json& s = report["at_sensor_rate"];
  const json& trials = report["trials"]["at_sensor_rate"];
  REQUIRE(trials.size() == 3);  // with the budget, budget 0, MCAP on
  const json* summaries[] = {&s, &s["budget_0"], &s["mcap_on"]};
  for (std::size_t i = 0; i < 3; ++i) {
    const json& summary = *summaries[i];
    const json& trial = trials[i];
    INFO("summary " << i << ": " << summary.dump());
    for (const char* key : {"lost", "frames_dropped", "pcap_not_recorded", "daemon_vs_bare_cpu"}) {
      INFO(key);
      REQUIRE(summary.contains(key));
      REQUIRE(trial.contains(key == std::string("daemon_vs_bare_cpu") ? "cpu_by_thread" : key));
    }
    const json& stages = trial["loss_by_stage"];
    CHECK(summary["frames_dropped"] == stages["frames_dropped"]);
    CHECK(summary["pcap_not_recorded"] == stages["pcap_packets_not_recorded"]);
    CHECK(summary["loss_by_stage"] == stages);
    CHECK(summary["lost"] == trial["lost"]);
    // Packets sent and never accepted: dropped by the kernel or the ring, rejected, or never
    // counted at all (clean traffic: no copies, nothing foreign).
    CHECK(summary["lost"].get<std::uint64_t>() == stages["kernel_drops"].get<std::uint64_t>() +
                                                      stages["ring_overruns"].get<std::uint64_t>() +
                                                      stages["rejected"].get<std::uint64_t>() +
                                                      stages["unaccounted"].get<std::uint64_t>());
    CHECK(summary["daemon_vs_bare_cpu"].get<double>() ==
          Approx(summary["cpu_fraction_of_one_core"].get<double>() /
                 s["bare_recvmmsg_cpu_fraction_of_one_core"].get<double>()));
  }
  CHECK(s["mcap_on"]["written_bytes"]["mcap"].get<std::uint64_t>() > 0);
  CHECK_THAT(md_text(dir / "report"),
             Catch::Contains("| lost | frames dropped | pcap not recorded |"));
}

TEST_CASE(
    "pandarcap-bench zero-loss --compare-tcpdump: the daemon and tcpdump -w in the same trials",
    "[bench][cli][threads][measures]") {
  if (::geteuid() != 0 || (!std::filesystem::exists("/usr/bin/tcpdump") &&
                           !std::filesystem::exists("/usr/sbin/tcpdump"))) {
    WARN("tcpdump needs root and /usr/bin/tcpdump: skipped");
    return;
  }
  test::ScratchDir dir("zero-loss-tcpdump");
  const auto config = dir / "frames-off.toml";
  std::ofstream(config) << "[output]\nframes = false\n";
  const auto result = run_report(
      dir, bench() + " zero-loss --json --sensor-rate-only --daemon-only --compare-tcpdump 2" +
               " --trial-seconds 1 --sensor-rate 1800 --config '" + config.string() +
               "' --report-dir '" + (dir / "report").string() + "'");
  INFO(result.out);
  INFO(result.err);
  REQUIRE(result.exit_code == 0);
  const json report = json::parse(result.out);
  const json& c = report["tcpdump_comparison"];
  REQUIRE(c["rounds"].size() == 2);
  REQUIRE(report["trials"]["beside_tcpdump"].size() == 2);
  double daemon = 0, tcpdump = 0;
  for (const json& round : c["rounds"]) {
    INFO(round.dump());
    // Both recorded the trial's packets (on a loaded machine either may fall behind: that is
    // reported, not asserted). tcpdump is stopped 1.2 s after the traffic, once its ring's 1 s
    // retire timer has handed it the last block; a tcpdump not scheduled by then leaves it out.
    CHECK(round["tcpdump_captured"].get<std::uint64_t>() > 0);
    CHECK(round["tcpdump_captured"].get<std::uint64_t>() <= round["sent"].get<std::uint64_t>());
    CHECK(round["tcpdump_dropped_by_kernel"].is_number());
    CHECK(round["daemon_pcap_not_recorded"].is_number());
    CHECK(round["daemon_pcap_bytes"].get<std::uint64_t>() > 100'000);
    CHECK(round["tcpdump_file_bytes"].get<std::uint64_t>() > 100'000);
    daemon += round["daemon_cpu_fraction_of_one_core"].get<double>();
    tcpdump += round["tcpdump_cpu_fraction_of_one_core"].get<double>();
  }
  CHECK(c["daemon_cpu_fraction_of_one_core"].get<double>() == Approx(daemon / 2));
  CHECK(c["tcpdump_cpu_fraction_of_one_core"].get<double>() == Approx(tcpdump / 2));
  if (tcpdump > 0) CHECK(c["daemon_vs_tcpdump_cpu"].get<double>() == Approx(daemon / tcpdump));
  CHECK(report["goals"].contains("cpu_recording_at_most_tcpdump_w"));
  CHECK_THAT(md_text(dir / "report"), Catch::Contains("Recording against `tcpdump -w`"));
}

TEST_CASE("pandarcap-bench zero-loss: the receiver and path options, refused when they clash",
          "[bench][cli]") {
  const auto refused = [](const std::string& options, const std::string& why) {
    const auto result = test::run_command(bench() + " zero-loss " + options + " 2>&1");
    INFO(options << ": " << result.out);
    CHECK(result.exit_code == 64);
    CHECK_THAT(result.out, Catch::Contains(why));
  };
  refused("--receiver bogus", "--receiver is socket or packet_ring, got 'bogus'");
  refused("--receiver", "--receiver");
  refused("--veth --interface eth0 --receiver packet_ring", "does not go with --interface");
  refused("--interface eth0", "give --receiver packet_ring");
  refused("--interface eth0 --receiver packet_ring", "--interface needs --destination IP");
  refused("--interface eth0 --compare-receivers", "--interface needs --destination IP");
  refused("--destination 10.0.0.1", "--destination goes with --interface");
  refused("--veth --foreign-fraction 0.1", "loopback only");
  refused("--interface eth0 --receiver packet_ring --destination 10.0.0", "an IPv4 address");
  // --veth makes interfaces and a namespace: as anyone but root, a usage error before anything.
  if (::geteuid() == 0) {
    const auto result = test::run_command("setpriv --reuid=65534 --regid=65534 --clear-groups -- " +
                                          bench() + " zero-loss --veth 2>&1");
    INFO(result.out);
    CHECK(result.exit_code == 64);
    CHECK_THAT(result.out, Catch::Contains("--veth") && Catch::Contains("run it as root"));
  }
  const auto help = test::run_command(bench() + " zero-loss --help");
  CHECK(help.exit_code == 0);
  for (const char* text : {"--receiver KIND", "--compare-receivers", "--veth", "--interface IFACE",
                           "path (loopback, veth or interface)", "generator_cpu_fraction"}) {
    CHECK_THAT(help.out, Catch::Contains(text));
  }
}

namespace {

// Whether `ip link show NAME` finds the interface, and `ip netns list` the namespace.
bool interface_exists(const std::string& name) {
  return test::run_command("ip link show '" + name + "' >/dev/null 2>&1").exit_code == 0;
}
bool namespace_exists(const std::string& name) {
  return test::run_command("ip netns list").out.find(name) != std::string::npos;
}

}  // namespace

TEST_CASE("pandarcap-bench zero-loss --veth: sent from a namespace of its own, nothing left behind",
          "[bench][cli][threads]") {
  if (::geteuid() != 0) {
    WARN("--veth needs root: skipped");
    return;
  }
  // Budget 0: the sensor-rate trial is also the budget-0 one, so one daemon trial in all.
  test::ScratchDir dir("zero-loss-veth");
  const auto result = run_report(
      dir, bench() + " zero-loss --veth --json --sensor-rate-only --daemon-only --trial-seconds 1" +
               " --latency-budget-ms 0 --sensor-rate 1800 --report-dir '" +
               (dir / "report").string() + "'");
  INFO(result.out);
  INFO(result.err);
  REQUIRE(result.exit_code == 0);
  const json report = json::parse(result.out);
  const json& settings = report["settings"];
  CHECK(settings["path"] == "veth");
  CHECK(settings["receiver"] == "socket");
  const std::string near = settings["interface"];
  const std::string space = settings["sender_namespace"];
  CHECK(near.rfind("pcb", 0) == 0);
  CHECK(space.rfind("/run/netns/pandarcap-bench-", 0) == 0);
  CHECK(settings["destination"].get<std::string>().rfind("10.231.", 0) == 0);
  // The daemon, bound to the near end's address, took every packet the far namespace sent.
  const json& s = report["at_sensor_rate"];
  CHECK(s["receiver"] == "socket");
  CHECK(s["lost"] == 0);
  CHECK(s["zero_loss"] == true);
  CHECK(report["trials"]["at_sensor_rate"][0]["sent"].get<std::uint64_t>() > 1000);
  CHECK(s["generator_cpu_fraction_of_one_core"].get<double>() > 0);
  CHECK(s["kernel"]["machine_softirq_cpu_fraction_of_one_core"].get<double>() >= 0);
  CHECK_THAT(md_text(dir / "report"), Catch::Contains("Path: **veth**"));
  // Both ends and the namespace are gone after the run.
  CHECK_FALSE(interface_exists(near));
  CHECK_FALSE(namespace_exists(space.substr(std::string("/run/netns/").size())));

  // Stopped by SIGTERM mid-trial: the daemon it runs stopped too, nothing left behind, and it ends
  // by that signal.
  harness::ChildProcess bench_run(test::binary("pandarcap-bench"),
                                  {"zero-loss", "--veth", "--json", "--sensor-rate-only",
                                   "--daemon-only", "--trial-seconds", "30"},
                                  dir / "stopped.log");
  const std::string pid = std::to_string(bench_run.pid());
  int daemon = 0;
  REQUIRE(harness::wait_until(
      [&] {
        std::istringstream children(
            harness::read_file("/proc/" + pid + "/task/" + pid + "/children"));
        for (int child = 0; children >> child;) {
          if (harness::read_file("/proc/" + std::to_string(child) + "/comm") == "pandarcapd\n") {
            daemon = child;
          }
        }
        return daemon != 0;
      },
      std::chrono::seconds(20)));
  bench_run.signal(SIGTERM);
  const auto status = bench_run.wait_exit(std::chrono::seconds(20));
  CHECK(status == -SIGTERM);
  CHECK_FALSE(std::filesystem::exists("/proc/" + std::to_string(daemon)));
  CHECK_FALSE(namespace_exists("pandarcap-bench-" + pid));
  CHECK_FALSE(interface_exists("pcb" + pid + "n"));
}

// The packet_ring receiver needs a pandarcapd that has it (--receiver): hidden until then; run
// with `pandarcap_tests "[compare_receivers]"`.
TEST_CASE("pandarcap-bench zero-loss --compare-receivers: socket and packet_ring in one run",
          "[bench][cli][threads][.compare_receivers]") {
  REQUIRE(::geteuid() == 0);
  test::ScratchDir dir("zero-loss-compare-receivers");
  for (const std::string path : {"", " --veth"}) {
    INFO("path:" << path);
    const auto result = run_report(
        dir, bench() + " zero-loss --json --sensor-rate-only --daemon-only --trial-seconds 1" +
                 " --latency-budget-ms 0 --sensor-rate 1800 --compare-receivers" + path);
    INFO(result.out);
    INFO(result.err);
    REQUIRE(result.exit_code == 0);
    const json report = json::parse(result.out);
    const json& s = report["at_sensor_rate"];
    CHECK(s["receiver"] == "socket");
    CHECK(s["lost"] == 0);
    REQUIRE(s.contains("packet_ring"));
    CHECK(s["packet_ring"]["receiver"] == "packet_ring");
    CHECK(s["packet_ring"]["lost"] == 0);
    // The ring watches the interface the packets arrive on: lo, or the veth's near end.
    const json& ring_trial = report["trials"]["at_sensor_rate"].back();
    CHECK(ring_trial["interface"] == report["settings"]["interface"]);
    const std::string interface = report["settings"]["interface"];
    CHECK(interface.rfind(path.empty() ? "lo" : "pcb", 0) == 0);
  }
}

TEST_CASE("pandarcap-bench send --sensor-model: every model at its own rate, one rotation",
          "[bench][cli]") {
  LoopbackSink sink;
  struct Case {
    std::string name;  // as a user types it: the case does not matter
    SensorModelId model;
    std::string options;
  };
  SECTION("each model's packets, checked one by one and through its stream decoder") {
    // Each run starts 200 packets before its one-second loop joins, so every run crosses the join;
    // 1200 RPM, so that 0.15 s holds whole revolutions.
    for (const Case& c : {Case{"pandar40p", SensorModelId::kPandar40P, ""},
                          Case{"PANDAR64", SensorModelId::kPandar64, ""},
                          Case{"PandarXT32", SensorModelId::kPandarXT32, ""},
                          Case{"pandarxt16", SensorModelId::kPandarXT16, " --return-mode first"},
                          Case{"PandarQT128", SensorModelId::kPandarQT128, ""},
                          Case{"pandarqt128", SensorModelId::kPandarQT128, " --no-sequence"}}) {
      INFO(c.name << c.options);
      with_model(c.model, [&]<class M>(std::type_identity<M>) {
        const bool single = c.options.find("--return-mode first") != std::string::npos;
        const ReturnMode mode = single ? ReturnMode::kFirst : ReturnMode::kDual;
        const int returns = returns_per_firing(mode);
        const double rate = M::packets_per_second(returns);
        const auto first = static_cast<std::uint64_t>(std::llround(rate)) - 200;
        const int rpm = M::kSupportedRpms.back();
        const std::string seconds = rpm >= 1200 ? "0.15" : "0.25";
        const auto result = test::run_command(
            bench() + " send --json --seconds " + seconds + " --rpm " + std::to_string(rpm) +
            " --sensor-model " + c.name + c.options + " --first-sequence " + std::to_string(first) +
            " --port " + std::to_string(sink.port()) + " 2>&1");
        INFO(result.out);
        REQUIRE(result.exit_code == 0);
        const json report = json::parse(result.out);
        CHECK(report["sensor_model"] == std::string(lower_case_name(c.model)));
        CHECK(report["offered_pps"].get<double>() == Approx(rate));  // the model's own rate
        const auto sent = report["sent"].get<std::uint64_t>();
        CHECK(sent > 200);  // across the join

        const auto datagrams = sink.take_all();
        REQUIRE(datagrams.size() == sent);
        std::uint64_t complete = 0;
        FrameCollector frames(
            3,
            static_cast<std::size_t>(M::packets_per_revolution(returns, rpm) * 1.2) *
                M::kMaxPointsPerPacket,
            [&](const Frame& frame) { complete += frame.info.partial ? 0 : 1; });
        AnyStreamDecoder decoder(c.model, Calibration::nominal(c.model), {}, frames);
        std::int64_t previous_time = 0;
        for (std::size_t i = 0; i < datagrams.size(); ++i) {
          INFO("packet " << i);
          const std::span<const std::uint8_t> p(datagrams[i]);
          REQUIRE(p.size() == report["packet_bytes"].get<std::size_t>());
          REQUIRE(M::validate(p) == RejectReason::kNone);
          CHECK(M::return_mode(p) == mode);
          CHECK(M::motor_rpm(p) == Approx(rpm).margin(5));
          if (c.options == " --no-sequence") {
            CHECK_FALSE(M::sequence(p));
          } else {
            CHECK(M::sequence(p) == std::optional<std::uint32_t>(first + i));
          }
          REQUIRE(decoder.process(p) == RejectReason::kNone);
          // The clock runs: one packet period from the one before (to the tail's µs), the join
          // included.
          const std::int64_t t = decoder.stats().last_t0_ns;
          if (i > 0) CHECK(std::abs(t - previous_time - M::packet_period_ns(returns)) <= 1000);
          previous_time = t;
        }
        decoder.flush();
        const StreamStats& stats = decoder.stats();
        CHECK(stats.accepted == sent);
        CHECK(stats.outliers == 0);
        CHECK(stats.stream_changes == 0);
        CHECK(stats.azimuth_gaps == 0);
        CHECK(stats.backward_timestamps + stats.timestamp_jumps + stats.static_timestamps == 0);
        CHECK(decoder.sequence().lost == 0);
        CHECK(decoder.frames().discontinuities == 0);
        CHECK(complete >= 1);
      });
    }
  }
  SECTION("a speed, mode or option the model does not have is a usage error") {
    for (const std::string& options : {std::string(" --sensor-model pandar64 --return-mode first"),
                                       std::string(" --sensor-model PandarXT32 --rpm 300"),
                                       std::string(" --sensor-model pandarxt16 --no-sequence"),
                                       std::string(" --sensor-model hdl32")}) {
      INFO(options);
      const auto result = test::run_command(bench() + " send" + options + " --seconds 0.1 --port " +
                                            std::to_string(sink.port()) + " 2>&1");
      CHECK(result.exit_code == 64);
      CHECK_THAT(result.out, Catch::Contains("Try 'pandarcap-bench send --help'"));
    }
    CHECK(sink.take_all().empty());
  }
}

// The hostile tester's tests of the zero-loss work directory (2077f82: $TMPDIR or /var/tmp,
// trials' outputs emptied after each trial and removed at the run's end).
namespace {

// Every path under `dir`, one a line (what a failing CHECK shows).
std::string listing(const std::filesystem::path& dir) {
  std::string out;
  std::error_code ec;
  for (std::filesystem::recursive_directory_iterator it(dir, ec), end; !ec && it != end;
       it.increment(ec)) {
    out += it->path().string() + "\n";
  }
  return out;
}

// How a run ended, and what it printed: what a failing check on its exit status shows.
std::string ended(const std::optional<int>& status, const harness::ChildProcess& run) {
  return "exit status " + (status ? std::to_string(*status) : std::string("none")) + ", log:\n" +
         run.log();
}

// The pids of the processes whose command line names `path` (a run's daemon, tcpdump, guard).
std::vector<int> processes_naming(const std::filesystem::path& path) {
  std::vector<int> pids;
  for (const int pid : test::process_ids()) {
    const std::string line = harness::read_file("/proc/" + std::to_string(pid) + "/cmdline");
    if (line.find(path.string()) != std::string::npos) pids.push_back(pid);
  }
  return pids;
}

}  // namespace

// A run stopped by SIGINT (a user's ^C, what the harness handles with StopOnSignal) leaves
// nothing: not its work directory (in /var/tmp, which no boot cleans, unless $TMPDIR is set), not
// a finished trial's outputs (emptied, removed only when the run ends: the guard removes them
// when a signal ends it), not a daemon. A hostile test saw 40 files left (39 of them daemon_000's
// emptied frames and recordings) and, signalling as the second trial's directory appeared, a
// pandarcapd left running with parent 1: forked, not yet registered with the handler. This
// signals at that moment.
TEST_CASE("pandarcap-bench zero-loss stopped by SIGINT: no trial's files and no daemon left",
          "[bench][cli][threads]") {
  test::ScratchDir dir("zero-loss-sigint-work");
  const auto tmpdir = dir / "tmp";
  std::filesystem::create_directories(tmpdir);
  harness::ChildProcess bench_run(test::binary("pandarcap-bench"),
                                  {"zero-loss", "--json", "--daemon-only", "--sensor-rate-only",
                                   "--trial-seconds", "0.5", "--sensor-rate", "1800"},
                                  dir / "bench.log", {"TMPDIR=" + tmpdir.string()});
  const auto work = tmpdir / fmt::format("pandarcap-bench-{}", bench_run.pid());
  REQUIRE(harness::wait_until([&] { return std::filesystem::exists(work / "daemon_001"); },
                              std::chrono::seconds(30)));
  bench_run.signal(SIGINT);
  const std::optional<int> status = bench_run.wait_exit(std::chrono::seconds(20));
  INFO(ended(status, bench_run));
  CHECK(status == -SIGINT);
  INFO(listing(tmpdir));
  CHECK_FALSE(std::filesystem::exists(work));
  // No process of the run's left: none has the work directory on its command line.
  const std::vector<int> left = processes_naming(work);
  INFO("left running: " << left.size());
  CHECK(left.empty());
}

// $TMPDIR naming no directory is refused, as mktemp(1) and std::filesystem::temp_directory_path()
// refuse it; a hostile test saw the bench make it, every missing parent with it, and leave them.
// And a run that fails leaves no work directory in a $TMPDIR that exists.
TEST_CASE("pandarcap-bench zero-loss with a $TMPDIR that does not exist, or a run that fails",
          "[bench][cli][threads]") {
  test::ScratchDir dir("zero-loss-tmpdir-missing");
  const auto missing = dir / "missing";
  const auto result = test::run_command(
      "TMPDIR='" + (missing / "deeper").string() + "' " + bench() +
      " zero-loss --json --daemon-only --sensor-rate-only --trial-seconds 0.5"
      " --receiver packet_ring --interface lo --destination 127.0.0.1 --daemon /bin/true 2>&1");
  INFO(result.out);
  INFO(listing(dir.path()));
  CHECK(result.exit_code != 0);
  CHECK_FALSE(std::filesystem::exists(missing));
  CHECK_THAT(result.out, Catch::Contains("is not a directory"));
  // The same run with a $TMPDIR that exists: it fails (the daemon has no --receiver) and
  // removes its work directory.
  const auto tmpdir = dir / "tmp";
  std::filesystem::create_directories(tmpdir);
  const auto failed = test::run_command(
      "TMPDIR='" + tmpdir.string() + "' " + bench() +
      " zero-loss --json --daemon-only --sensor-rate-only --trial-seconds 0.5"
      " --receiver packet_ring --interface lo --destination 127.0.0.1 --daemon /bin/true 2>&1");
  INFO(failed.out);
  CHECK(failed.exit_code != 0);
  CHECK(std::filesystem::is_empty(tmpdir));
}

// With --work-dir the trials' logs stay and their outputs go, on a signal too (the guard removes
// daemon_*/out). tcpdump's recording of a --compare-tcpdump round is such an output (a finished
// round removes it), but it lives in daemon_NNN/, not in out/: a SIGINT during that round leaves
// it, as big as the round made it. Every time.
TEST_CASE("zero-loss --work-dir stopped by SIGINT in a tcpdump round keeps no recording",
          "[bench][cli][signals][threads]") {
  test::ScratchDir dir("zero-loss-sigint-tcpdump");
  const auto work = dir / "work";
  harness::ChildProcess bench_run(
      test::binary("pandarcap-bench"),
      {"zero-loss", "--json", "--daemon-only", "--sensor-rate-only", "--trial-seconds", "5",
       "--sensor-rate", "1800", "--compare-tcpdump", "1", "--work-dir", work.string()},
      dir / "bench.log");
  // tcpdump listening and recording the round's traffic.
  REQUIRE(harness::wait_until(
      [&] {
        std::error_code ec;
        for (const auto& entry : std::filesystem::directory_iterator(work, ec)) {
          if (harness::read_file(entry.path() / "tcpdump.log").find("listening on") !=
              std::string::npos) {
            return true;
          }
        }
        return false;
      },
      std::chrono::seconds(60)));
  bench_run.signal(SIGINT);
  const std::optional<int> status = bench_run.wait_exit(std::chrono::seconds(20));
  INFO(ended(status, bench_run));
  CHECK(status == -SIGINT);
  CHECK_THAT(listing(work), Catch::Contains("/daemon.log\n"));  // the logs are kept
  CHECK_THAT(listing(work), !Catch::Contains("/tcpdump.pcap\n"));
  CHECK(processes_naming(work).empty());
}

// A harness started with SIGINT ignored (a background job of a non-interactive shell, `cmd &`,
// which POSIX shells make immune to the terminal's ^C) must stay immune: the clean-up handler is
// for a SIGINT that would have stopped it. StopOnSignal installs its handler over the inherited
// SIG_IGN, so the same SIGINT is ignored during start-up and stops the run once the first trial
// is under way. Every time.
TEST_CASE("zero-loss started with SIGINT ignored is not stopped by SIGINT",
          "[bench][cli][signals][threads]") {
  test::ScratchDir dir("zero-loss-sigint-ignored");
  const auto work = dir / "work";
  const std::string command =
      "trap '' INT; exec " + bench() +
      " zero-loss --json --daemon-only --sensor-rate-only --trial-seconds 0.5 --sensor-rate 1800"
      " --work-dir " +
      test::quoted(work);
  harness::ChildProcess bench_run("/bin/sh", {"-c", command}, dir / "bench.log");
  REQUIRE(harness::wait_until(
      [&] { return std::filesystem::exists(work / "daemon_000" / "daemon.log"); },
      std::chrono::seconds(30)));
  bench_run.signal(SIGINT);
  const std::optional<int> status = bench_run.wait_exit(std::chrono::seconds(60));
  INFO(ended(status, bench_run));
  CHECK(status == 0);
  for (const int pid : processes_naming(work))
    ::kill(pid, SIGKILL);
}

// A terminal that hangs up (an ssh session dropped during a long run) sends SIGHUP to the job's
// process group. The harness has no clean-up for it and dies; its guard dies with it (it ignores
// only SIGINT and SIGTERM) and removes nothing; and pandarcapd takes SIGHUP as "rotate the
// recordings" and keeps running, orphaned, writing into the work directory left in $TMPDIR (by
// default /var/tmp). Every time.
TEST_CASE("zero-loss whose terminal hangs up leaves no daemon and no work directory",
          "[bench][cli][signals][threads]") {
  test::ScratchDir dir("zero-loss-sighup-group");
  const auto tmpdir = dir / "tmp";
  std::filesystem::create_directories(tmpdir);
  // In a session and process group of its own (setsid execs it in place: same pid), as a job.
  harness::ChildProcess bench_run(
      "/usr/bin/setsid",
      {test::binary("pandarcap-bench").string(), "zero-loss", "--json", "--daemon-only",
       "--sensor-rate-only", "--trial-seconds", "5", "--sensor-rate", "1800"},
      dir / "bench.log", {"TMPDIR=" + tmpdir.string()});
  const auto work = tmpdir / fmt::format("pandarcap-bench-{}", bench_run.pid());
  REQUIRE(harness::wait_until(
      [&] {
        return harness::read_file(work / "daemon_000" / "daemon.log").find("ready:") !=
                   std::string::npos &&
               ::getpgid(bench_run.pid()) == bench_run.pid();
      },
      std::chrono::seconds(30)));
  ::kill(-bench_run.pid(), SIGHUP);
  const std::optional<int> status = bench_run.wait_exit(std::chrono::seconds(20));
  INFO(ended(status, bench_run));
  CHECK(status == -SIGHUP);
  // The handler's clean-up, had there been one, is done once the work directory is gone.
  harness::wait_until([&] { return !std::filesystem::exists(work); }, std::chrono::seconds(10));
  INFO(listing(tmpdir));
  CHECK_FALSE(std::filesystem::exists(work));
  const std::vector<int> left = processes_naming(work);
  INFO("left running: " << left.size());
  CHECK(left.empty());
  for (const int pid : left)
    ::kill(pid, SIGKILL);
}
