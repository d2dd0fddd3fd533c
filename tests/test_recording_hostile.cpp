// Hostile tests of the recording: pcap (raw/) and MCAP packets hold exactly what was received,
// for datagrams of every length, through both receivers, raw batches that fill exactly, replays,
// rotation and stop. Each compares the real pandarcapd's files byte for byte against what was
// sent, or against tcpdump -w on the same veth.
#include <arpa/inet.h>
#include <fmt/format.h>
#include <fmt/ranges.h>
#include <linux/if_packet.h>
#include <net/if.h>
#include <signal.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <catch2/catch.hpp>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "bench/child_process.hpp"
#include "daemon/io/unique_fd.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "support/hand_frames.hpp"
#include "support/live_daemon.hpp"
#include "support/pcap_records.hpp"
#include "support/test_support.hpp"
#include "support/veth_daemon.hpp"
#include "support/veth_pair.hpp"

namespace fs = std::filesystem;
using namespace std::chrono_literals;
using pandarcap::harness::ChildProcess;
using pandarcap::harness::wait_until;

namespace pandarcap {
namespace {

using Bytes = std::vector<std::uint8_t>;

using test::count_pcap_records;
using test::PcapRecord;

std::vector<PcapRecord> read_pcaps(const fs::path& dir) {
  std::vector<PcapRecord> all;
  for (const fs::path& f : test::files_ending(dir, ".pcap")) {
    auto r = test::read_pcap_records(f);
    all.insert(all.end(), r.begin(), r.end());
  }
  return all;
}

// A record's UDP payload and the lengths its headers declare (Ethernet, VLAN, IPv4 or IPv6).
struct Udp {
  bool ok = false;
  std::string payload;
  std::uint32_t udp_length = 0;  // the UDP header's length field
  std::uint32_t ip_length = 0;   // IPv4 total length, or IPv6 payload length
};

Udp udp_of(const std::string& frame) {
  Udp u;
  const auto b = [&](std::size_t i) { return static_cast<std::uint8_t>(frame[i]); };
  const auto be16 = [&](std::size_t i) { return static_cast<std::uint32_t>(b(i) << 8 | b(i + 1)); };
  if (frame.size() < 14) return u;
  std::size_t at = 12;
  std::uint32_t type = be16(at);
  while (type == 0x8100 || type == 0x88A8) {
    at += 4;
    if (frame.size() < at + 2) return u;
    type = be16(at);
  }
  at += 2;
  std::size_t udp = 0;
  if (type == 0x0800) {
    if (frame.size() < at + 20) return u;
    u.ip_length = be16(at + 2);
    udp = at + std::size_t{b(at) & 0x0Fu} * 4;
  } else if (type == 0x86DD) {
    if (frame.size() < at + 40) return u;
    u.ip_length = be16(at + 4);
    udp = at + 40;
  } else {
    return u;
  }
  if (frame.size() < udp + 8) return u;
  u.udp_length = be16(udp + 4);
  const std::size_t end =
      std::min<std::size_t>(frame.size(), udp + std::max<std::uint32_t>(u.udp_length, 8));
  u.payload = frame.substr(udp + 8, end - udp - 8);
  u.ok = true;
  return u;
}

// Datagram `index` of `length` bytes: every byte says where it is, so a byte from another
// datagram or another place is seen.
Bytes datagram(std::size_t length, std::size_t index) {
  Bytes d(length);
  for (std::size_t j = 0; j < length; ++j)
    d[j] = static_cast<std::uint8_t>((index * 131 + j * 7 + (j >> 8) * 3 + 0x41) & 0xFF);
  return d;
}

// Every length from 0 to 1400, then the largest ones (a loopback datagram may be 65507 bytes).
std::vector<std::size_t> every_length(std::size_t up_to, bool large) {
  std::vector<std::size_t> lengths;
  for (std::size_t l = 0; l <= up_to; ++l)
    lengths.push_back(l);
  if (large)
    for (std::size_t l : {1471u, 1472u, 2000u, 4096u, 9000u, 65507u})
      lengths.push_back(l);
  return lengths;
}

std::string as_string(const Bytes& b) {
  return std::string(b.begin(), b.end());
}

// Sends `datagrams` from `from_ip` to `to_ip`:port, each waited for in the kernel's socket
// buffer before the next few go (so a slow start does not drop any): every 64, a wait until the
// receiver's count says so would take a health period; instead the sender's pace is kept low.
void send_all(const std::string& from_ip, const std::string& to_ip, std::uint16_t port,
              const std::vector<Bytes>& datagrams) {
  const io::UniqueFd fd = test::udp_socket_from(from_ip);
  int big = 8 << 20;
  ::setsockopt(fd.get(), SOL_SOCKET, SO_SNDBUF, &big, sizeof big);
  const sockaddr_in to = test::ipv4_endpoint(to_ip, port);
  std::size_t i = 0;
  for (const auto& d : datagrams) {
    const ssize_t n = ::sendto(fd.get(), d.data(), d.size(), 0,
                               reinterpret_cast<const sockaddr*>(&to), sizeof to);
    INFO("datagram " << i << " of " << d.size() << " bytes");
    REQUIRE(n == static_cast<ssize_t>(d.size()));
    if (++i % 32 == 0) std::this_thread::sleep_for(1ms);  // ~30 000/s: a pace, not a wait
  }
}

// Datagrams of every length from 0 to 1400 bytes and the largest (see every_length).
std::vector<Bytes> every_length_datagrams() {
  std::vector<Bytes> sent;
  std::size_t index = 0;
  for (std::size_t length : every_length(1400, true))
    sent.push_back(datagram(length, index++));
  return sent;
}

// Sends `sent` over loopback to `daemon`, stops it once it has counted them all, and returns its
// final health record (a clean exit required).
nlohmann::json send_and_stop(test::LiveDaemon& daemon, const std::vector<Bytes>& sent) {
  send_all("127.0.0.1", "127.0.0.1", daemon.port, sent);
  const nlohmann::json h = daemon.stop_after(sent.size());
  INFO(daemon.process->log());
  REQUIRE(daemon.exit_status == 0);
  return h;
}

// Checks that `records` (in order) hold `sent` (in order): each payload as sent, or its first
// 1280 bytes (the slot's room) with the real length in the record's original length and the
// headers.
void check_records_hold(const std::vector<PcapRecord>& records, const std::vector<Bytes>& sent,
                        std::size_t header_bytes) {
  CHECK(records.size() == sent.size());
  std::size_t exact = 0, mismatched = 0;
  std::string first_mismatch;
  for (std::size_t i = 0; i < std::min(records.size(), sent.size()); ++i) {
    const PcapRecord& r = records[i];
    const Udp u = udp_of(r.bytes);
    const std::size_t length = sent[i].size();
    const std::size_t kept = std::min<std::size_t>(length, 1280);
    const std::string want = as_string(sent[i]).substr(0, kept);
    const bool good = u.ok && u.payload == want && u.udp_length == 8 + length &&
                      r.captured == header_bytes + kept && r.original == header_bytes + length;
    if (good) {
      ++exact;
    } else if (mismatched++ == 0) {
      first_mismatch = fmt::format(
          "record {}: sent {} bytes; recorded captured {} original {} udp_length {} payload {} "
          "bytes, same bytes: {}",
          i, length, r.captured, r.original, u.udp_length, u.payload.size(), u.payload == want);
    }
  }
  INFO(first_mismatch);
  CHECK(mismatched == 0);
  CHECK(exact == sent.size());
}

}  // namespace

// The socket receiver (synthesised headers): every datagram length from 0 to 1400 bytes and the
// largest, raw batches of 7 (so they fill exactly again and again). The pcap holds each as sent.
TEST_CASE("recording hostile: socket receiver records every datagram length exactly",
          "[recording_hostile][threads]") {
  test::ScratchDir dir("rec-hostile-socket");
  test::LiveDaemon daemon(dir, "[arenas]\npackets_per_frame = 7\n");
  REQUIRE(daemon.ready());
  const std::vector<Bytes> sent = every_length_datagrams();
  const nlohmann::json h = send_and_stop(daemon, sent);
  const auto c = [&](const char* name) { return test::health_counter(h, name); };
  CHECK(c("kernel_drops") == 0);
  CHECK(c("datagrams_received") == sent.size());
  CHECK(c("pcap_packets_written") == sent.size());
  check_records_hold(read_pcaps(daemon.out / "raw"), sent, 42);
}

// The same through MCAP: each datagram a PandarPacket message, read back by the capture reader.
TEST_CASE("recording hostile: MCAP packets hold every datagram length exactly",
          "[recording_hostile][threads]") {
  test::ScratchDir dir("rec-hostile-mcap");
  test::LiveDaemon daemon(dir, "[arenas]\npackets_per_frame = 7\n", {"--mcap", "--mcap-packets"});
  REQUIRE(daemon.ready());
  const std::vector<Bytes> sent = every_length_datagrams();
  const nlohmann::json h = send_and_stop(daemon, sent);
  CHECK(test::health_counter(h, "datagrams_received") == sent.size());
  const auto files = test::files_ending(daemon.out / "mcap", ".mcap");
  REQUIRE(files.size() == 1);
  CaptureReader reader(files[0].string());
  CaptureRecord record;
  std::vector<std::string> got;
  CaptureStatus status;
  while ((status = reader.next(record)) == CaptureStatus::kRecord)
    got.emplace_back(record.payload.begin(), record.payload.end());
  INFO(reader.error());
  CHECK(status == CaptureStatus::kEnd);
  CHECK(got.size() == sent.size());
  std::size_t mismatched = 0;
  std::string first;
  for (std::size_t i = 0; i < std::min(got.size(), sent.size()); ++i) {
    const std::string want = as_string(sent[i]).substr(0, 1280);
    if (got[i] != want && mismatched++ == 0)
      first =
          fmt::format("message {}: sent {} bytes, recorded {}", i, sent[i].size(), got[i].size());
  }
  INFO(first);
  CHECK(mismatched == 0);
}

namespace {}  // namespace

// packet_ring on a veth pair, tcpdump -w on the same interface as the witness: UDP datagrams of
// every length the link carries whole (0..1472; the short ones padded to 60 bytes on the wire),
// then frames made by hand with trailers and VLAN tags whose datagram and trailer end just
// below, at and just above the slot's 1280 bytes. Raw batches of 7. The daemon's pcap must be
// tcpdump's, record for record, each cut to its headers and 1280 bytes at most.
TEST_CASE("recording hostile: packet_ring records every length and trailer as tcpdump does",
          "[recording_hostile][threads]") {
  if (!test::can_make_links()) return;
  test::VethPair veth("rh");
  REQUIRE(veth.ok());
  test::ScratchDir dir("rec-hostile-ring");
  const std::uint16_t port = harness::free_udp_port();
  ChildProcess tcpdump("/usr/bin/tcpdump",
                       {"-i", veth.near(), "-n", "-U", "-B", "65536", "-w",
                        (dir / "tcpdump.pcap").string(), "udp dst port " + std::to_string(port)},
                       dir / "tcpdump.log");
  REQUIRE(wait_until([&] { return tcpdump.log().find("listening on") != std::string::npos; }, 10s));
  test::VethDaemon daemon(dir, veth, port, "[arenas]\npackets_per_frame = 7\n");

  std::vector<Bytes> datagrams;
  std::size_t index = 0;
  for (std::size_t length : every_length(1472, false))
    datagrams.push_back(datagram(length, index++));
  std::size_t frames = 0;
  {
    test::FarNamespace far(veth.ns());
    send_all(veth.far_ip(), veth.near_ip(), port, datagrams);
    io::UniqueFd raw(::socket(AF_PACKET, SOCK_RAW, 0));
    REQUIRE(raw);
    sockaddr_ll link{};
    link.sll_family = AF_PACKET;
    link.sll_ifindex = static_cast<int>(::if_nametoindex(veth.far().c_str()));
    REQUIRE(::bind(raw.get(), reinterpret_cast<sockaddr*>(&link), sizeof link) == 0);
    std::uint16_t id = 0;
    for (const std::uint16_t tci : {std::uint16_t{0}, std::uint16_t{0x6007}}) {
      for (std::size_t length :
           {0u, 1u, 5u, 17u, 18u, 19u, 1240u, 1262u, 1266u, 1270u, 1279u, 1280u, 1281u, 1300u}) {
        for (std::size_t trailer : {0u, 1u, 2u, 13u, 14u, 15u, 16u, 30u, 100u}) {
          if (28 + length + trailer > 1500) continue;
          const Bytes f =
              test::hand_frame(veth, port, tci, datagram(length, index++), id++, trailer);
          INFO("frame of " << f.size() << " bytes");
          REQUIRE(::send(raw.get(), f.data(), f.size(), 0) == static_cast<ssize_t>(f.size()));
          ++frames;
          if (frames % 32 == 0) std::this_thread::sleep_for(1ms);
        }
      }
    }
    // IPv4 options (40 bytes) and two VLAN tags: the largest headers the slot keeps (90).
    for (const std::uint16_t inner :
         {std::uint16_t{0}}) {  // a second tag: veth drops it before tcpdump or the daemon sees it
      for (std::size_t length : {0u, 1u, 17u, 1262u, 1266u, 1279u, 1280u, 1281u, 1300u}) {
        for (std::size_t trailer : {0u, 1u, 14u, 30u}) {
          const Bytes f = test::hand_frame(veth, port, 0x6007, datagram(length, index++), id++,
                                           trailer, 40, inner);
          INFO("frame of " << f.size() << " bytes");
          REQUIRE(::send(raw.get(), f.data(), f.size(), 0) == static_cast<ssize_t>(f.size()));
          ++frames;
        }
      }
    }
  }
  const std::size_t total = datagrams.size() + frames;
  const nlohmann::json h = daemon.stop_after(total);
  INFO(daemon.process->log());
  wait_until([&] { return count_pcap_records(dir / "tcpdump.pcap") >= total; }, 10s);
  tcpdump.signal(SIGINT);
  REQUIRE(tcpdump.wait_exit(10s).has_value());
  const auto c = [&](const char* name) { return test::health_counter(h, name); };
  CHECK(c("kernel_drops") == 0);
  CHECK(c("datagrams_received") == total);
  CHECK(c("pcap_packets_written") == total);
  const std::vector<PcapRecord> ours = read_pcaps(daemon.out / "raw");
  const std::vector<PcapRecord> theirs = test::read_pcap_records(dir / "tcpdump.pcap");
  REQUIRE(theirs.size() == total);
  {
    // Which of tcpdump's frames the daemon has no record of (by their IP identification).
    std::string missing;
    std::size_t o = 0, count = 0;
    for (const PcapRecord& t : theirs) {
      if (o < ours.size() && ours[o].original == t.original &&
          ours[o].bytes == t.bytes.substr(0, ours[o].bytes.size())) {
        ++o;
        continue;
      }
      if (count++ < 6)
        missing += fmt::format(" [{} bytes, bytes 12..19 {:02x}]", t.original,
                               fmt::join(t.bytes.substr(12, 8), " "));
    }
    INFO("tcpdump's frames the daemon did not record: " << count << missing);
    CHECK(count == 0);
  }
  CHECK(ours.size() == total);
  std::size_t mismatched = 0;
  std::string first;
  for (std::size_t i = 0; i < std::min(ours.size(), theirs.size()); ++i) {
    PcapRecord want = theirs[i];
    // The headers end where the UDP payload starts: what follows is cut to 1280 bytes.
    std::size_t at = 12;
    while ((static_cast<std::uint8_t>(want.bytes[at]) << 8 |
            static_cast<std::uint8_t>(want.bytes[at + 1])) == 0x8100)
      at += 4;
    at += 2;
    at += std::size_t{static_cast<std::uint8_t>(want.bytes[at]) & 0x0Fu} * 4 + 8;
    if (want.bytes.size() > at + 1280) {
      want.bytes.resize(at + 1280);
      want.captured = static_cast<std::uint32_t>(want.bytes.size());
    }
    if (!(ours[i] == want) && mismatched++ == 0) {
      first = fmt::format(
          "record {}: tcpdump captured {} original {}; ours captured {} original {}; same "
          "time {}; same bytes (cut) {}",
          i, theirs[i].captured, theirs[i].original, ours[i].captured, ours[i].original,
          ours[i].seconds == want.seconds && ours[i].fraction == want.fraction,
          ours[i].bytes == want.bytes);
    }
  }
  INFO(first);
  CHECK(mismatched == 0);
}

namespace {

void le32(std::string& out, std::uint32_t v) {
  for (int i = 0; i < 4; ++i)
    out.push_back(static_cast<char>(v >> (8 * i)));
}
void be16s(std::string& out, std::uint32_t v) {
  out.push_back(static_cast<char>(v >> 8));
  out.push_back(static_cast<char>(v));
}

}  // namespace

// A replay of a capture from an IPv6 sensor, its datagrams of every length 0..1400 and larger
// ones (a capture may hold them whole). The replay's recording holds each record as it was, its
// synthesised headers as the file's (the same MACs, hop limit and addresses), the bytes past
// 1280 cut with the length kept. The UDP checksum is not compared.
TEST_CASE("recording hostile: a replayed IPv6 capture of every length is recorded as read",
          "[recording_hostile][threads]") {
  test::ScratchDir dir("rec-hostile-replay6");
  std::string file;
  le32(file, 0xA1B2C3D4u);
  file += std::string("\x02\x00\x04\x00", 4);
  le32(file, 0);
  le32(file, 0);
  le32(file, 262144);
  le32(file, 1);
  std::vector<std::string> frames;
  std::vector<std::size_t> lengths = every_length(1400, false);
  for (std::size_t l : {1500u, 4000u, 9000u, 65000u})
    lengths.push_back(l);
  const std::uint32_t base = 1'800'000'000u;
  std::size_t index = 0;
  for (std::size_t length : lengths) {
    std::string f("\x02\x00\x00\x00\x00\x02\x02\x00\x00\x00\x00\x01\x86\xDD", 14);
    le32(f, 0);  // placeholder
    f.resize(14);
    f += std::string("\x60\x00\x00\x00", 4);
    be16s(f, static_cast<std::uint32_t>(8 + length));
    f += std::string("\x11\x40", 2);
    std::string source(16, '\0'), destination(16, '\0');
    source[0] = destination[0] = '\xfd';
    source[15] = 1;
    destination[15] = 2;
    f += source + destination;
    be16s(f, 2368);
    be16s(f, 2368);
    be16s(f, static_cast<std::uint32_t>(8 + length));
    be16s(f, 0);
    f += as_string(datagram(length, index));
    const auto t_us = static_cast<std::uint32_t>(index * 1000);
    le32(file, base + t_us / 1'000'000);
    le32(file, t_us % 1'000'000);
    le32(file, static_cast<std::uint32_t>(f.size()));
    le32(file, static_cast<std::uint32_t>(f.size()));
    file += f;
    frames.push_back(f);
    ++index;
  }
  const fs::path input = dir / "sensor6.pcap";
  test::write_bytes(input, file);
  std::ofstream(dir / "daemon.toml") << "[arenas]\npackets_per_frame = 7\n";
  const auto r = test::run_command(
      test::pandarcapd_command() + " -c " + test::quoted(dir / "daemon.toml") + " --replay " +
      test::quoted(input) + " --output-dir " + test::quoted(dir / "out") + " 2>&1");
  INFO(r.out);
  REQUIRE(r.exit_code == 0);
  const std::vector<PcapRecord> records = read_pcaps(dir / "out" / "raw");
  CHECK(records.size() == frames.size());
  std::size_t mismatched = 0;
  std::string first;
  for (std::size_t i = 0; i < std::min(records.size(), frames.size()); ++i) {
    const std::size_t headers = 14 + 40 + 8;
    std::string want = frames[i].substr(0, headers + 1280);
    std::string got = records[i].bytes;
    const auto t_us = static_cast<std::uint32_t>(i * 1000);
    const bool same_head =
        records[i].seconds == base + t_us / 1'000'000 && records[i].fraction == t_us % 1'000'000 &&
        records[i].captured == want.size() && records[i].original == frames[i].size();
    if (got.size() >= headers) got[headers - 2] = got[headers - 1] = 0;  // the UDP checksum
    if ((!same_head || got != want) && mismatched++ == 0)
      first = fmt::format(
          "record {}: read {} bytes; recorded captured {} original {} time {}.{}; "
          "same bytes {}",
          i, frames[i].size(), records[i].captured, records[i].original, records[i].seconds,
          records[i].fraction, got == want);
  }
  INFO(first);
  CHECK(mismatched == 0);
}

// SIGHUP again and again while datagrams of changing lengths arrive (raw batches of 5, rotation
// mid-batch), then SIGTERM as soon as the last is sent: the recordings, in order, hold the
// datagrams in the order sent, each as sent; whatever is not recorded is counted.
TEST_CASE("recording hostile: SIGHUP mid-batch and SIGTERM right after a burst",
          "[recording_hostile][threads]") {
  test::ScratchDir dir("rec-hostile-hup");
  test::LiveDaemon daemon(dir, "[arenas]\npackets_per_frame = 5\n", {"--mcap", "--mcap-packets"});
  REQUIRE(daemon.ready());
  std::vector<Bytes> sent;
  for (std::size_t i = 0; i < 6000; ++i)
    sent.push_back(datagram((i * 37) % 1300 + 1, i));
  {
    io::UniqueFd fd(::socket(AF_INET, SOCK_DGRAM, 0));
    REQUIRE(fd);
    sockaddr_in to{};
    to.sin_family = AF_INET;
    to.sin_port = htons(daemon.port);
    inet_pton(AF_INET, "127.0.0.1", &to.sin_addr);
    for (std::size_t i = 0; i < sent.size(); ++i) {
      REQUIRE(::sendto(fd.get(), sent[i].data(), sent[i].size(), 0,
                       reinterpret_cast<const sockaddr*>(&to),
                       sizeof to) == static_cast<ssize_t>(sent[i].size()));
      if (i % 500 == 250) daemon.process->signal(SIGHUP);
      if (i % 16 == 0 && i < 4000) std::this_thread::sleep_for(500us);
    }
  }
  daemon.process->signal(SIGTERM);
  daemon.exit_status = daemon.process->wait_exit(30s);
  INFO(daemon.process->log());
  REQUIRE(daemon.exit_status == 0);
  const nlohmann::json h = test::last_health_record(daemon.out);
  INFO(h.dump());
  const auto c = [&](const char* name) { return test::health_counter(h, name); };
  const std::vector<PcapRecord> records = read_pcaps(daemon.out / "raw");
  CHECK(test::files_ending(daemon.out / "raw", ".pcap").size() >= 6);
  CHECK(records.size() == c("pcap_packets_written"));
  CHECK(c("datagrams_received") ==
        c("pcap_packets_written") + c("pcap_packets_not_recorded") + c("pcap_packets_not_written"));
  // In order, each as sent: a subsequence of what was sent.
  std::size_t next = 0, matched = 0;
  for (const PcapRecord& r : records) {
    const Udp u = udp_of(r.bytes);
    while (next < sent.size() && as_string(sent[next]).substr(0, 1280) != u.payload)
      ++next;
    if (next == sent.size()) break;
    ++matched;
    ++next;
  }
  CHECK(matched == records.size());
  // The MCAP recordings: the same datagrams.
  std::vector<std::string> messages;
  for (const fs::path& f : test::files_ending(daemon.out / "mcap", ".mcap")) {
    CaptureReader reader(f.string());
    CaptureRecord record;
    while (reader.next(record) == CaptureStatus::kRecord)
      messages.emplace_back(record.payload.begin(), record.payload.end());
  }
  CHECK(messages.size() == records.size());
  std::size_t same = 0;
  for (std::size_t i = 0; i < std::min(messages.size(), records.size()); ++i)
    same += messages[i] == udp_of(records[i].bytes).payload;
  CHECK(same == records.size());
}

}  // namespace pandarcap
