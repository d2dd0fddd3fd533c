#include "support/test_support.hpp"

#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <catch2/catch.hpp>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>

#include "bench/child_process.hpp"
#include "core/decode/calibration.hpp"
#include "core/decode/stream_decoder.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "daemon/io/calibration_file.hpp"
#include "daemon/pcap/pcap_writer.hpp"

namespace pandarcap::test {

std::optional<std::filesystem::path> real_capture(const std::string& name) {
  std::filesystem::path path = std::filesystem::path(PANDARCAP_CAPTURES_DIR) / name;
  if (std::filesystem::exists(path)) return path;
  const char* ci = std::getenv("CI");
  if (ci != nullptr && std::string(ci) == "true") {
    FAIL("real capture missing under CI=true: " << path.string());
  }
  WARN("real capture not found, test body not run: " << path.string());
  return std::nullopt;
}

std::vector<std::vector<std::uint8_t>> capture_payloads(const std::filesystem::path& path) {
  CaptureReader reader(path.string());
  std::vector<std::vector<std::uint8_t>> payloads;
  CaptureRecord record;
  CaptureStatus status;
  while ((status = reader.next(record)) == CaptureStatus::kRecord)
    payloads.emplace_back(record.payload.begin(), record.payload.end());
  REQUIRE(status == CaptureStatus::kEnd);
  return payloads;
}

ScratchDir::ScratchDir(const std::string& tag) {
  std::random_device rd;
  path_ = std::filesystem::temp_directory_path() /
          ("pandarcap-test-" + tag + "-" + std::to_string(::getpid()) + "-" + std::to_string(rd()));
  std::filesystem::create_directories(path_);
}

ScratchDir::~ScratchDir() {
  std::error_code ec;
  std::filesystem::remove_all(path_, ec);
}

std::filesystem::path binary(const std::string& name) {
  return std::filesystem::path(PANDARCAP_BIN_DIR) / name;
}

std::string quoted(const std::filesystem::path& path) {
  return "'" + path.string() + "'";
}

void write_bytes(const std::filesystem::path& path, std::string_view bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc)
      .write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

std::size_t pcap_record_offset(std::string_view pcap, std::size_t index) {
  std::size_t at = kPcapGlobalHeaderBytes;
  for (std::size_t i = 0; i < index; ++i) {
    std::uint32_t captured = 0;
    std::memcpy(&captured, pcap.data() + at + 8, 4);
    at += kPcapRecordHeaderBytes + captured;
  }
  return at;
}

CommandResult run_command(const std::string& command) {
  CommandResult result;
  std::FILE* pipe = ::popen(command.c_str(), "r");
  REQUIRE(pipe != nullptr);
  std::array<char, 4096> buffer{};
  std::size_t n = 0;
  while ((n = std::fread(buffer.data(), 1, buffer.size(), pipe)) > 0)
    result.out.append(buffer.data(), n);
  const int status = ::pclose(pipe);
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  return result;
}

std::vector<nlohmann::json> json_lines(const std::filesystem::path& file) {
  std::ifstream in(file);
  std::vector<nlohmann::json> lines;
  for (std::string line; std::getline(in, line);) {
    if (in.eof()) break;  // no newline after it: still being written
    if (line.empty()) continue;
    INFO(file.string() << ": " << line);
    nlohmann::json parsed = nlohmann::json::parse(line, nullptr, false);
    CHECK_FALSE(parsed.is_discarded());
    if (!parsed.is_discarded()) lines.push_back(std::move(parsed));
  }
  return lines;
}

std::vector<nlohmann::json> health_records(const std::filesystem::path& output_dir) {
  return json_lines(output_dir / "health" / "health.jsonl");
}

nlohmann::json last_health_record(const std::filesystem::path& output_dir) {
  // Only the last whole line is parsed: the waits poll this every few milliseconds, and parsing
  // every record each time took half a core beside the daemon under test.
  const std::filesystem::path file = output_dir / "health" / "health.jsonl";
  const std::string text = harness::read_file(file);
  std::size_t end = text.rfind('\n');  // a line without its newline is being written
  while (end != std::string::npos && end > 0 && text[end - 1] == '\n')
    --end;  // empty lines are not records
  if (end == std::string::npos || end == 0) return nlohmann::json();
  const std::size_t begin = end == 0 ? std::string::npos : text.rfind('\n', end - 1);
  const std::string line = text.substr(begin == std::string::npos ? 0 : begin + 1,
                                       end - (begin == std::string::npos ? 0 : begin + 1));
  INFO(file.string() << ": " << line);
  nlohmann::json parsed = nlohmann::json::parse(line, nullptr, false);
  CHECK_FALSE(parsed.is_discarded());
  return parsed.is_discarded() ? nlohmann::json() : parsed;
}

std::string pandarcapd_command() {
  return binary("pandarcapd").string() + " --allow-root";
}

std::uint64_t check_ring_overruns(const nlohmann::json& record) {
  const std::uint64_t allowed = kThreadSanitizerBuild ? health_counter(record, "ring_overruns") : 0;
  CHECK(health_counter(record, "ring_overruns") == allowed);
  return allowed;
}

std::vector<std::string_view> reason_parts(std::string_view reason) {
  std::vector<std::string_view> parts;
  for (std::size_t at = 0; at < reason.size();) {
    const std::size_t end = std::min(reason.find("; ", at), reason.size());
    parts.push_back(reason.substr(at, end - at));
    at = end + 2;
  }
  return parts;
}

bool clock_behind_by_at_most(std::string_view part, double max_s) {
  constexpr std::string_view kStart = "sensor clock off by ";
  constexpr std::string_view kBehind = " s (behind the host): not synchronised?";
  if (!part.starts_with(kStart) || !part.ends_with(kBehind)) return false;
  const std::string number(
      part.substr(kStart.size(), part.size() - kStart.size() - kBehind.size()));
  char* end = nullptr;
  const double seconds = std::strtod(number.c_str(), &end);
  return end == number.c_str() + number.size() && !number.empty() && seconds >= 0 &&
         seconds <= max_s;
}

std::uint64_t health_counter(const nlohmann::json& record, std::string_view name) {
  if (!record.is_object() || !record.contains("counters")) return 0;
  return record["counters"].value(std::string(name), std::uint64_t{0});
}

bool wait_until_counted(const std::filesystem::path& output_dir, std::uint64_t total,
                        std::chrono::milliseconds timeout) {
  return harness::wait_until(
      [&] {
        const nlohmann::json last = last_health_record(output_dir);
        return !last.is_null() &&
               health_counter(last, "datagrams_received") + health_counter(last, "kernel_drops") >=
                   total;
      },
      timeout);
}

void check_record_spacing(const std::vector<nlohmann::json>& records, double min_gap_s) {
  for (std::size_t i = 1; i + 1 < records.size(); ++i) {
    const double gap = records[i]["gauges"]["uptime_seconds"].get<double>() -
                       records[i - 1]["gauges"]["uptime_seconds"].get<double>();
    INFO("records " << i - 1 << " and " << i << " are " << gap << " s apart");
    // The writer says at once when packets stop or start again (a new state), without waiting
    // for the second's tick: such a record may follow the one before it sooner.
    const bool state_changed = records[i].value("state", "") != records[i - 1].value("state", "");
    if (!state_changed) CHECK(gap > min_gap_s);
    CHECK(gap <= 1.5);
  }
}

bool promtool_accepts(const std::filesystem::path& file, std::string& output) {
  const CommandResult result = run_command("promtool check metrics < '" + file.string() + "' 2>&1");
  output = result.out;
  return result.exit_code == 0 && result.out.empty();
}

std::map<std::string, std::string> prom_samples(const std::string& text) {
  std::map<std::string, std::string> out;
  std::istringstream in(text);
  std::string line;
  while (std::getline(in, line)) {
    if (line.empty() || line[0] == '#') continue;
    const auto space = line.rfind(' ');
    REQUIRE(space != std::string::npos);
    out[line.substr(0, space)] = line.substr(space + 1);
  }
  return out;
}

double pcd_reference_time(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::string header(512, '\0');
  in.read(header.data(), static_cast<std::streamsize>(header.size()));
  header.resize(static_cast<std::size_t>(in.gcount()));
  const std::string key = "# pandarcap frame_reference_time ";
  const auto at = header.find(key);
  INFO(file.string());
  REQUIRE(at != std::string::npos);
  return std::stod(header.substr(at + key.size(), 30));
}

std::vector<PcdPoint> pandarcap_pcd_points(const std::filesystem::path& file) {
  const std::string bytes = harness::read_file(file);
  const std::size_t data = bytes.find("DATA binary\n");
  REQUIRE(data != std::string::npos);
  const std::size_t begin = data + 12;
  REQUIRE((bytes.size() - begin) % kPcdPointBytes == 0);
  std::vector<PcdPoint> points;
  for (std::size_t at = begin; at < bytes.size(); at += kPcdPointBytes) {
    points.push_back(decode_pcd_point(std::span<const std::uint8_t, kPcdPointBytes>(
        reinterpret_cast<const std::uint8_t*>(bytes.data() + at), kPcdPointBytes)));
  }
  return points;
}

void decode_capture(const std::filesystem::path& capture,
                    const std::filesystem::path& calibration_csv, FrameSink& frames) {
  StreamDecoder decoder(load_calibration(calibration_csv.string()), {}, frames);
  CaptureReader reader(capture.string());
  CaptureRecord record;
  while (reader.next(record) == CaptureStatus::kRecord)
    decoder.process(record.payload);
  decoder.flush();
}

std::vector<std::filesystem::path> files_ending(const std::filesystem::path& dir,
                                                const std::string& suffix) {
  std::vector<std::filesystem::path> files;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(dir, ec)) {
    if (entry.path().native().ends_with(suffix)) files.push_back(entry.path());
  }
  std::sort(files.begin(), files.end());
  return files;
}

