#include "bench/zero_loss_trials.hpp"

#include <fmt/format.h>
#include <signal.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <stdexcept>
#include <thread>
#include <vector>

#include "bench/child_process.hpp"
#include "bench/stop_on_signal.hpp"

namespace pandarcap::bench {

namespace fs = std::filesystem;
using nlohmann::ordered_json;
using namespace std::chrono_literals;
using harness::read_file;

// a / b, 0 when b is 0.
double ratio(double a, std::uint64_t b) {
  return b == 0 ? 0.0 : a / static_cast<double>(b);
}

std::string trim(std::string s) {
  while (!s.empty() && (s.back() == '\n' || s.back() == ' '))
    s.pop_back();
  return s;
}

namespace {

// The daemon's CPU between two thread_cpu_ns() readings `seconds` apart, in total and per
// thread.
ordered_json cpu_use(const std::map<std::string, std::uint64_t>& before,
                     const std::map<std::string, std::uint64_t>& after, double seconds,
                     std::uint64_t packets) {
  double total = 0;
  ordered_json per_thread;
  for (const auto& [name, ns] : after) {
    const auto start = before.count(name) ? before.at(name) : 0;
    const double cpu_s = static_cast<double>(ns - start) / 1e9;
    total += cpu_s;
    per_thread[name] = {{"cpu_fraction_of_one_core", cpu_s / seconds},
                        {"cpu_us_per_packet", ratio(cpu_s * 1e6, packets)}};
  }
  bool exact = true;
  harness::thread_cpu_ns(::getpid(), &exact);
  return {{"cpu_fraction_of_one_core", total / seconds},
          {"cpu_by_thread", per_thread},
          {"cpu_resolution_s", exact ? 1e-9 : 1.0 / static_cast<double>(::sysconf(_SC_CLK_TCK))}};
}

std::optional<ordered_json> last_health(const fs::path& out) {
  std::ifstream in(out / "health" / "health.jsonl");
  std::string line, last;
  while (std::getline(in, line)) {
    if (!line.empty()) last = line;
  }
  if (last.empty()) return std::nullopt;
  try {
    return ordered_json::parse(last);
  } catch (const std::exception&) {
    return std::nullopt;  // a line being appended right now
  }
}

// Every regular file under `dir` cut to 0 bytes: its space freed, its inode kept.
void empty_files(const fs::path& dir) {
  std::error_code ec;
  for (fs::recursive_directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    std::error_code ignored;
    if (it->is_regular_file(ignored)) fs::resize_file(it->path(), 0, ignored);
  }
}

std::uint64_t counter(const ordered_json& health, const char* name) {
  return health["counters"].value(name, std::uint64_t{0});
}

// The budget the daemon says it runs with ("latency budget 5 ms", or "latency budget 0").
ordered_json effective_budget_ms(const std::string& log) {
  if (log.find("latency budget 0)") != std::string::npos) return 0;
  // The packet ring's: "... handed over when full or after N ms" (its block retire timer).
  if (const auto ring = log.find("handed over when full or after "); ring != std::string::npos) {
    return std::strtod(log.c_str() + ring + 31, nullptr);
  }
  const auto at = log.find("latency budget ");
  if (at == std::string::npos) return nullptr;
  return std::strtod(log.c_str() + at + 15, nullptr);
}

// The bytes waiting in the receive queue of the UDP socket bound to `port` on this machine
// (/proc/net/udp and udp6: "sl local_address rem_address st tx_queue:rx_queue ..."); nothing when
// no socket is bound to it.
std::optional<std::uint64_t> udp_port_queued_bytes(std::uint16_t port) {
  const std::string needle = fmt::format(":{:04X} ", port);
  for (const char* table : {"/proc/net/udp", "/proc/net/udp6"}) {
    std::istringstream lines(read_file(table));
    std::string line;
    while (std::getline(lines, line)) {
      std::istringstream fields(line);
      std::string slot, local, remote, state, queues;
      if (!(fields >> slot >> local >> remote >> state >> queues)) continue;
      if ((local + " ").find(needle) == std::string::npos) continue;
      const auto colon = queues.find(':');
      if (colon == std::string::npos) return 0;
      return std::strtoull(queues.c_str() + colon + 1, nullptr, 16);
    }
  }
  return std::nullopt;
}

// N of the last line "received N" a receiver printed.
std::optional<std::uint64_t> last_received_line(const std::string& log) {
  std::optional<std::uint64_t> n;
  std::istringstream lines(log);
  std::string line;
  while (std::getline(lines, line)) {
    const auto at = line.find("received ");
    if (at == std::string::npos) continue;
    const char* digits = line.c_str() + at + 9;
    if (*digits < '0' || *digits > '9') continue;
    n = std::strtoull(digits, nullptr, 10);
  }
  return n;
}

// N of tcpdump's closing line "N <what>" ("12 packets captured"); nullopt when it printed none.
std::optional<std::uint64_t> tcpdump_count(const std::string& log, const std::string& what) {
  const auto at = log.rfind(" " + what);
  if (at == std::string::npos) return std::nullopt;
  auto start = at;
  while (start > 0 && log[start - 1] >= '0' && log[start - 1] <= '9')
    --start;
  if (start == at) return std::nullopt;
  return std::strtoull(log.c_str() + start, nullptr, 10);
}

// libpcap's read timeout for tcpdump (1000 ms), which is its ring's block retire timer, and a
// margin for the wake-up.
constexpr auto kTcpdumpRetire = std::chrono::milliseconds(1200);

// tcpdump recording the trial's packets beside the daemon: started once the daemon is ready,
// measured over the same traffic, stopped before it.
class TcpdumpBeside {
 public:
  TcpdumpBeside(const fs::path& dir, std::uint16_t port, const std::string& interface)
      : file_(dir / "tcpdump.pcap"),
        // -Z root: as root it would switch to the tcpdump user before opening the file, which
        // could not write in the harness's directory.
        process_(fs::exists("/usr/bin/tcpdump") ? "/usr/bin/tcpdump" : "/usr/sbin/tcpdump",
                 {"-i", interface, "-n", "-Z", "root", "-w", file_.string(), "udp", "dst", "port",
                  std::to_string(port)},
                 dir / "tcpdump.log"),
        stop_(process_.pid()) {
    held_.release();  // registered: a signal finds it now
    if (!harness::wait_until(
            [&] { return process_.log().find("listening on") != std::string::npos; }, 15s)) {
      throw std::runtime_error("tcpdump did not start listening:\n" + process_.log());
    }
  }
  int pid() const { return process_.pid(); }
  // Stops it; its counts and file, with the CPU it used between the two readings.
  ordered_json finish(ordered_json cpu, double seconds, std::uint64_t sent) {
    const std::uint64_t rss = harness::process_memory_bytes(process_.pid(), "VmHWM");
    process_.signal(SIGTERM);
    const std::optional<int> status = process_.wait_exit(10s);
    if (status) stop_.release();  // reaped: its pid is no longer its own
    const std::string log = process_.log();
    std::error_code ec;
    const auto bytes = fs::file_size(file_, ec);
    cpu["cpu_us_per_packet"] =
        ratio(cpu["cpu_fraction_of_one_core"].get<double>() * seconds * 1e6, sent);
    cpu["exit_status"] = status ? ordered_json(*status) : ordered_json(nullptr);
    const auto captured = tcpdump_count(log, "packets captured");
    const auto dropped = tcpdump_count(log, "packets dropped by kernel");
    cpu["captured"] = captured ? ordered_json(*captured) : ordered_json(nullptr);
    cpu["dropped_by_kernel"] = dropped ? ordered_json(*dropped) : ordered_json(nullptr);
    cpu["file_bytes"] = ec ? 0 : bytes;
    cpu["peak_rss_bytes"] = rss;
    fs::remove(file_, ec);
    return cpu;
  }

