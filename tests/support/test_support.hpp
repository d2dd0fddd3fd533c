// Shared helpers for the test suite: locating the real captures and scratch directories.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <map>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/frames/frame.hpp"
#include "core/frames/pcd.hpp"
#include "daemon/pcap/capture_reader.hpp"

namespace pandarcap::harness {
class ChildProcess;
}  // namespace pandarcap::harness

namespace pandarcap::test {

// 360° in the sensor's 0.01° units.
inline constexpr std::int64_t kCircle = 36000;

// Sanitizer builds run the daemon several times slower: under TSan, at one sensor's rate, its
// writer alone takes ~75 % of a core and the simulated sensor ~65 %. On a 2-core machine a
// real-time stream then outruns it (alone, or beside another test), and it does what it does
// live: it drops and counts (pcap_packets_not_recorded, frames_dropped_no_arena, kernel_drops).
// The release job requires zero loss in the tests that stream in real time; the slow builds'
// jobs (kSlowBuild), which are there for memory errors, races and another architecture, require
// that every loss is counted.
#if defined(__SANITIZE_THREAD__)
inline constexpr bool kThreadSanitizerBuild = true;
#else
inline constexpr bool kThreadSanitizerBuild = false;
#endif
// kSanitizerBuild: what only a sanitizer's builds have (their own allocator and address space).
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
inline constexpr bool kSanitizerBuild = true;
#else
inline constexpr bool kSanitizerBuild = false;
#endif
// The ARM64 job's daemon is as slow: QEMU emulates it, beside three other emulated test runs on
// 2 cores, and its simulated sensor there fell to 2487 datagrams in 1.5 s where it sends 5400
// (CI, 2026-11-30). Those builds are slow builds too (tests/CMakeLists.txt: PANDARCAP_EMULATED).
#if defined(PANDARCAP_EMULATED)
inline constexpr bool kSlowBuild = true;
#else
inline constexpr bool kSlowBuild = kSanitizerBuild;
#endif

// Division and remainder rounded toward minus infinity (azimuths before the cut are negative).
inline std::int64_t floor_div(std::int64_t a, std::int64_t b) {
  return a >= 0 ? a / b : -((-a + b - 1) / b);
}
inline std::int64_t floor_mod(std::int64_t a, std::int64_t b) {
  return a - floor_div(a, b) * b;
}

// Path of a real capture in ../shared/captures. When the file is missing the test must not pass
// silently in CI: under CI=true this FAILs the test; elsewhere it WARNs and returns nullopt so
// the caller can return early.
std::optional<std::filesystem::path> real_capture(const std::string& name);

// Every UDP payload of a capture file, in order (REQUIREs that the file reads to its end).
std::vector<std::vector<std::uint8_t>> capture_payloads(const std::filesystem::path& path);

// A fresh, empty directory under the system temp dir, removed by the destructor.
class ScratchDir {
 public:
  explicit ScratchDir(const std::string& tag);
  ~ScratchDir();
  ScratchDir(const ScratchDir&) = delete;
  ScratchDir& operator=(const ScratchDir&) = delete;
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& name) const { return path_ / name; }

 private:
  std::filesystem::path path_;
};

// Path of a built binary (pandarcap-inspect, pandarcapd).
std::filesystem::path binary(const std::string& name);

// `path` in single quotes, for the shell commands the tests run (run_command).
std::string quoted(const std::filesystem::path& path);
// `bytes` written to `path`, replacing it.
void write_bytes(const std::filesystem::path& path, std::string_view bytes);
// The byte offset of record `index`'s header in a classic pcap's bytes (PcapWriter's layout):
// where a test cuts or damages a recording.
std::size_t pcap_record_offset(std::string_view pcap, std::size_t index);

// Runs a command through /bin/sh, returning its exit status and standard output.
struct CommandResult {
  int exit_code = -1;
  std::string out;
};
CommandResult run_command(const std::string& command);

// Every complete (newline-ended) non-empty line of a JSON-lines file (pandarcapd's health.jsonl),
// parsed. A line that does not parse fails the test (CHECK) and is left out. Text after the last
// newline is not a line yet: a running daemon may be appending it while the test reads (a read
// racing a write() can see its first part), so it is left out, as a tailing reader would. No
// file: no lines.
std::vector<nlohmann::json> json_lines(const std::filesystem::path& file);
// The health records of a run with the default health directory: OUTPUT_DIR/health/health.jsonl.
std::vector<nlohmann::json> health_records(const std::filesystem::path& output_dir);

// The newest of those records; null when there is none yet.
nlohmann::json last_health_record(const std::filesystem::path& output_dir);

// The daemon as the shell commands of the tests run it. --allow-root: the tests (and CI) may run
// as root; the refusal itself is tested in test_privileges.cpp.
// /proc/PID/task/*: thread name -> {Cpus_allowed_list, scheduling policy (0 other, 1 FIFO)}.
struct ThreadState {
  std::string cpus;
  int policy = -1;
};
std::map<std::string, ThreadState> threads_of(int pid);
// Every process's pid (the numeric entries of /proc): what a test looks through for what a run
// left running.
std::vector<int> process_ids();

std::string pandarcapd_command();

// A counter of a health record (its "counters" object); 0 when absent or not a record.
std::uint64_t health_counter(const nlohmann::json& record, std::string_view name);

// The parts of a health reason, each problem it names ("3 kernel drops; packet rate ..."): views
// into `reason`.
std::vector<std::string_view> reason_parts(std::string_view reason);