std::size_t open_descriptors(int pid) {
  std::size_t n = 0;
  std::error_code ec;
  for (auto it = std::filesystem::directory_iterator("/proc/" + std::to_string(pid) + "/fd", ec);
       it != std::filesystem::directory_iterator(); it.increment(ec))
    ++n;
  return n;
}

bool stall_writer(const harness::ChildProcess& daemon, const std::filesystem::path& stall,
                  std::chrono::milliseconds timeout) {
  std::ofstream(stall).put('\n');
  return harness::wait_until([&] { return daemon.logged("test hook: writer stalled"); }, timeout);
}

std::filesystem::path write_simulated_recording(const std::filesystem::path& path, int packets,
                                                std::int64_t start_unix_ns, Endpoint from,
                                                Endpoint to) {
  SyntheticSensorConfig config;
  config.start_unix_ns = start_unix_ns;
  SyntheticSensor sensor(config);
  std::array<std::uint8_t, kMaxPacketBytes> packet{};
  PcapWriter pcap(path.string());
  for (int i = 0; i < packets; ++i) {
    const std::size_t size = sensor.next(packet);
    pcap.write({packet.data(), size}, sensor.last_packet_time_ns() + 300'000, from, to);
  }
  pcap.close();
  return path;
}

std::pair<CaptureStatus, std::size_t> read_capture(const std::filesystem::path& file) {
  CaptureReader reader(file.string());
  CaptureRecord record;
  std::size_t records = 0;
  CaptureStatus status;
  while ((status = reader.next(record)) == CaptureStatus::kRecord)
    ++records;
  return {status, records};
}

std::vector<std::string> tmpfs_run_args(const std::filesystem::path& mount_point,
                                        const std::string& size,
                                        const std::filesystem::path& program,
                                        const std::vector<std::string>& args, bool keep_after) {
  const std::string userns = ::geteuid() == 0 ? "" : "--user --map-root-user ";
  if (run_command("unshare " + userns + "--mount true 2>/dev/null").exit_code != 0) return {};
  std::vector<std::string> out;
  if (::geteuid() != 0) out = {"--user", "--map-root-user"};
  for (const std::string& arg :
       {std::string("--mount"), std::string("--propagation"), std::string("private"),
        std::string("--"), std::string("/bin/sh"), std::string("-c"),
        "mount -t tmpfs -o size=" + size + " pandarcap-test \"$0\" && " +
            (keep_after ? std::string("{ \"$@\" & pid=$!; echo $pid >\"$0.pid\"; wait $pid; "
                                      "status=$?; mkdir -p \"$0.after\"; "
                                      "cp -r \"$0/health\" \"$0/raw\" \"$0.after/\" 2>/dev/null; "
                                      "exit $status; }")
                        : std::string("exec \"$@\"")),
        mount_point.string(), program.string()})
    out.push_back(arg);
  out.insert(out.end(), args.begin(), args.end());
  return out;
}

int tmpfs_program_pid(const std::filesystem::path& mount_point) {
  const std::filesystem::path file = mount_point.string() + ".pid";
  int pid = 0;
  harness::wait_until(
      [&] {
        std::ifstream in(file);
        return static_cast<bool>(in >> pid) && pid > 0;
      },
      std::chrono::seconds(10));
  return pid;
}

std::filesystem::path tmpfs_view(int pid, const std::filesystem::path& mount_point) {
  return std::filesystem::path("/proc") / std::to_string(pid) / "root" /
         mount_point.relative_path();
}

std::vector<int> process_ids() {
  std::vector<int> pids;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator("/proc", ec)) {
    const std::string name = entry.path().filename().string();
    if (name.find_first_not_of("0123456789") == std::string::npos) pids.push_back(std::stoi(name));
  }
  return pids;
}

std::map<std::string, ThreadState> threads_of(int pid) {
  std::map<std::string, ThreadState> threads;
  for (const auto& task : std::filesystem::directory_iterator(std::filesystem::path("/proc") /
                                                              std::to_string(pid) / "task")) {
    std::string name = harness::read_file(task.path() / "comm");
    if (!name.empty() && name.back() == '\n') name.pop_back();
    ThreadState state;
    std::istringstream status(harness::read_file(task.path() / "status"));
    for (std::string line; std::getline(status, line);) {
      if (line.rfind("Cpus_allowed_list:", 0) == 0) {
        state.cpus = line.substr(line.find_first_not_of(" \t", 18));
      }
    }
    // Field 41 of stat is the policy; the command name (field 2) may hold spaces, so count
    // from the closing parenthesis.
    const std::string stat = harness::read_file(task.path() / "stat");
    std::istringstream fields(stat.substr(stat.rfind(')') + 2));
    std::string field;
    for (int i = 3; i <= 41 && fields >> field; ++i)
      if (i == 41) state.policy = std::stoi(field);
    threads[name] = state;
  }
  return threads;
}

}  // namespace pandarcap::test