 private:
  fs::path file_;
  StopOnSignal::Held held_;  // from before the fork to the registration
  harness::ChildProcess process_;
  StopOnSignal::Child stop_;
};

// Where the kernel's receive work is charged, beside the threads measured: the softirq time of
// the whole machine (/proc/stat, every CPU; ticks sampled, so it includes the other users of the
// machine) and the CPU of the ksoftirqd threads (softirq work deferred out of whatever task was
// running). This kernel has no IRQ time accounting (CONFIG_IRQ_TIME_ACCOUNTING unset), so
// softirq work done on the way out of a task's system call is part of that task's own CPU time.
class SoftirqMeter {
 public:
  SoftirqMeter() : ksoftirqd_(ksoftirqd_pids()), start_(read()) {}
  ordered_json finish(double seconds) const {
    const Reading end = read();
    const double tick = static_cast<double>(::sysconf(_SC_CLK_TCK));
    return {{"machine_softirq_cpu_fraction_of_one_core",
             static_cast<double>(end.softirq - start_.softirq) / tick / seconds},
            {"ksoftirqd_cpu_fraction_of_one_core",
             static_cast<double>(end.ksoftirqd - start_.ksoftirqd) / tick / seconds}};
  }

 private:
  struct Reading {
    std::uint64_t softirq = 0, ksoftirqd = 0;
  };
  static std::vector<int> ksoftirqd_pids() {
    std::vector<int> pids;
    std::error_code ec;
    for (const auto& entry : fs::directory_iterator("/proc", ec)) {
      const std::string name = entry.path().filename().string();
      if (name.empty() || name[0] < '1' || name[0] > '9') continue;
      if (read_file(entry.path() / "comm").rfind("ksoftirqd/", 0) == 0)
        pids.push_back(std::stoi(name));
    }
    return pids;
  }
  Reading read() const {
    Reading r;
    // "cpu  user nice system idle iowait irq softirq ..."
    std::istringstream stat(read_file("/proc/stat"));
    std::string cpu;
    std::uint64_t field = 0;
    stat >> cpu;
    for (int i = 0; i < 7 && (stat >> field); ++i)
      r.softirq = field;
    for (const int pid : ksoftirqd_) {
      for (const auto& [name, ticks] : harness::thread_cpu_ticks(pid))
        r.ksoftirqd += ticks;
    }
    return r;
  }
  std::vector<int> ksoftirqd_;
  Reading start_;
};

// Whether `daemon --help` lists --receiver.
bool has_receiver_option(const fs::path& daemon) {
  return harness::run_shell("'" + daemon.string() + "' --help 2>/dev/null")
             .out.find("--receiver") != std::string::npos;
}

}  // namespace

ZeroLossTrials::ZeroLossTrials(const ZeroLossOptions& options, const TrafficSource& source,
                               fs::path work, TrafficPath path)
    : o_(options),
      source_(source),
      work_(std::move(work)),
      path_(std::move(path)),
      daemon_(options.daemon.empty() ? harness::beside_this_binary("pandarcapd")
                                     : fs::path(options.daemon)),
      daemon_has_receiver_option_(has_receiver_option(daemon_)) {
  if (!daemon_has_receiver_option_ && (o_.receiver != "socket" || o_.compare_receivers)) {
    throw std::runtime_error(fmt::format(
        "{} has no --receiver option (a pandarcapd from before the packet_ring receiver): it "
        "cannot be measured with the packet_ring receiver",
        daemon_.string()));
  }
}

GeneratorOptions ZeroLossTrials::traffic(std::uint16_t port, double rate, double seconds) const {
  GeneratorOptions g = o_.traffic;
  g.destination_ip = path_.destination_ip;
  g.network_namespace = path_.sender_namespace;
  g.port = port;
  g.rate_pps = rate;
  g.seconds = seconds;
  return g;
}

ordered_json ZeroLossTrials::daemon_trial(double rate, double seconds,
                                          std::optional<std::uint32_t> budget_ms,
                                          const std::vector<std::string>& extra_args,
                                          bool beside_tcpdump, const std::string& receiver_choice) {
  const std::string receiver = receiver_choice.empty() ? o_.receiver : receiver_choice;
  const fs::path dir = work_ / fmt::format("daemon_{:03d}", trials_++);
  fs::create_directories(dir);
  const fs::path out = dir / "out";
  // Removed when the run ends, also when this trial throws (a daemon that did not start).
  emptied_.push_back(out);
  if (beside_tcpdump) emptied_.push_back(dir / "tcpdump.pcap");
  const std::uint16_t port = harness::free_udp_port();
  std::vector<std::string> args;
  if (!o_.daemon_config.empty()) args = {"-c", o_.daemon_config};
  // Whoever runs the harness as root has chosen to; the daemon would refuse otherwise.
  if (::geteuid() == 0) args.emplace_back("--allow-root");
  if (!budget_ms) budget_ms = o_.latency_budget_ms;
  if (budget_ms) {
    args.emplace_back("--latency-budget-ms");
    args.push_back(std::to_string(*budget_ms));
  }
  // An older daemon receives with its socket only, and has no option to say so.
  if (daemon_has_receiver_option_) {
    args.emplace_back("--receiver");
    args.push_back(receiver);
    if (receiver == "packet_ring") {
      args.emplace_back("--interface");
      args.push_back(path_.interface);
    }
  }
  for (const std::string& a : {std::string("--host-ip"), path_.receive_ip, std::string("--port"),
                               std::to_string(port), std::string("--output-dir"), out.string()}) {
    args.push_back(a);
  }
  args.insert(args.end(), extra_args.begin(), extra_args.end());
  StopOnSignal::Held held;  // until the daemon is registered: a signal must find it
  harness::ChildProcess process(daemon_, args, dir / "daemon.log");
  StopOnSignal::Child stopped_on_signal(process.pid());
  held.release();
  if (!harness::wait_until([&] { return process.log().find("ready:") != std::string::npos; },
                           15s)) {
    throw std::runtime_error("pandarcapd did not become ready:\n" + process.log());
  }
  if (daemon_socket_buffer.empty()) {
    const std::string log = process.log();
    const auto at = log.find("socket receive buffer: ");
    if (at != std::string::npos) {
      daemon_socket_buffer = log.substr(at + 23, log.find('\n', at) - at - 23);
    }
  }
  std::optional<TcpdumpBeside> tcpdump;
  if (beside_tcpdump) tcpdump.emplace(dir, port, path_.interface);
  const auto cpu_before = harness::thread_cpu_ns(process.pid());
  const auto tcpdump_before =
      tcpdump ? harness::thread_cpu_ns(tcpdump->pid()) : std::map<std::string, std::uint64_t>{};
  const SoftirqMeter softirq;
  const GeneratorResult sent = run_generator(source_, traffic(port, rate, seconds));
  const ordered_json kernel = softirq.finish(sent.seconds);
  const auto cpu_after = harness::thread_cpu_ns(process.pid());
  const auto tcpdump_after =
      tcpdump ? harness::thread_cpu_ns(tcpdump->pid()) : std::map<std::string, std::uint64_t>{};
  const std::uint64_t rss = harness::process_memory_bytes(process.pid(), "VmHWM");
  // A health record written in the traffic's last half second or after it: its per-second
  // wake-up rates cover the traffic. (The latest record on disk may be older on a slow machine:
  // the one written at once when packets began, whose rates are the idle second's before.)
  const auto traffic_end = std::chrono::system_clock::now();
  const auto since_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(
                            traffic_end.time_since_epoch() - std::chrono::milliseconds(500))
                            .count();
  std::optional<ordered_json> during;
  harness::wait_until(
      [&] {
        during = last_health(out);
        return during && during->value("unix_time_ns", std::int64_t{0}) >= since_ns;
      },
      3s);
  // Let the daemon count everything (it reads kernel drops once a second), then stop it.
  harness::wait_until(
      [&] {
        const auto h = last_health(out);
        return h && counter(*h, "datagrams_received") + counter(*h, "kernel_drops") >= sent.sent;
      },
      3s);
  // tcpdump takes the last packets when its ring's last block retires: libpcap gives tcpdump's
  // TPACKET_V3 ring its 1 s read timeout as the retire timer, and a SIGTERM before it left up to
  // a second of the trial's end out of its file (35 936 of 35 999 captured, none dropped). Its
  // CPU was read above; stopped once that second has passed, before the daemon.
  ordered_json tcpdump_result;
  if (tcpdump) {
    const auto retired = traffic_end + kTcpdumpRetire;
    while (std::chrono::system_clock::now() < retired)
      std::this_thread::sleep_until(retired);
    tcpdump_result = tcpdump->finish(
        cpu_use(tcpdump_before, tcpdump_after, sent.seconds, sent.sent), sent.seconds, sent.sent);
  }
  process.signal(SIGTERM);
  const std::optional<int> status = process.wait_exit(30s);
  if (status) stopped_on_signal.release();  // reaped: its pid is no longer its own
  const auto health = last_health(out);
  if (!status || *status != 0 || !health) {
    throw std::runtime_error(
        fmt::format("pandarcapd trial at {:.0f} packets/s ended badly:\n{}", rate, process.log()));
  }
  const ordered_json& h = *health;
  const std::uint64_t received = counter(h, "datagrams_received");
  const std::uint64_t accepted = counter(h, "packets_accepted");
  ordered_json stages = {{"kernel_drops", counter(h, "kernel_drops")},
                         {"ring_overruns", counter(h, "ring_overruns")},
                         {"rejected", counter(h, "packets_rejected")},
                         {"frames_dropped", counter(h, "frames_dropped_no_arena")},
                         {"pcap_packets_not_recorded", counter(h, "pcap_packets_not_recorded")},
                         {"write_errors", counter(h, "write_errors")},
                         {"mcap_messages_not_written", counter(h, "mcap_messages_not_written")},
                         {"mcap_messages_not_recorded", counter(h, "mcap_messages_not_recorded")},
                         {"unaccounted", sent.sent > received + counter(h, "kernel_drops")
                                             ? sent.sent - received - counter(h, "kernel_drops")
                                             : 0}};
  const std::uint64_t lost = sent.sent > accepted ? sent.sent - accepted : 0;
  // Packets the daemon failed to do its whole job on: not decoded, or not recorded to pcap.
  const std::uint64_t failed = std::min(sent.sent, lost + counter(h, "pcap_packets_not_recorded"));
  bool clean = lost == 0;
  for (const auto& [stage, n] : stages.items())
    clean = clean && n.get<std::uint64_t>() == 0;
  ordered_json wakeups = ordered_json::object();
  for (const char* thread : {"receive", "decode", "writer"}) {
    wakeups[thread] =
        during ? (*during)["gauges"].value(std::string(thread) + "_wakeups_per_second", 0.0) : 0.0;
  }
  ordered_json t = {
      {"offered_pps", rate},
      {"receiver", receiver},
      {"interface", receiver == "packet_ring" ? ordered_json(path_.interface) : ordered_json()},
      {"budget_ms", effective_budget_ms(process.log())},
      {"achieved_pps", sent.achieved_pps},
      {"generator_cpu_fraction_of_one_core", sent.cpu_seconds / sent.seconds},
      {"sent", sent.sent},
      {"received", received},
      {"accepted", accepted},
      {"delivered_pps", static_cast<double>(accepted) / sent.seconds},
      {"lost", lost},
      // What fell behind without losing the packet: frames not written for want of an arena,
      // packets left out of the pcap because the writer was behind (also in loss_by_stage).
      {"frames_dropped", stages["frames_dropped"]},
      {"pcap_not_recorded", stages["pcap_packets_not_recorded"]},
      {"loss_fraction", ratio(static_cast<double>(failed), sent.sent)},
      {"zero_loss", clean},
      {"loss_by_stage", stages},
      {"sequence_lost", counter(h, "sequence_lost")},
      {"latency", h["latency"]},
      {"frame_latency", h.contains("frame_latency") ? h["frame_latency"] : ordered_json()},
      {"wakeups_per_second", wakeups},
      // What the file system charged for each file the daemon created (the daemon's own count,
      // start-up's files included): dear on ext4 without a journal after many deletions there.
      {"files_created", counter(h, "files_created")},
      {"file_create_us",
       ratio(static_cast<double>(counter(h, "file_create_cpu_us")), counter(h, "files_created"))},
      {"peak_rss_bytes", rss},
      {"written_bytes",
       {{"pcd", counter(h, "pcd_bytes_written")},
        {"pcap", counter(h, "pcap_bytes_written")},
        {"mcap", counter(h, "mcap_bytes_written")}}},
      // MCAP chunks stored as they were, compression a chunk behind (docs/mcap.md).
      {"mcap_chunks_uncompressed", counter(h, "mcap_chunks_uncompressed")},
      {"hot_path_allocations", h["counters"].contains("hot_path_allocations")
                                   ? ordered_json(counter(h, "hot_path_allocations"))
                                   : ordered_json(nullptr)}};
  t.update(cpu_use(cpu_before, cpu_after, sent.seconds, sent.sent));
  t["kernel"] = kernel;
  if (tcpdump) t["tcpdump"] = tcpdump_result;
  empty_files(out);
  return t;
}

ZeroLossTrials::~ZeroLossTrials() {
  for (const fs::path& out : emptied_) {
    std::error_code ec;
    fs::remove_all(out, ec);
  }
}

ordered_json ZeroLossTrials::other_receiver_trial(double rate, double seconds) {
  const fs::path log = work_ / "other_receiver.log";
  StopOnSignal::Held held;  // until the receiver is registered: a signal must find it
  harness::ChildProcess process("/bin/sh", {"-c", "exec " + o_.receiver_command}, log);
  StopOnSignal::Child stopped_on_signal(process.pid());
  held.release();
  if (!harness::wait_until([&] { return udp_port_queued_bytes(o_.receiver_port).has_value(); },
                           15s)) {
    throw std::runtime_error(fmt::format("'{}' did not bind UDP port {} within 15 s:\n{}",
                                         o_.receiver_command, o_.receiver_port, process.log()));
  }
  const auto cpu_before = harness::thread_cpu_ns(process.pid());
  const GeneratorResult sent = run_generator(source_, traffic(o_.receiver_port, rate, seconds));
  const auto cpu_after = harness::thread_cpu_ns(process.pid());
  const std::uint64_t rss = harness::process_memory_bytes(process.pid(), "VmHWM");
  // Datagrams still queued in its socket are not lost, only not read yet: the receiver is given
  // up to 5 s to read them before it is asked to stop and say what it received.
  harness::wait_until([&] { return udp_port_queued_bytes(o_.receiver_port).value_or(0) == 0; }, 5s);
  process.signal(SIGTERM);
  const std::optional<int> status = process.wait_exit(10s);
  if (status) stopped_on_signal.release();  // reaped: its pid is no longer its own
  const std::optional<std::uint64_t> received = last_received_line(process.log());
  ordered_json t = {{"command", o_.receiver_command},
                    {"port", o_.receiver_port},
                    {"offered_pps", rate},
                    {"achieved_pps", sent.achieved_pps},
                    {"sent", sent.sent},
                    {"exit_status", status ? ordered_json(*status) : ordered_json(nullptr)},
                    {"peak_rss_bytes", rss}};
  t.update(cpu_use(cpu_before, cpu_after, sent.seconds, sent.sent));
  t["cpu_us_per_packet"] =
      ratio(t["cpu_fraction_of_one_core"].get<double>() * sent.seconds * 1e6, sent.sent);
  if (received) {
    t["received"] = *received;
    t["lost"] = sent.sent > *received ? sent.sent - *received : 0;
  } else {
    t["received"] = nullptr;  // it printed no "received N" line
    t["lost"] = nullptr;
  }
  return t;
}

ordered_json ZeroLossTrials::reference_trial(ReferenceReceiver::Kind kind, double rate,
                                             double seconds) {
  ReferenceReceiver receiver(kind, o_.receive_buffer_bytes, path_.receive_ip);
  const SoftirqMeter softirq;
  const GeneratorResult sent = run_generator(source_, traffic(receiver.port(), rate, seconds));
  const ordered_json kernel = softirq.finish(sent.seconds);
  receiver.drain_and_stop(200);
  const std::uint64_t received = std::min(receiver.received(), sent.sent);
  const std::uint64_t lost = sent.sent - received;
  return {{"offered_pps", rate},
          {"achieved_pps", sent.achieved_pps},
          {"generator_cpu_fraction_of_one_core", sent.cpu_seconds / sent.seconds},
          {"sent", sent.sent},
          {"received", received},
          {"delivered_pps", static_cast<double>(received) / sent.seconds},
          {"lost", lost},
          {"loss_fraction", ratio(static_cast<double>(lost), sent.sent)},
          {"zero_loss", lost == 0},
          {"kernel_drops", receiver.kernel_drops()},
          {"receive_buffer_granted", receiver.receive_buffer_granted()},
          {"cpu_us_per_packet", ratio(receiver.cpu_seconds() * 1e6, received)},
          {"cpu_fraction_of_one_core", receiver.cpu_seconds() / sent.seconds},
          {"kernel", kernel}};
}

}  // namespace pandarcap::bench