// Whether a part of a health reason says the sensor's clock is behind the host's by no more than
// `max_s` seconds ("sensor clock off by 1.354 s (behind the host): not synchronised?"): what a
// simulated sensor starved on a loaded machine says, its packets sent late. It can be behind by
// no more than the time it has run; ahead of the host, or further behind, is a clock fault.
bool clock_behind_by_at_most(std::string_view part, double max_s);

// Waits (`timeout` at most) until the newest health record of OUTPUT_DIR counts `total`
// datagrams received or dropped by the kernel; whether it did.
bool wait_until_counted(const std::filesystem::path& output_dir, std::uint64_t total,
                        std::chrono::milliseconds timeout);

// The ring overruns a test that streams in real time allows: none, except under
// ThreadSanitizer, whose decode thread (every point it encodes is instrumented) may fall behind
// on a busy machine; the ring then overflows, counted, and an overflowed datagram is neither
// accepted nor recorded. Checks (CHECK) that the record has no others, and returns them for the
// test's identities.
std::uint64_t check_ring_overruns(const nlohmann::json& record);

// Health records come once a second: consecutive ones are more than `min_gap_s` and at most
// 1.5 s apart by their monotonic uptime. The final record (written at shutdown) may follow the
// one before it sooner, so its gap is not checked; so may a record whose state differs from the
// one before (the writer reports packets stopping or starting again at once).
void check_record_spacing(const std::vector<nlohmann::json>& records, double min_gap_s);

// `promtool check metrics` on a Prometheus text file: exit status 0 and nothing said, no lint
// note either (every metric in base units). `output` gets what promtool said.
bool promtool_accepts(const std::filesystem::path& file, std::string& output);

// The samples of a Prometheus text ("name{labels} value" lines), keyed by "name{labels}";
// comment lines skipped. A sample line without a value fails the test.
std::map<std::string, std::string> prom_samples(const std::string& text);

// The points of a PCD file in the pandarcap layout (--pcd-fields pandarcap, the MCAP messages'
// layout), decoded. Fails the test when the file has no data section or a partial point.
std::vector<PcdPoint> pandarcap_pcd_points(const std::filesystem::path& file);

// A PCD file's frame_reference_time, in seconds (the comment pandarcap writes on the header's
// second line), read from the header alone: a whole frame is megabytes, and a test under TSan
// pays for every byte it copies. Fails the test when the header has none.
double pcd_reference_time(const std::filesystem::path& file);

// Every packet of a capture decoded with the calibration file `calibration_csv` (a
// StreamDecoder with the default configuration), its frames into `frames`, flushed at the end.
void decode_capture(const std::filesystem::path& capture,
                    const std::filesystem::path& calibration_csv, FrameSink& frames);

// The files directly in `dir` whose names end in `suffix` (".pcd", ".pcap"), sorted. No
// directory: none.
std::vector<std::filesystem::path> files_ending(const std::filesystem::path& dir,
                                                const std::string& suffix);

// How many file descriptors process `pid` has open (/proc/PID/fd).
std::size_t open_descriptors(int pid);

// Holds the writer of `daemon`, a pandarcapd started with PANDARCAP_TEST_STALL_WRITER_FILE=`stall`:
// creates `stall` and waits, up to `timeout`, for the daemon to say its writer stopped (at its
// next tick, a second at most). True once it has; removing `stall` lets the writer go on.
bool stall_writer(const harness::ChildProcess& daemon, const std::filesystem::path& stall,
                  std::chrono::milliseconds timeout);

// `packets` of the simulated sensor (dual return, 600 RPM) from `start_unix_ns` on, recorded at
// `path` as a host received them: each record 300 us after the packet's own time (a synchronised
// sensor), from `from` to `to`. Returns `path`.
std::filesystem::path write_simulated_recording(const std::filesystem::path& path, int packets,
                                                std::int64_t start_unix_ns, Endpoint from,
                                                Endpoint to);

// Reads a capture to its end: how the read ended and how many records it held.
std::pair<CaptureStatus, std::size_t> read_capture(const std::filesystem::path& file);

// A small file system for a test alone: the arguments for /usr/bin/unshare that mount a tmpfs of
// `size` ("48m") at `mount_point` in a private mount namespace (as root directly, otherwise in a
// user namespace where this user is root) and run `program args...` there. Empty when this
// machine cannot make a mount namespace (the caller says so, WARN, and returns). From outside,
// the mount is seen at /proc/PID/root/MOUNT_POINT (tmpfs_view) while PID runs.
//   - plain: `program` is exec'd: one process, one pid (the ChildProcess's);
//   - `keep_after`: a shell runs it, writes its pid to MOUNT_POINT.pid (tmpfs_program_pid), and
//     when it ends copies MOUNT_POINT/health and MOUNT_POINT/raw into MOUNT_POINT.after/ (the
//     mount goes with the namespace) and exits with its status.
std::vector<std::string> tmpfs_run_args(const std::filesystem::path& mount_point,
                                        const std::string& size,
                                        const std::filesystem::path& program,
                                        const std::vector<std::string>& args,
                                        bool keep_after = false);
std::filesystem::path tmpfs_view(int pid, const std::filesystem::path& mount_point);
// The pid of a keep_after run's program, once its shell has written it (0 after 10 s without).
int tmpfs_program_pid(const std::filesystem::path& mount_point);

}  // namespace pandarcap::test
