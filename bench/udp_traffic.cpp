#include "bench/udp_traffic.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <fmt/format.h>
#include <linux/sock_diag.h>
#include <netinet/in.h>
#include <sched.h>
#include <sys/prctl.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <concepts>
#include <cstdlib>
#include <cstring>
#include <optional>
#include <random>
#include <span>
#include <stdexcept>
#include <type_traits>

#include "core/decode/packet_time.hpp"
#include "core/ipv4.hpp"
#include "core/sensors/crc32_mpeg2.hpp"
#include "core/sensors/model_access.hpp"
#include "core/sensors/sensor_model.hpp"
#include "core/sensors/sensor_models.hpp"
#include "core/sensors/timing.hpp"
#include "core/sim/model_sensor.hpp"
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

// A UDP socket made in the network namespace `path` names (/run/netns/NAME; "" = this thread's).
// A socket stays in the namespace it was made in, so only the making needs the switch: this
// thread enters the namespace, makes it and goes back at once (setns is per thread; the rest of
// the process never leaves its own).
int udp_socket_in(const std::string& path) {
  if (path.empty()) return udp_socket();
  const int own = ::open("/proc/thread-self/ns/net", O_RDONLY | O_CLOEXEC);
  if (own < 0) io::throw_errno("open /proc/thread-self/ns/net");
  const int target = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
  if (target < 0) {
    ::close(own);
    io::throw_errno("open " + path);
  }
  if (::setns(target, CLONE_NEWNET) != 0) {
    const int error = errno;
    ::close(target);
    ::close(own);
    errno = error;
    io::throw_errno("setns " + path);
  }
  const int fd = ::socket(AF_INET, SOCK_DGRAM | SOCK_CLOEXEC, 0);
  const int error = errno;
  // Back home before anything else can happen on this thread; failing that, nothing this thread
  // did afterwards would be where it is meant to be.
  if (::setns(own, CLONE_NEWNET) != 0) std::abort();
  ::close(target);
  ::close(own);
  errno = error;
  if (fd < 0) io::throw_errno("socket in " + path);
  return fd;
}

void store_u32_le(std::uint8_t* p, std::uint32_t value) noexcept {
  for (int b = 0; b < 4; ++b)
    p[b] = static_cast<std::uint8_t>(value >> (8 * b));
}

