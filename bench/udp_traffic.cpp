#include "bench/udp_traffic.hpp"

#include <arpa/inet.h>
#include <linux/sock_diag.h>
#include <netinet/in.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <optional>
#include <random>
#include <stdexcept>

#include "core/decode/packet_time.hpp"
#include "core/ipv4.hpp"
#include "core/sensors/timing.hpp"
#include "core/sim/synthetic_sensor.hpp"
#include "daemon/clocks.hpp"
#include "daemon/io/errors.hpp"
#include "daemon/pcap/capture_reader.hpp"

namespace pandarcap::bench {

namespace {

int udp_socket() {
  const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  if (fd < 0) io::throw_errno("socket");
  return fd;
}

// The tail's time fields: the µs timestamp at tail offset 10 (packet 1250) to the UTC date-time's
// last byte at tail offset 21 (packet 1261), return mode and factory bytes between them.
constexpr std::size_t kTimeTailOffset = kBodyBytes + 10;
constexpr std::size_t kTimeTailBytes = kPacketBytes - kTimeTailOffset;  // 12

// `out` := the body's bytes 1250-1261 with the time `unix_ns` written in (µs within the second,
// UTC date-time).
void write_time_tail(const std::vector<std::uint8_t>& body, std::int64_t unix_ns,
                     std::array<std::uint8_t, kTimeTailBytes>& out) {
  std::memcpy(out.data(), body.data() + kTimeTailOffset, kTimeTailBytes);
  const std::int64_t seconds = unix_ns / 1'000'000'000;
  const auto micros = static_cast<std::uint32_t>((unix_ns % 1'000'000'000) / 1000);
  for (int b = 0; b < 4; ++b)
    out[static_cast<std::size_t>(b)] = static_cast<std::uint8_t>(micros >> (8 * b));
  const TailDateTime utc = tail_datetime_from_unix(seconds);
  const std::uint8_t fields[6] = {utc.year_since_2000, utc.month, utc.day, utc.hour,
                                  utc.minute,          utc.second};
  std::memcpy(out.data() + 6, fields, sizeof fields);
}

// Whether the options ask for bursts at all.
bool has_bursts(const GeneratorOptions& o) {
  return o.burst_ms > 0 && o.burst_factor > 1 && o.burst_every_s > 0;
}

// Valid packets due by `elapsed_s`: the base rate, plus the extra of every burst window so far.
double due_packets(const GeneratorOptions& o, double elapsed_s) {
  double due = o.rate_pps * elapsed_s;
  if (has_bursts(o)) {
    const double window = o.burst_ms / 1000.0;
    const double whole = std::floor(elapsed_s / o.burst_every_s);
    const double into = std::min(window, elapsed_s - whole * o.burst_every_s);
    due += o.rate_pps * (o.burst_factor - 1) * (whole * window + into);
  }
  return due;
}

}  // namespace

TrafficSource TrafficSource::synthetic(const SyntheticSensorConfig& sensor_config) {
  TrafficSource source;
  SyntheticSensorConfig config = sensor_config;
  config.udp_sequence = false;
  const std::size_t count = config.return_mode == ReturnMode::kDual ? 3600 : 1800;
  SyntheticSensor sensor(config);
  std::array<std::uint8_t, kMaxPacketBytes> buffer{};
  const std::int64_t period = packet_period_ns(config.return_mode);
  for (std::size_t i = 0; i < count; ++i) {
    const std::size_t size = sensor.next(buffer);
    source.bodies.emplace_back(buffer.begin(), buffer.begin() + static_cast<long>(size));
    source.offsets_ns.push_back(static_cast<std::int64_t>(i) * period);
  }
  // The loop joins where the azimuth does: its packets turn a hair over a whole number of
  // revolutions (600 RPM: 0.29° over one second), so the next loop's first packet would be that
  // much behind the one that follows the last, against its time (the stream decoder takes 0.25°
  // against the time for a glitch). The drift is taken back over the loop, a share a packet
  // (0.008° at 600 RPM: within the encoder's jitter), so the loop joins at a packet's step and
  // its times stay one period apart.
  const std::size_t size = sensor.next(buffer);
  const int next_azimuth = PacketView::assume_valid(std::span(buffer).first(size)).azimuth_cdeg(0);
  const int first_azimuth =
      PacketView::assume_valid(std::span(source.bodies.front())).azimuth_cdeg(0);
  const int drift_cdeg = ((next_azimuth - first_azimuth) % 36000 + 54000) % 36000 - 18000;
  for (std::size_t i = 0; i < count; ++i) {
    const auto back = static_cast<int>(std::lround(
        static_cast<double>(drift_cdeg) * static_cast<double>(i) / static_cast<double>(count)));
    if (back == 0) continue;
    std::uint8_t* body = source.bodies[i].data();
    for (int b = 0; b < kBlocks; ++b) {
      std::uint8_t* field = body + kBlockBytes * static_cast<std::size_t>(b) + 2;
      const int azimuth = ((load_u16_le(field) - back) % 36000 + 36000) % 36000;
      field[0] = static_cast<std::uint8_t>(azimuth);
      field[1] = static_cast<std::uint8_t>(azimuth >> 8);
    }
  }
  source.loop_ns = static_cast<std::int64_t>(count) * period;
  source.description = "simulated Pandar40P, " + std::string(to_string(config.return_mode)) +
                       " return, " + std::to_string(config.rpm) + " RPM";
  return source;
}

TrafficSource TrafficSource::from_capture(const std::string& path) {
  TrafficSource source;
  CaptureReader reader(path);
  CaptureRecord record;
  PacketClock clock;
  std::optional<std::int64_t> first_ns;
  while (reader.next(record) == CaptureStatus::kRecord) {
    if (validate(record.payload) != RejectReason::kNone) continue;
    source.bodies.emplace_back(record.payload.begin(), record.payload.begin() + kPacketBytes);
    const PacketView packet = PacketView::assume_valid(record.payload);
    const PacketTime time = clock.convert(packet.utc(), packet.timestamp_us());
    const std::int64_t t = time.valid() ? time.t0_ns : record.timestamp_ns;
    if (!first_ns) first_ns = t;
    // Never before the previous one: the offsets must rise for the clock to run.
    const std::int64_t previous = source.offsets_ns.empty() ? 0 : source.offsets_ns.back();
    source.offsets_ns.push_back(std::max(previous, t - *first_ns));
  }
  if (source.bodies.empty()) throw std::runtime_error(path + ": no valid Pandar40P packets");
  // The cycle lasts its span and one more packet's step (the mean step: a capture is one mode).
  const std::int64_t span = source.offsets_ns.back();
  const auto n = static_cast<std::int64_t>(source.offsets_ns.size());
  source.loop_ns = span + (n > 1 ? std::max<std::int64_t>(span / (n - 1), 1) : 1'000'000);
  source.description = path;
  return source;
}

std::optional<std::string> generator_options_problem(const GeneratorOptions& o) {
  const auto address = parse_ipv4_host_order(o.destination_ip);
  if (!address) return "not an IPv4 address: " + o.destination_ip;
  if (o.foreign_fraction > 0 && (*address >> 24) != 127) {
    return "foreign traffic is sent from 127.0.0.2, which cannot reach " + o.destination_ip +
           "; use a 127.x.x.x destination";
  }
  return std::nullopt;
}

GeneratorResult run_generator(const TrafficSource& source, const GeneratorOptions& o) {
  if (const auto problem = generator_options_problem(o)) throw std::runtime_error(*problem);
  const sockaddr_in destination = ipv4_endpoint(o.destination_ip, o.port, "destination");
  const int fd = udp_socket();
  int foreign_fd = -1;
  if (o.foreign_fraction > 0) {
    foreign_fd = udp_socket();
    const sockaddr_in from = ipv4_endpoint("127.0.0.2", 0, "foreign source");
    if (::bind(foreign_fd, reinterpret_cast<const sockaddr*>(&from), sizeof from) != 0) {
      ::close(foreign_fd);
      ::close(fd);
      throw std::runtime_error("cannot bind the foreign sender to 127.0.0.2");
    }
  }
  const int batch = std::max(1, o.batch);
  std::vector<mmsghdr> messages(static_cast<std::size_t>(batch));
  std::vector<std::array<iovec, 3>> iovecs(static_cast<std::size_t>(batch));
  std::vector<std::uint32_t> sequences(static_cast<std::size_t>(batch));
  // Each packet's tail from its µs timestamp to the end of its UTC date-time (bytes 1250-1261),
  // written per packet: the clock that runs. The body's bytes around it go out as they are.
  std::vector<std::array<std::uint8_t, kTimeTailBytes>> times(static_cast<std::size_t>(batch));
  const std::int64_t clock_start =
      o.clock_start_unix_ns != 0 ? o.clock_start_unix_ns : realtime_ns();
  std::mt19937 rng(1);
  std::array<std::uint8_t, 2048> junk{};

  GeneratorResult result;
  double foreign_credit = 0, malformed_credit = 0, duplicate_credit = 0, glitch_credit = 0;
  const bool bursting = has_bursts(o);
  // Sleeps end within a microsecond of their deadline instead of the default 50 µs slack, so a
  // packet leaves when it is due (restored on return: the caller's thread is borrowed).
  const int old_slack = ::prctl(PR_GET_TIMERSLACK, 0, 0, 0, 0);
  ::prctl(PR_SET_TIMERSLACK, 1000UL, 0, 0, 0);
  timespec cpu_start{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &cpu_start);
  const std::int64_t start = monotonic_ns();
  const auto end = start + static_cast<std::int64_t>(o.seconds * 1e9);
  for (;;) {
    const std::int64_t now = monotonic_ns();
    if (now >= end) break;
    const double elapsed = static_cast<double>(now - start) / 1e9;
    const auto due = static_cast<std::uint64_t>(due_packets(o, elapsed));
    if (due <= result.sent) {
      // Ahead of schedule: sleep until the next packet is due, and never spin. On a 2-core
      // machine a spinning generator takes a whole core from the receiver it measures (it did:
      // 0.9 of a core at 50 k packets/s). At high rates the wake-up delay lets several packets
      // fall due, and they go out in one sendmmsg: batching comes from the clock, not from a loop.
      std::int64_t wake = 0;
      if (bursting) {
        // The next packet is due within one interval at the fastest (burst) rate.
        wake = now + static_cast<std::int64_t>(1e9 / (o.rate_pps * o.burst_factor));
      } else {
        wake = start + static_cast<std::int64_t>(
                           std::ceil(static_cast<double>(result.sent + 1) * 1e9 / o.rate_pps));
      }
      const timespec until{static_cast<time_t>(wake / 1'000'000'000),
                           static_cast<long>(wake % 1'000'000'000)};
      clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &until, nullptr);
      continue;
    }
    const auto n = static_cast<unsigned>(std::min<std::uint64_t>(due - result.sent, batch));
    for (unsigned i = 0; i < n; ++i) {
      const std::uint64_t k = o.first_sequence + result.sent + i;
      const std::size_t index = k % source.bodies.size();
      const auto& body = source.bodies[index];
      const auto loops = static_cast<std::int64_t>(k / source.bodies.size());
      std::int64_t packet_time = clock_start + loops * source.loop_ns + source.offsets_ns[index];
      glitch_credit += o.glitch_fraction;
      if (glitch_credit >= 1) {
        // A clock glitch: this one packet says it is 1 to 5 minutes back or ahead.
        glitch_credit -= 1;
        const std::int64_t minutes = 1 + static_cast<std::int64_t>(rng() % 5);
        packet_time += (rng() % 2 == 0 ? -1 : 1) * minutes * 60'000'000'000LL;
        ++result.glitches_sent;
      }
      write_time_tail(body, packet_time, times[i]);
      sequences[i] = static_cast<std::uint32_t>(k);  // little-endian on the wire, as the sensor
      iovecs[i][0] = {const_cast<std::uint8_t*>(body.data()), kTimeTailOffset};
      iovecs[i][1] = {times[i].data(), kTimeTailBytes};
      iovecs[i][2] = {&sequences[i], sizeof(std::uint32_t)};
      messages[i] = {};
      messages[i].msg_hdr.msg_name = const_cast<sockaddr_in*>(&destination);
      messages[i].msg_hdr.msg_namelen = sizeof destination;
      messages[i].msg_hdr.msg_iov = iovecs[i].data();
      messages[i].msg_hdr.msg_iovlen = o.udp_sequence ? 3 : 2;
    }
    const int sent = ::sendmmsg(fd, messages.data(), n, 0);
    if (sent < 0) {
      if (errno != ENOBUFS && errno != EAGAIN && errno != EINTR) ++result.send_errors;
      continue;
    }
    result.sent += static_cast<std::uint64_t>(sent);
    // Copies of packets just sent, each right after the batch (a switch loop's echo).
    duplicate_credit += o.duplicate_fraction * sent;
    for (int i = 0; duplicate_credit >= 1 && i < sent; ++i, duplicate_credit -= 1) {
      if (::sendmsg(fd, &messages[static_cast<std::size_t>(i)].msg_hdr, 0) > 0) {
        ++result.duplicates_sent;
      }
    }
    // The extra traffic, sent one datagram at a time beside the valid stream.
    foreign_credit += o.foreign_fraction * sent;
    malformed_credit += o.malformed_fraction * sent;
    for (; foreign_credit >= 1; foreign_credit -= 1) {
      const auto& body = source.bodies[result.foreign_sent % source.bodies.size()];
      if (::sendto(foreign_fd, body.data(), body.size(), 0,
                   reinterpret_cast<const sockaddr*>(&destination), sizeof destination) > 0) {
        ++result.foreign_sent;
      }
    }
    for (; malformed_credit >= 1; malformed_credit -= 1) {
      const std::size_t length = rng() % junk.size();
      for (std::size_t i = 0; i < length; ++i)
        junk[i] = static_cast<std::uint8_t>(rng());
      if (::sendto(fd, junk.data(), length, 0, reinterpret_cast<const sockaddr*>(&destination),
                   sizeof destination) >= 0) {
        ++result.malformed_sent;
      }
    }
  }
  result.seconds = static_cast<double>(monotonic_ns() - start) / 1e9;
  result.achieved_pps = static_cast<double>(result.sent) / result.seconds;
  timespec cpu_end{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &cpu_end);
  result.cpu_seconds = static_cast<double>(cpu_end.tv_sec - cpu_start.tv_sec) +
                       static_cast<double>(cpu_end.tv_nsec - cpu_start.tv_nsec) / 1e9;
  if (old_slack > 0) ::prctl(PR_SET_TIMERSLACK, static_cast<unsigned long>(old_slack), 0, 0, 0);
  if (foreign_fd >= 0) ::close(foreign_fd);
  ::close(fd);
  return result;
}

ReferenceReceiver::ReferenceReceiver(Kind kind, std::uint64_t receive_buffer_bytes)
    : kind_(kind), fd_(udp_socket()) {
  const int requested = static_cast<int>(std::min<std::uint64_t>(receive_buffer_bytes, 1u << 30));
  // As the daemon does: force past rmem_max when privileged, else take what the kernel allows.
  if (::setsockopt(fd_, SOL_SOCKET, SO_RCVBUFFORCE, &requested, sizeof requested) != 0) {
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &requested, sizeof requested);
  }
  socklen_t length = sizeof granted_;
  ::getsockopt(fd_, SOL_SOCKET, SO_RCVBUF, &granted_, &length);
  const timeval timeout{0, 100'000};  // wake up to see the stop flag
  ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &timeout, sizeof timeout);
  sockaddr_in address = ipv4_endpoint("127.0.0.1", 0, "listener");
  if (::bind(fd_, reinterpret_cast<sockaddr*>(&address), sizeof address) != 0) {
    ::close(fd_);
    io::throw_errno("bind");
  }
  length = sizeof address;
  ::getsockname(fd_, reinterpret_cast<sockaddr*>(&address), &length);
  port_ = ntohs(address.sin_port);
  thread_ = std::thread([this] { run(); });
}

ReferenceReceiver::~ReferenceReceiver() {
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
  ::close(fd_);
}

void ReferenceReceiver::run() {
  constexpr int kBatch = 64;
  std::vector<std::array<std::uint8_t, 2048>> buffers(kBatch);
  std::array<iovec, kBatch> iov{};
  std::array<mmsghdr, kBatch> messages{};
  for (int i = 0; i < kBatch; ++i) {
    iov[i] = {buffers[i].data(), buffers[i].size()};
    messages[i].msg_hdr.msg_iov = &iov[i];
    messages[i].msg_hdr.msg_iovlen = 1;
  }
  const double cpu_start = thread_cpu_seconds();
  while (!stop_.load(std::memory_order_relaxed)) {
    if (kind_ == Kind::kRecvmmsg) {
      const int n = ::recvmmsg(fd_, messages.data(), kBatch, MSG_WAITFORONE, nullptr);
      if (n > 0) received_.fetch_add(static_cast<std::uint64_t>(n), std::memory_order_relaxed);
    } else {
      if (::recvfrom(fd_, buffers[0].data(), buffers[0].size(), 0, nullptr, nullptr) >= 0) {
        received_.fetch_add(1, std::memory_order_relaxed);
      }
    }
  }
  cpu_seconds_ = thread_cpu_seconds() - cpu_start;
}

void ReferenceReceiver::drain_and_stop(int quiet_ms) {
  std::uint64_t last = received();
  for (;;) {
    std::this_thread::sleep_for(std::chrono::milliseconds(quiet_ms));  // a quiet period, polled
    const std::uint64_t now = received();
    if (now == last) break;
    last = now;
  }
  stop_.store(true);
  if (thread_.joinable()) thread_.join();
}

std::uint64_t ReferenceReceiver::kernel_drops() const {
  std::array<std::uint32_t, SK_MEMINFO_VARS> info{};
  socklen_t length = sizeof info;
  if (::getsockopt(fd_, SOL_SOCKET, SO_MEMINFO, info.data(), &length) != 0) return 0;
  return info[SK_MEMINFO_DROPS];
}

}  // namespace pandarcap::bench