// `out` := the body's run of tail bytes (`tail`) with the time `unix_ns` written in (µs within the
// second, UTC date-time), and the sequence and the CRC where the model has them there.
void write_tail(const TailFields& tail, const std::vector<std::uint8_t>& body, std::int64_t unix_ns,
                std::uint32_t sequence, std::array<std::uint8_t, TailFields::kMaxBytes>& out) {
  std::memcpy(out.data(), body.data() + tail.offset, tail.bytes);
  const std::int64_t seconds = unix_ns / 1'000'000'000;
  const auto micros = static_cast<std::uint32_t>((unix_ns % 1'000'000'000) / 1000);
  store_u32_le(out.data() + tail.micros_at, micros);
  const TailDateTime utc = tail_datetime_from_unix(seconds);
  // The 2000-based year as the model's year byte (the XT's and the QT128's count from 1900).
  const auto year = static_cast<std::uint8_t>(utc.year_since_2000 + 2000 - tail.year_base);
  const std::uint8_t fields[6] = {year, utc.month, utc.day, utc.hour, utc.minute, utc.second};
  std::memcpy(out.data() + tail.date_at, fields, sizeof fields);
  if (tail.sequence_at) store_u32_le(out.data() + *tail.sequence_at, sequence);
  if (tail.crc_at) {
    store_u32_le(out.data() + *tail.crc_at,
                 crc32_mpeg2(std::span<const std::uint8_t>(out.data(), *tail.crc_at)));
  }
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
  source.packets_per_second = pandarcap::packets_per_second(config.return_mode);
  source.description = "simulated Pandar40P, " + std::string(to_string(config.return_mode)) +
                       " return, " + std::to_string(config.rpm) + " RPM";
  return source;
}

namespace {

template <class Model>
TrafficSource model_source(int rpm, ReturnMode mode, bool udp_sequence) {
  TrafficSource source;
  source.model = Model::kId;
  ModelSensorConfig config;
  config.rpm = rpm;
  config.return_mode = mode;
  // The Pandar64's sequence is appended by the generator, as the 40P's; the QT128's is in its tail.
  config.udp_sequence = kSequenceFlagged<Model> && udp_sequence;
  ModelSensor<Model> sensor(config);
  const int returns = returns_per_firing(mode);
  const std::int64_t period = Model::packet_period_ns(returns);
  const auto count = static_cast<std::size_t>(std::llround(Model::packets_per_second(returns)));
  std::array<std::uint8_t, Model::kMaxDatagramBytes> buffer{};
  for (std::size_t i = 0; i < count; ++i) {
    const std::size_t size = sensor.next(buffer);
    source.bodies.emplace_back(buffer.begin(), buffer.begin() + static_cast<long>(size));
    source.offsets_ns.push_back(static_cast<std::int64_t>(i) * period);
  }
  // The loop joins where the azimuth does, as synthetic()'s: the drift of a second's packets
  // over a whole number of turns is taken back over the loop, a share a packet.
  const std::size_t size = sensor.next(buffer);
  const int next_azimuth = Model::azimuth_cdeg(std::span(buffer).first(size), 0);
  const int first_azimuth = Model::azimuth_cdeg(source.bodies.front(), 0);
  const int drift_cdeg = ((next_azimuth - first_azimuth) % 36000 + 54000) % 36000 - 18000;
  for (std::size_t i = 0; i < count; ++i) {
    const auto back = static_cast<int>(std::lround(
        static_cast<double>(drift_cdeg) * static_cast<double>(i) / static_cast<double>(count)));
    if (back == 0) continue;
    std::vector<std::uint8_t>& body = source.bodies[i];
    for (int b = 0; b < Model::kBlocks; ++b) {
      std::uint8_t* field = body.data() + block_azimuth_offset<Model>(body, b);
      const int azimuth = ((load_u16_le(field) - back) % 36000 + 36000) % 36000;
      field[0] = static_cast<std::uint8_t>(azimuth);
      field[1] = static_cast<std::uint8_t>(azimuth >> 8);
    }
    // The blocks' CRC covers the azimuths (the tail's is the generator's, per packet).
    write_checksums<Model>(body);
  }
  source.tail = time_run<Model>(source.bodies.front());
  if (source.tail.offset + source.tail.bytes != source.bodies.front().size()) {
    throw std::logic_error("the generator's tail run does not end the simulated packet");
  }
  source.loop_ns = static_cast<std::int64_t>(count) * period;
  source.packets_per_second = Model::packets_per_second(returns);
  source.description = fmt::format("simulated {}, {} return, {} RPM", display_name(Model::kId),
                                   to_string(mode), rpm);
  return source;
}

}  // namespace

TrafficSource TrafficSource::synthetic_model(SensorModelId model, int rpm, ReturnMode mode,
                                             bool udp_sequence) {
  if (model == SensorModelId::kPandar40P) {
    SyntheticSensorConfig config;
    config.rpm = rpm;
    config.return_mode = mode;
    return synthetic(config);
  }
  return with_model(model, [&]<class M>(std::type_identity<M>) {
    if constexpr (std::same_as<M, Pandar40P>) {
      return TrafficSource{};  // handled above
    } else {
      return model_source<M>(rpm, mode, udp_sequence);
    }
  });
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
  const int fd = udp_socket_in(o.network_namespace);
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
  // Each packet's run of tail bytes (the 40P's: its µs timestamp to the end of its UTC date-time,
  // bytes 1250-1261), written per packet: the clock that runs. The body's bytes before it go out
  // as they are.
  const TailFields& tail = source.tail;
  const bool append_sequence = o.udp_sequence && !tail.sequence_at;
  std::vector<std::array<std::uint8_t, TailFields::kMaxBytes>> times(
      static_cast<std::size_t>(batch));
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
      sequences[i] = static_cast<std::uint32_t>(k);  // little-endian on the wire, as the sensor
      write_tail(tail, body, packet_time, sequences[i], times[i]);
      iovecs[i][0] = {const_cast<std::uint8_t*>(body.data()), tail.offset};
      iovecs[i][1] = {times[i].data(), tail.bytes};
      iovecs[i][2] = {&sequences[i], sizeof(std::uint32_t)};
      messages[i] = {};
      messages[i].msg_hdr.msg_name = const_cast<sockaddr_in*>(&destination);
      messages[i].msg_hdr.msg_namelen = sizeof destination;
      messages[i].msg_hdr.msg_iov = iovecs[i].data();
      messages[i].msg_hdr.msg_iovlen = append_sequence ? 3 : 2;
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

ReferenceReceiver::ReferenceReceiver(Kind kind, std::uint64_t receive_buffer_bytes,
                                     const std::string& bind_ip)
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
  sockaddr_in address = ipv4_endpoint(bind_ip, 0, "listener");
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
