// CaptureReader and PcapWriter: round trips, every link type and skip reason, truncated and
// corrupt files (classic pcap and pcapng), and the real captures.
#include <algorithm>
#include <catch2/catch.hpp>
#include <cerrno>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <limits>
#include <random>
#include <system_error>
#include <tuple>
#include <vector>

#include "daemon/pcap/capture_reader.hpp"
#include "daemon/pcap/pcap_writer.hpp"
#include "support/capture_bytes.hpp"
#include "support/test_support.hpp"

using pandarcap::CaptureReader;
using pandarcap::CaptureRecord;
using pandarcap::CaptureStats;
using pandarcap::CaptureStatus;
using pandarcap::Endpoint;
using pandarcap::PcapWriter;
using pandarcap::test::ScratchDir;

namespace {

using pandarcap::test::append;
using pandarcap::test::Bytes;
using pandarcap::test::get_be16;
using pandarcap::test::pcapng_header;
using pandarcap::test::pcapng_packet;
using pandarcap::test::put_be16;
using pandarcap::test::put_be32;
using pandarcap::test::put_le16;
using pandarcap::test::put_le32;
namespace fs = std::filesystem;

constexpr Endpoint kLidar{0xC0A801C9, 2368};  // 192.168.1.201:2368
constexpr Endpoint kHost{0xC0A8010A, 2368};   // 192.168.1.10:2368
// [fd00::201]:2368 and [fd00::10]:2368
constexpr Endpoint kLidar6{
    0, 2368, true, {0xFD, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x02, 0x01}};
constexpr Endpoint kHost6{0, 2368, true, {0xFD, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0x10}};

constexpr std::uint32_t kLinktypeEthernet = 1;
constexpr std::uint32_t kLinktypeRaw = 101;
constexpr std::uint32_t kLinktypeIpv4 = 228;
constexpr std::uint32_t kLinktypeIpv6 = 229;
constexpr std::uint32_t kLinktypeLinuxSll = 113;
constexpr std::uint32_t kLinktypeLinuxSll2 = 276;
constexpr std::uint32_t kLinktypePpp = 9;

constexpr std::uint16_t kEthertypeIpv4 = 0x0800;
constexpr std::uint16_t kEthertypeArp = 0x0806;
constexpr std::uint16_t kEthertypeIpv6 = 0x86DD;

constexpr std::size_t kGlobalHeaderBytes = 24;
constexpr std::size_t kRecordHeaderBytes = 16;
constexpr std::size_t kFrameHeadersBytes = 14 + 20 + 8;  // Ethernet + IPv4 + UDP

Bytes pattern(std::size_t size, std::uint8_t seed) {
  Bytes bytes(size);
  for (std::size_t i = 0; i < size; ++i) {
    bytes[i] = static_cast<std::uint8_t>(seed + i * 7);
  }
  return bytes;
}

Bytes read_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  REQUIRE(in);
  return Bytes(std::istreambuf_iterator<char>(in), {});
}
void write_bytes(const fs::path& path, const Bytes& bytes, std::size_t size) {
  REQUIRE(size <= bytes.size());
  std::ofstream out(path, std::ios::binary);
  out.write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(size));
  REQUIRE(out);
}
void write_bytes(const fs::path& path, const Bytes& bytes) {
  write_bytes(path, bytes, bytes.size());
}

// What to put in (or get wrong in) a synthesised IPv4 / UDP datagram.
struct Datagram {
  Bytes payload;
  Endpoint source = kLidar;
  Endpoint destination = kHost;
  std::uint8_t protocol = 17;
  std::uint16_t flags_fragment = 0x4000;  // DF
  std::uint8_t version_ihl = 0x45;
  int total_length_delta = 0;  // added to the correct IPv4 total length
  int udp_length_delta = 0;    // added to the correct UDP length
};

Bytes ipv4(const Datagram& d) {
  Bytes out;
  out.push_back(d.version_ihl);
  out.push_back(0);
  put_be16(out, static_cast<std::uint16_t>(28 + d.payload.size() + d.total_length_delta));
  put_be16(out, 0x1234);
  put_be16(out, d.flags_fragment);
  out.push_back(64);
  out.push_back(d.protocol);
  put_be16(out, 0);  // the reader does not check the header checksum
  put_be32(out, d.source.ip);
  put_be32(out, d.destination.ip);
  put_be16(out, d.source.port);
  put_be16(out, d.destination.port);
  put_be16(out, static_cast<std::uint16_t>(8 + d.payload.size() + d.udp_length_delta));
  put_be16(out, 0);
  append(out, d.payload);
  return out;
}

// An IPv6 / UDP datagram (RFC 8200) from `d` (its IPv6 endpoints; protocol and the length deltas
// as for IPv4), behind `extensions`: pairs of (next-header value of the extension, its bytes), in
// order. Each extension's first byte (its next-header field) is filled in here.
Bytes ipv6(const Datagram& d, std::vector<std::pair<std::uint8_t, Bytes>> extensions = {}) {
  Bytes chain;
  for (std::size_t i = 0; i < extensions.size(); ++i) {
    Bytes header = extensions[i].second;
    header[0] = i + 1 < extensions.size() ? extensions[i + 1].first : d.protocol;
    append(chain, header);
  }
  Bytes out;
  put_be32(out, 0x60000000);
  put_be16(out,
           static_cast<std::uint16_t>(chain.size() + 8 + d.payload.size() + d.total_length_delta));
  out.push_back(extensions.empty() ? d.protocol : extensions.front().first);
  out.push_back(64);
  out.insert(out.end(), d.source.ip6.begin(), d.source.ip6.end());
  out.insert(out.end(), d.destination.ip6.begin(), d.destination.ip6.end());
  append(out, chain);
  put_be16(out, d.source.port);
  put_be16(out, d.destination.port);
  put_be16(out, static_cast<std::uint16_t>(8 + d.payload.size() + d.udp_length_delta));
  put_be16(out, 0);
  append(out, d.payload);
  return out;
}

// Ethernet frame; `tags` are the TPIDs of VLAN tags, outermost first.
Bytes ethernet(const Bytes& body, std::uint16_t ethertype = kEthertypeIpv4,
               const std::vector<std::uint16_t>& tags = {}) {
  Bytes out = {0x02, 0, 0, 0, 0, 0x02, 0x02, 0, 0, 0, 0, 0x01};
  for (std::uint16_t tpid : tags) {
    put_be16(out, tpid);
    put_be16(out, 0x0064);  // PCP 0, VLAN 100
  }
  put_be16(out, ethertype);
  append(out, body);
  return out;
}

Bytes linux_sll(const Bytes& body, std::uint16_t protocol = kEthertypeIpv4) {
  Bytes out;
  put_be16(out, 0);  // packet type: to us
  put_be16(out, 1);  // ARPHRD_ETHER
  put_be16(out, 6);  // address length
  append(out, {0x02, 0, 0, 0, 0, 0x01, 0, 0});
  put_be16(out, protocol);
  append(out, body);
  return out;
}

Bytes linux_sll2(const Bytes& body, std::uint16_t protocol = kEthertypeIpv4) {
  Bytes out;
  put_be16(out, protocol);
  put_be16(out, 0);  // reserved
  put_be32(out, 2);  // interface index
  put_be16(out, 1);  // ARPHRD_ETHER
  out.push_back(0);  // packet type: to us
  out.push_back(6);  // address length
  append(out, {0x02, 0, 0, 0, 0, 0x01, 0, 0});
  append(out, body);
  return out;
}

// A classic pcap file built byte by byte (little-endian, as written on x86).
class PcapFile {
 public:
  explicit PcapFile(std::uint32_t linktype, bool nanosecond = false) {
    put_le32(bytes_, nanosecond ? 0xA1B23C4D : 0xA1B2C3D4);
    put_le16(bytes_, 2);
    put_le16(bytes_, 4);
    put_le32(bytes_, 0);
    put_le32(bytes_, 0);
    put_le32(bytes_, 65535);
    put_le32(bytes_, linktype);
  }
  // Captured length = frame.size(); the original length defaults to the same.
  PcapFile& add(const Bytes& frame, std::uint32_t seconds = 1'700'000'000,
                std::uint32_t fraction = 0, std::size_t original_length = 0) {
    put_le32(bytes_, seconds);
    put_le32(bytes_, fraction);
    put_le32(bytes_, static_cast<std::uint32_t>(frame.size()));
    put_le32(bytes_, static_cast<std::uint32_t>(std::max(original_length, frame.size())));
    append(bytes_, frame);
    return *this;
  }
  const Bytes& bytes() const { return bytes_; }
  void save(const fs::path& path) const { write_bytes(path, bytes_); }

 private:
  Bytes bytes_;
};

// Everything a reader yields from a file, copied out of the reader.
struct ReadResult {
  struct Record {
    Bytes payload;
    std::int64_t timestamp_ns = 0;
    Endpoint source;
    Endpoint destination;
    std::uint32_t udp_payload_length = 0;
    bool snapped = false;
  };
  std::vector<Record> records;
  CaptureStatus status = CaptureStatus::kRecord;
  std::string error;
  CaptureStats stats;
};

ReadResult read_capture(const fs::path& path, CaptureReader::Options options = {}) {
  CaptureReader reader(path.string(), options);
  ReadResult result;
  pandarcap::CaptureRecord record;
  while ((result.status = reader.next(record)) == CaptureStatus::kRecord) {
    result.records.push_back({Bytes(record.payload.begin(), record.payload.end()),
                              record.timestamp_ns, record.source, record.destination,
                              record.udp_payload_length, record.snapped});
  }
  // A final status is sticky.
  CHECK(reader.next(record) == result.status);
  CHECK(reader.next(record) == result.status);
  result.error = reader.error();
  result.stats = reader.stats();
  const CaptureStats& s = result.stats;
  // Every record is accounted for exactly once.
  CHECK(s.records ==
        s.udp_datagrams + s.port_filtered + s.non_ip + s.non_udp + s.ip_fragments + s.malformed);
  CHECK(s.udp_datagrams == result.records.size());
  return result;
}

std::string tcpdump_path() {
  for (const char* candidate : {"/usr/bin/tcpdump", "/usr/sbin/tcpdump"}) {
    if (fs::exists(candidate)) return candidate;
  }
  return {};
}

std::size_t count(const std::string& haystack, const std::string& needle) {
  std::size_t n = 0;
  for (std::size_t at = haystack.find(needle); at != std::string::npos;
       at = haystack.find(needle, at + needle.size())) {
    ++n;
  }
  return n;
}

}  // namespace

TEST_CASE("to_string formats an endpoint as dotted quad (or [IPv6]) and port", "[capture]") {
  CHECK(pandarcap::to_string(kLidar) == "192.168.1.201:2368");
  CHECK(pandarcap::to_string(Endpoint{0xFFFFFFFF, 65535}) == "255.255.255.255:65535");
  CHECK(pandarcap::to_string(Endpoint{}) == "0.0.0.0:0");
  CHECK(pandarcap::to_string(kLidar6) == "[fd00::201]:2368");
}

TEST_CASE("classic pcap times from 2038 to 2106 read back as written, not negative", "[capture]") {
  ScratchDir dir("capture-2038");
  const fs::path path = dir / "future.pcap";
  // 2038-01-19T03:14:08Z (the first second past INT32_MAX), 2070, and the last second of 2105.
  const std::vector<std::int64_t> times = {2'147'483'648'000'000'000, 3'155'760'000'123'456'000,
                                           4'291'747'199'999'999'000};
  {
    PcapWriter writer(path.string());
    for (const std::int64_t t : times)
      writer.write(pattern(1262, 1), t, {0x7F000001, 1}, {0x7F000001, 2368});
    writer.close();
  }
  CaptureReader reader(path.string());
  CaptureRecord record;
  for (const std::int64_t t : times) {
    REQUIRE(reader.next(record) == CaptureStatus::kRecord);
    CHECK(record.timestamp_ns == t);
  }
  CHECK(reader.next(record) == CaptureStatus::kEnd);
}

TEST_CASE("PcapWriter output reads back identically", "[capture]") {
  ScratchDir dir("capture");
  const fs::path path = dir / "round_trip.pcap";
  const std::vector<std::size_t> sizes = {1262, 1266, 0, 1, 7, 9000, 65507};
  std::vector<Bytes> payloads;
  std::vector<std::int64_t> timestamps;
  std::vector<Endpoint> sources;
  std::vector<Endpoint> destinations;
  std::uint64_t expected_bytes = kGlobalHeaderBytes;
  {
    PcapWriter writer(path.string());
    CHECK(writer.path() == path.string());
    CHECK(writer.bytes() == kGlobalHeaderBytes);
    for (std::size_t i = 0; i < sizes.size(); ++i) {
      payloads.push_back(pattern(sizes[i], static_cast<std::uint8_t>(i)));
      // Distinct seconds and sub-microsecond digits that the writer must drop.
      timestamps.push_back(1'700'000'000'000'000'000 +
                           static_cast<std::int64_t>(i) * 1'234'567'891);
      sources.push_back(
          {0x0A000001 + static_cast<std::uint32_t>(i), static_cast<std::uint16_t>(10000 + i)});
      destinations.push_back(
          {0xC0A86400 + static_cast<std::uint32_t>(i), static_cast<std::uint16_t>(2368 + i)});
      writer.write(payloads[i], timestamps[i], sources[i], destinations[i]);
      expected_bytes += kRecordHeaderBytes + kFrameHeadersBytes + sizes[i];
      CHECK(writer.records() == i + 1);
      CHECK(writer.bytes() == expected_bytes);
    }
    writer.close();
    writer.close();  // idempotent
  }
  REQUIRE(fs::file_size(path) == expected_bytes);

  const ReadResult result = read_capture(path);
  REQUIRE(result.status == CaptureStatus::kEnd);
  CHECK(result.error.empty());
  REQUIRE(result.records.size() == sizes.size());
  for (std::size_t i = 0; i < sizes.size(); ++i) {
    INFO("record " << i);
    const ReadResult::Record& r = result.records[i];
    CHECK(r.payload == payloads[i]);
    CHECK(r.udp_payload_length == sizes[i]);
    CHECK_FALSE(r.snapped);
    CHECK(r.source == sources[i]);
    CHECK(r.destination == destinations[i]);
    CHECK(r.timestamp_ns == timestamps[i] / 1000 * 1000);
  }
  CHECK(result.stats.records == sizes.size());
  CHECK(result.stats.udp_datagrams == sizes.size());
  CHECK(result.stats.malformed == 0);
  CHECK(result.stats.snapped == 0);

  const std::string tcpdump = tcpdump_path();
  if (tcpdump.empty()) {
    WARN("tcpdump not installed: skipping the third-party read of the file");
    return;
  }
  // -v prints each IPv4 header and flags a wrong header checksum with "bad cksum".
  const auto run =
      pandarcap::test::run_command(tcpdump + " -nn -v -r '" + path.string() + "' 2>&1");
  INFO(run.out);
  CHECK(run.exit_code == 0);
  CHECK(count(run.out, "proto UDP (17)") == sizes.size());
  CHECK(count(run.out, "ttl 64") == sizes.size());
  CHECK(count(run.out, "flags [DF]") == sizes.size());
  CHECK(count(run.out, "bad cksum") == 0);
  CHECK(run.out.find("10.0.0.1.10000 > 192.168.100.0.2368: UDP, length 1262") != std::string::npos);
  CHECK(run.out.find("UDP, length 65507") != std::string::npos);
}

TEST_CASE("PcapWriter writes the documented headers", "[capture]") {
  ScratchDir dir("capture");
  const fs::path path = dir / "headers.pcap";
  {
    PcapWriter writer(path.string());
    writer.write(pattern(4, 1), 1'700'000'000'123'456'789, kLidar, kHost);
    writer.write(pattern(4, 2), 1'700'000'001'000'000'000, kLidar, kHost);
  }  // the destructor closes
  const Bytes file = read_bytes(path);
  REQUIRE(file.size() == kGlobalHeaderBytes + 2 * (kRecordHeaderBytes + kFrameHeadersBytes + 4));

  // Global header, native byte order (the reader detects the order from the magic).
  const auto native16 = [&](std::size_t offset) {
    std::uint16_t v = 0;
    std::memcpy(&v, file.data() + offset, sizeof v);
    return v;
  };
  const auto native32 = [&](std::size_t offset) {
    std::uint32_t v = 0;
    std::memcpy(&v, file.data() + offset, sizeof v);
    return v;
  };
  CHECK(native32(0) == 0xA1B2C3D4);
  CHECK(native16(4) == 2);  // version 2.4
  CHECK(native16(6) == 4);
  CHECK(native32(16) >= 65535 + 14);  // snaplen fits the largest frame
  CHECK(native32(20) == kLinktypeEthernet);

  std::size_t at = kGlobalHeaderBytes;
  CHECK(native32(at) == 1'700'000'000);
  CHECK(native32(at + 4) == 123'456);  // microseconds
  CHECK(native32(at + 8) == kFrameHeadersBytes + 4);
  CHECK(native32(at + 12) == kFrameHeadersBytes + 4);
  at += kRecordHeaderBytes;
  CHECK(Bytes(file.begin() + at, file.begin() + at + 14) ==
        Bytes{0x02, 0, 0, 0, 0, 0x02, 0x02, 0, 0, 0, 0, 0x01, 0x08, 0x00});
  const std::size_t ip = at + 14;
  CHECK(file[ip] == 0x45);
  CHECK(get_be16(file, ip + 2) == 32);      // total length 20 + 8 + 4
  CHECK(get_be16(file, ip + 6) == 0x4000);  // DF, offset 0
  CHECK(file[ip + 8] == 64);                // TTL
  CHECK(file[ip + 9] == 17);                // UDP
  std::uint32_t sum = 0;                    // a correct header sums to 0xFFFF in one's complement
  for (std::size_t i = 0; i < 20; i += 2) {
    sum += get_be16(file, ip + i);
  }
  while (sum > 0xFFFF) {
    sum = (sum & 0xFFFF) + (sum >> 16);
  }
  CHECK(sum == 0xFFFF);
  const std::size_t udp = ip + 20;
  CHECK(get_be16(file, udp) == kLidar.port);
  CHECK(get_be16(file, udp + 4) == 12);
  CHECK(get_be16(file, udp + 6) == 0);  // checksum not computed

  const std::size_t ip2 =
      kGlobalHeaderBytes + (kRecordHeaderBytes + kFrameHeadersBytes + 4) + kRecordHeaderBytes + 14;
  CHECK(get_be16(file, ip2 + 4) == static_cast<std::uint16_t>(get_be16(file, ip + 4) + 1));
}

TEST_CASE("PcapWriter records a cut datagram as cut: the bytes kept, the length it had",
          "[capture]") {
  ScratchDir dir("capture");
  const fs::path path = dir / "cut.pcap";
  {
    PcapWriter writer(path.string());
    writer.write(pattern(1280, 1), 1281, 1'700'000'000'000'000'000, kLidar, kHost);
    writer.write(pattern(1280, 2), 100'000, 1'700'000'000'000'001'000, kLidar, kHost);  // > IPv4
    writer.write(pattern(8, 3), 4, 1'700'000'000'000'002'000, kLidar, kHost);  // never below kept
  }
  const Bytes file = read_bytes(path);
  const auto native32 = [&](std::size_t offset) {
    std::uint32_t v = 0;
    std::memcpy(&v, file.data() + offset, sizeof v);
    return v;
  };
  std::size_t at = kGlobalHeaderBytes;
  CHECK(native32(at + 8) == kFrameHeadersBytes + 1280);                      // captured
  CHECK(native32(at + 12) == kFrameHeadersBytes + 1281);                     // original
  CHECK(get_be16(file, at + kRecordHeaderBytes + 14 + 2) == 20 + 8 + 1281);  // IPv4 length
  CHECK(get_be16(file, at + kRecordHeaderBytes + 14 + 20 + 4) == 8 + 1281);  // UDP length
  at += kRecordHeaderBytes + kFrameHeadersBytes + 1280;
  CHECK(native32(at + 12) == kFrameHeadersBytes + 65507);  // the most IPv4 can say
  CHECK(get_be16(file, at + kRecordHeaderBytes + 14 + 2) == 65535);

  CaptureReader reader(path.string());
  CaptureRecord record;
  std::vector<std::tuple<std::size_t, std::uint32_t, bool>> read;
  while (reader.next(record) == CaptureStatus::kRecord)
    read.emplace_back(record.payload.size(), record.udp_payload_length, record.snapped);
  CHECK(read == std::vector<std::tuple<std::size_t, std::uint32_t, bool>>{
                    {1280, 1281, true}, {1280, 65507, true}, {8, 8, false}});
}

TEST_CASE("PcapWriter rejects what a pcap record cannot hold", "[capture]") {
  ScratchDir dir("capture");
  PcapWriter writer((dir / "reject.pcap").string());
  CHECK_THROWS_AS(writer.write(Bytes(65508), 0, kLidar, kHost), std::invalid_argument);
  CHECK_THROWS_AS(writer.write(Bytes(4), -1, kLidar, kHost), std::invalid_argument);
  CHECK_THROWS_AS(writer.write(Bytes(4), std::int64_t{1} << 32 << 30, kLidar, kHost),
                  std::invalid_argument);
  CHECK(writer.records() == 0);
  CHECK(writer.bytes() == kGlobalHeaderBytes);
}

TEST_CASE("PcapWriter reports a file it cannot open as system_error with errno and path",
          "[capture]") {
  ScratchDir dir("capture");
  const std::string missing_dir = (dir / "no_such_dir" / "x.pcap").string();
  try {
    PcapWriter writer(missing_dir);
    FAIL("opening a file in a missing directory did not throw");
  } catch (const std::system_error& e) {
    CHECK(e.code() == std::error_code(ENOENT, std::generic_category()));
    CHECK_THAT(e.what(), Catch::Contains("cannot open '" + missing_dir + "'"));
  }

  SECTION("a full disk surfaces at creation: the header is written at once") {
    if (!fs::exists("/dev/full")) return;
    try {
      PcapWriter writer("/dev/full");
      FAIL("creating a recording on /dev/full did not throw");
    } catch (const std::system_error& e) {
      CHECK(e.code() == std::error_code(ENOSPC, std::generic_category()));
      CHECK_THAT(e.what(), Catch::Contains("/dev/full"));
    }
  }
  SECTION("writing after close") {
    PcapWriter writer((dir / "closed.pcap").string());
    writer.close();
    const std::error_code bad_file(EBADF, std::generic_category());
    CHECK_THROWS_MATCHES(writer.write(pattern(4, 0), 0, kLidar, kHost), std::system_error,
                         Catch::Predicate<std::system_error>(
                             [&](const std::system_error& e) { return e.code() == bad_file; }));
    CHECK_THROWS_AS(writer.flush(), std::system_error);
  }
}

TEST_CASE("destination-port filter keeps one port and counts the rest", "[capture]") {
  ScratchDir dir("capture");
  const fs::path path = dir / "ports.pcap";
  {
    PcapWriter writer(path.string());
    const std::vector<std::uint16_t> ports = {2368, 2369, 2368, 10110, 2368};
    for (std::size_t i = 0; i < ports.size(); ++i) {
      writer.write(pattern(16, static_cast<std::uint8_t>(i)), static_cast<std::int64_t>(i) * 1000,
                   kLidar, {kHost.ip, ports[i]});
    }
  }
  const ReadResult all = read_capture(path);
  CHECK(all.records.size() == 5);
  CHECK(all.stats.port_filtered == 0);

  const ReadResult kept = read_capture(path, {.destination_port = 2368});
  REQUIRE(kept.status == CaptureStatus::kEnd);
  REQUIRE(kept.records.size() == 3);
  CHECK(kept.records[0].payload == pattern(16, 0));
  CHECK(kept.records[1].payload == pattern(16, 2));
  CHECK(kept.records[2].payload == pattern(16, 4));
  CHECK(kept.stats.records == 5);
  CHECK(kept.stats.port_filtered == 2);

  const ReadResult none = read_capture(path, {.destination_port = 1});
  CHECK(none.records.empty());
  CHECK(none.stats.port_filtered == 5);
}

TEST_CASE("a classic pcap cut short yields every complete record, then kTruncated", "[capture]") {
  ScratchDir dir("capture");
  const fs::path whole = dir / "whole.pcap";
  {
    PcapWriter writer(whole.string());
    for (int i = 0; i < 3; ++i) {
      writer.write(pattern(1262, static_cast<std::uint8_t>(i)), i, kLidar, kHost);
    }
  }
  const Bytes file = read_bytes(whole);
  const std::size_t record_bytes = kRecordHeaderBytes + kFrameHeadersBytes + 1262;
  const std::size_t third = kGlobalHeaderBytes + 2 * record_bytes;  // offset of the third record
  const fs::path cut = dir / "cut.pcap";

  SECTION("cut in the middle of a record's data") {
    write_bytes(cut, file, third + kRecordHeaderBytes + 500);
    const ReadResult result = read_capture(cut);
    CHECK(result.records.size() == 2);
    CHECK(result.records[1].payload == pattern(1262, 1));
    CHECK(result.status == CaptureStatus::kTruncated);
    // libpcap: "truncated dump file; tried to read 1304 captured bytes, only got 500"
    CHECK_THAT(result.error, Catch::StartsWith(cut.string() + ": truncated dump file"));
    CHECK_THAT(result.error, Catch::Contains("only got 500"));
  }
  SECTION("cut in the middle of a record header") {
    write_bytes(cut, file, third + 5);
    const ReadResult result = read_capture(cut);
    CHECK(result.records.size() == 2);
    CHECK(result.status == CaptureStatus::kTruncated);
    // libpcap: "truncated dump file; tried to read 16 header bytes, only got 5"
    CHECK_THAT(result.error, Catch::Contains("truncated dump file"));
    CHECK_THAT(result.error, Catch::Contains("header bytes, only got 5"));
  }
  SECTION("cut on a record boundary is a clean end") {
    write_bytes(cut, file, third);
    const ReadResult result = read_capture(cut);
    CHECK(result.records.size() == 2);
    CHECK(result.status == CaptureStatus::kEnd);
    CHECK(result.error.empty());
  }
  SECTION("a global header and no records is a clean, empty capture") {
    write_bytes(cut, file, kGlobalHeaderBytes);
    const ReadResult result = read_capture(cut);
    CHECK(result.records.empty());
    CHECK(result.status == CaptureStatus::kEnd);
  }
}

TEST_CASE("a corrupt record header ends the read with kError, never a crash", "[capture]") {
  ScratchDir dir("capture");
  const fs::path whole = dir / "whole.pcap";
  {
    PcapWriter writer(whole.string());
    for (int i = 0; i < 3; ++i) {
      writer.write(pattern(100, static_cast<std::uint8_t>(i)), i, kLidar, kHost);
    }
  }
  Bytes file = read_bytes(whole);
  const std::size_t second = kGlobalHeaderBytes + kRecordHeaderBytes + kFrameHeadersBytes + 100;
  const auto set_captured_length = [&](std::uint32_t caplen) {  // native order, as written
    std::memcpy(file.data() + second + 8, &caplen, sizeof caplen);
  };
  const fs::path corrupt = dir / "corrupt.pcap";

  SECTION("captured length beyond any snaplen") {
    set_captured_length(0xFFFFFF00);
    write_bytes(corrupt, file);
    const ReadResult result = read_capture(corrupt);
    CHECK(result.records.size() == 1);
    // libpcap 1.10.3: "invalid packet capture length 4294967040, bigger than snaplen of 262144"
    CHECK(result.status == CaptureStatus::kError);
    CHECK_THAT(result.error, Catch::StartsWith(corrupt.string() + ": "));
    CHECK_THAT(result.error, Catch::Contains("invalid packet capture length 4294967040"));
  }
  SECTION("a plausible captured length that runs past the end reads as truncation") {
    set_captured_length(100'000);  // below the snaplen: libpcap cannot tell it from a cut file
    write_bytes(corrupt, file);
    const ReadResult result = read_capture(corrupt);
    CHECK(result.records.size() == 1);
    // libpcap 1.10.3: "truncated dump file; tried to read 100000 captured bytes, only got 300"
    CHECK(result.status == CaptureStatus::kTruncated);
    CHECK_THAT(result.error, Catch::Contains("tried to read 100000 captured bytes"));
  }
}

TEST_CASE("files that are not captures make the constructor throw", "[capture]") {
  ScratchDir dir("capture");
  const auto expect_throw = [](const fs::path& path, const std::string& reason) {
    try {
      CaptureReader reader(path.string());
      FAIL("no exception for " << path);
    } catch (const pandarcap::CaptureError& e) {
      CHECK_THAT(e.what(), Catch::Contains(path.string()));
      CHECK_THAT(e.what(), Catch::Contains(reason));
    }
  };
  expect_throw(dir / "missing.pcap", "No such file or directory");

  const fs::path text = dir / "notes.txt";
  write_bytes(text, Bytes{'h', 'e', 'l', 'l', 'o', ' ', 'p', 'c', 'a', 'p', '\n'});
  expect_throw(text, "unknown file format");

  const fs::path empty = dir / "empty.pcap";
  write_bytes(empty, Bytes{});
  expect_throw(empty, "truncated dump file");

  const fs::path ppp = dir / "ppp.pcap";
  PcapFile(kLinktypePpp).add(ipv4({.payload = pattern(8, 0)})).save(ppp);
  expect_throw(ppp, "unsupported link type PPP");
}

TEST_CASE("Ethernet frames with any number of VLAN tags", "[capture]") {
  ScratchDir dir("capture");
  const fs::path path = dir / "vlan.pcap";
  PcapFile(kLinktypeEthernet)
      .add(ethernet(ipv4({.payload = pattern(10, 0)})))
      .add(ethernet(ipv4({.payload = pattern(11, 1)}), kEthertypeIpv4, {0x8100}))
      .add(ethernet(ipv4({.payload = pattern(12, 2)}), kEthertypeIpv4, {0x88A8, 0x8100}))
      .add(ethernet(ipv4({.payload = pattern(13, 3)}), kEthertypeIpv4, {0x9100, 0x8100, 0x8100}))
      .add(ethernet(ipv6({.payload = pattern(14, 4), .source = kLidar6, .destination = kHost6}),
                    kEthertypeIpv6, {0x8100}))
      .add(ethernet(Bytes(28, 0), kEthertypeArp, {0x8100}))
      .save(path);
  const ReadResult result = read_capture(path);
  REQUIRE(result.status == CaptureStatus::kEnd);
  REQUIRE(result.records.size() == 5);
  for (std::size_t i = 0; i < 5; ++i) {
    CHECK(result.records[i].payload == pattern(10 + i, static_cast<std::uint8_t>(i)));
    CHECK(result.records[i].source == (i < 4 ? kLidar : kLidar6));
    CHECK(result.records[i].destination == (i < 4 ? kHost : kHost6));
  }
  CHECK(result.stats.ipv6_datagrams == 1);  // IPv6 behind a VLAN tag
  CHECK(result.stats.non_ip == 1);          // ARP behind one
}

TEST_CASE("Linux cooked captures v1 (SLL) and v2 (SLL2)", "[capture]") {
  ScratchDir dir("capture");
  const Endpoint source{0x0A000002, 5555};
  const Datagram datagram{.payload = pattern(33, 9), .source = source};
  struct Case {
    std::uint32_t linktype;
    Bytes (*frame)(const Bytes&, std::uint16_t);
  };
  for (const Case& c : {Case{kLinktypeLinuxSll, linux_sll}, Case{kLinktypeLinuxSll2, linux_sll2}}) {
    INFO("linktype " << c.linktype);
    const fs::path path = dir / ("cooked" + std::to_string(c.linktype) + ".pcap");
    PcapFile(c.linktype)
        .add(c.frame(ipv4(datagram), kEthertypeIpv4))
        .add(c.frame(ipv4(datagram), kEthertypeArp))
        .save(path);
    CHECK(CaptureReader(path.string()).link_type() == static_cast<int>(c.linktype));
    const ReadResult result = read_capture(path);
    REQUIRE(result.records.size() == 1);
    CHECK(result.records[0].payload == datagram.payload);
    CHECK(result.records[0].source == source);
    CHECK(result.stats.non_ip == 1);
  }
}

TEST_CASE("raw IP link types: LINKTYPE_RAW, LINKTYPE_IPV4/IPV6 and DLT_RAW's values", "[capture]") {
  ScratchDir dir("capture");
  const Datagram datagram{.payload = pattern(20, 5)};
  const Datagram datagram6{.payload = pattern(21, 6), .source = kLidar6, .destination = kHost6};
  Bytes ipv6_jumbo(48, 0);  // payload length 0: a jumbogram's, refused
  ipv6_jumbo[0] = 0x60;
  for (std::uint32_t linktype :
       {kLinktypeRaw, kLinktypeIpv4, kLinktypeIpv6, std::uint32_t{12}, std::uint32_t{14}}) {
    INFO("linktype " << linktype);
    const fs::path path = dir / ("raw" + std::to_string(linktype) + ".pcap");
    PcapFile(linktype)
        .add(ipv4(datagram))
        .add(ipv6(datagram6))
        .add(ipv6_jumbo)
        .add(Bytes{})
        .save(path);
    const ReadResult result = read_capture(path);
    REQUIRE(result.records.size() == 2);
    CHECK(result.records[0].payload == datagram.payload);
    CHECK(result.records[0].destination == kHost);
    CHECK(result.records[1].payload == datagram6.payload);
    CHECK(result.records[1].source == kLidar6);
    CHECK(result.records[1].destination == kHost6);
    CHECK(result.stats.ipv6_datagrams == 1);
    CHECK(result.stats.malformed == 2);  // the jumbogram and the empty record
  }
}

TEST_CASE("IPv6 / UDP: behind extension headers, fragments and other protocols counted",
          "[capture]") {
  ScratchDir dir("capture");
  const fs::path path = dir / "ipv6.pcap";
  const Datagram d{.payload = pattern(30, 8), .source = kLidar6, .destination = kHost6};
  const Bytes options8 = {0, 0, 1, 4, 0, 0, 0, 0};  // hop-by-hop / destination options: PadN
  const Bytes routing16 = {0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0};  // (1 + 1) * 8
  const Bytes auth12 = {0, 1, 0, 0, 0, 0, 0, 1, 0, 0, 0, 1};                 // AH: (1 + 2) * 4
  const Bytes fragment = {0, 0, 0, 1, 0, 0, 0, 7};                           // offset 0, M
  std::vector<std::pair<std::uint8_t, Bytes>> too_many;
  for (int i = 0; i < 9; ++i)
    too_many.emplace_back(std::uint8_t{60}, options8);
  Datagram tcp = d;
  tcp.protocol = 6;
  Datagram long_udp = d;
  long_udp.udp_length_delta = 1;
  const Bytes chained = ethernet(
      ipv6(d, {{0, options8}, {43, routing16}, {51, auth12}, {60, options8}}), kEthertypeIpv6);
  PcapFile(kLinktypeEthernet)
      .add(ethernet(ipv6(d), kEthertypeIpv6))
      .add(chained)
      .add(ethernet(ipv6(d, {{44, fragment}}), kEthertypeIpv6))                 // ip_fragments
      .add(ethernet(ipv6(d, {{0, options8}, {44, fragment}}), kEthertypeIpv6))  // ip_fragments
      .add(ethernet(ipv6(tcp), kEthertypeIpv6))                                 // non_udp
      .add(ethernet(ipv6(d, too_many), kEthertypeIpv6))  // malformed: 9 extension headers
      .add(ethernet(ipv6(long_udp), kEthertypeIpv6))     // malformed: UDP longer than IP
      .add(ethernet(Bytes(39, 0x60), kEthertypeIpv6))    // malformed: header cut
      .add(ethernet(ipv4({.payload = d.payload}), kEthertypeIpv6))  // malformed: version 4
      .save(path);
  const ReadResult result = read_capture(path);
  REQUIRE(result.status == CaptureStatus::kEnd);
  REQUIRE(result.records.size() == 2);
  for (const auto& record : result.records) {
    CHECK(record.payload == d.payload);
    CHECK(record.source == kLidar6);
    CHECK(record.destination == kHost6);
    CHECK(record.udp_payload_length == d.payload.size());
  }
  CHECK(result.stats.ipv6_datagrams == 2);
  CHECK(result.stats.ip_fragments == 2);
  CHECK(result.stats.non_udp == 1);
  CHECK(result.stats.malformed == 4);
  CHECK(result.stats.skipped() == 7);
  // Every cut of the chained one stays inside the record: a payload is never longer than what
  // the record holds of it.
  const fs::path cut_path = dir / "ipv6-cut.pcap";
  for (std::size_t cut = 0; cut < chained.size(); ++cut) {
    INFO("cut at " << cut);
    PcapFile(kLinktypeEthernet)
        .add(Bytes(chained.begin(), chained.begin() + static_cast<std::ptrdiff_t>(cut)),
             1'700'000'000, 0, chained.size())
        .save(cut_path);
    const ReadResult cut_result = read_capture(cut_path);
    for (const auto& record : cut_result.records) {
      CHECK(record.snapped);
      CHECK(record.payload.size() < d.payload.size());
    }
  }
}

TEST_CASE("PcapWriter writes IPv6 datagrams with IPv6 headers and a valid UDP checksum",
          "[capture]") {
  ScratchDir dir("capture");
  const fs::path path = dir / "written6.pcap";
  const Bytes odd = pattern(1261, 3);  // an odd length: the checksum pads the last byte
  {
    PcapWriter writer(path.string());
    writer.write(odd, 1'700'000'000'000'000'000, kLidar6, kHost6);
    writer.write(std::span(odd).first(100), odd.size(), 1'700'000'000'000'001'000, kLidar6, kHost6);
    writer.close();
  }
  const ReadResult result = read_capture(path);
  REQUIRE(result.records.size() == 2);
  CHECK(result.records[0].payload == odd);
  CHECK(result.records[0].source == kLidar6);
  CHECK(result.records[0].destination == kHost6);
  CHECK(result.records[1].snapped);
  CHECK(result.records[1].udp_payload_length == odd.size());
  // The first record's frame, summed as a receiver checks it: pseudo-header + UDP header +
  // payload add up to 0xFFFF when the checksum is right.
  const Bytes file = read_bytes(path);
  const std::size_t frame = kGlobalHeaderBytes + kRecordHeaderBytes;
  CHECK(get_be16(file, frame + 12) == kEthertypeIpv6);
  CHECK(file[frame + 14] >> 4 == 6);
  CHECK(file[frame + 14 + 6] == 17);  // next header: UDP
  const std::size_t udp = frame + 14 + 40;
  const std::size_t udp_length = get_be16(file, udp + 4);
  CHECK(udp_length == 8 + odd.size());
  CHECK(get_be16(file, frame + 14 + 4) == udp_length);
  std::uint64_t sum = 0;
  for (std::size_t i = 0; i < 32; i += 2)
    sum += get_be16(file, frame + 14 + 8 + i);
  sum += udp_length + 17;
  for (std::size_t i = 0; i < udp_length; i += 2) {
    sum += i + 1 < udp_length ? get_be16(file, udp + i) : std::uint32_t{file[udp + i]} << 8;
  }
  while (sum >> 16)
    sum = (sum & 0xFFFF) + (sum >> 16);
  CHECK(sum == 0xFFFF);
  CHECK(get_be16(file, udp + 6) != 0);
  // The cut one: its sum cannot be known, so none is claimed.
  const std::size_t second = frame + 14 + 40 + 8 + odd.size() + kRecordHeaderBytes;
  CHECK(get_be16(file, second + 14 + 40 + 6) == 0);

  const std::string tcpdump = tcpdump_path();
  if (tcpdump.empty()) {
    WARN("tcpdump not installed: skipping the third-party read of the file");
    return;
  }
  // A third party's reading: -vv verifies the UDP checksum of an IPv6 datagram it holds whole.
  const auto run =
      pandarcap::test::run_command(tcpdump + " -nn -vv -r '" + path.string() + "' 2>&1");
  INFO(run.out);
  CHECK(run.exit_code == 0);
  CHECK(run.out.find("fd00::201.2368 > fd00::10.2368: [udp sum ok] UDP, length 1261") !=
        std::string::npos);
  CHECK(count(run.out, "bad udp cksum") == 0);
}

TEST_CASE("frames that are not usable UDP datagrams are counted and skipped", "[capture]") {
  ScratchDir dir("capture");
  const fs::path path = dir / "skipped.pcap";
  const Bytes payload = pattern(40, 3);
  const Bytes mac_only = {0x02, 0, 0, 0, 0, 0x02, 0x02, 0, 0, 0, 0, 0x01};
  PcapFile(kLinktypeEthernet)
      // non_ip
      .add(ethernet(Bytes(28, 0), kEthertypeArp))
      // non_udp
      .add(ethernet(ipv4({.payload = payload, .protocol = 6})))
      // ip_fragments: the first fragment (MF) and a later one (offset 185 * 8)
      .add(ethernet(ipv4({.payload = payload, .flags_fragment = 0x2000})))
      .add(ethernet(ipv4({.payload = payload, .flags_fragment = 0x00B9})))
      // malformed
      .add(ethernet(ipv4({.payload = payload, .udp_length_delta = 1})))    // UDP longer than IP
      .add(ethernet(ipv4({.payload = payload, .udp_length_delta = -41})))  // UDP length 7
      .add(ethernet(ipv4({.payload = payload, .version_ihl = 0x44})))      // IHL 4
      .add(ethernet(ipv4({.payload = {}, .version_ihl = 0x4F})))           // IHL 15 > captured
      .add(ethernet(ipv4({.payload = payload, .version_ihl = 0x55})))      // version 5
      .add(ethernet(ipv4({.payload = {}, .total_length_delta = -9})))      // total < header
      .add(ethernet(ipv4({.payload = {}, .total_length_delta = -4})))      // no room for UDP
      .add(Bytes(mac_only.begin(), mac_only.begin() + 10))                 // no ethertype
      .add(ethernet({}, 0x8100))                                           // tag cut off
      .add(ethernet(Bytes(19, 0x45)))                                      // IPv4 header cut
      .add(ethernet(Bytes(40, 0), kEthertypeIpv6))                         // IPv6 version 0
      // and reading goes on after all of them
      .add(ethernet(ipv4({.payload = payload})))
      .save(path);
  const ReadResult result = read_capture(path);
  REQUIRE(result.status == CaptureStatus::kEnd);
  REQUIRE(result.records.size() == 1);
  CHECK(result.records[0].payload == payload);
  CHECK(result.stats.records == 16);
  CHECK(result.stats.non_ip == 1);
  CHECK(result.stats.non_udp == 1);
  CHECK(result.stats.ip_fragments == 2);
  CHECK(result.stats.malformed == 11);
  CHECK(result.stats.udp_datagrams == 1);
}

TEST_CASE("payload length: link padding, short UDP length and snapped records", "[capture]") {
  ScratchDir dir("capture");
  const fs::path path = dir / "lengths.pcap";
  const Bytes payload = pattern(1262, 7);
  Bytes padded = ethernet(ipv4({.payload = pattern(2, 1)}));
  padded.resize(60, 0);  // Ethernet minimum frame: padding after the IP datagram
  const Bytes full = ethernet(ipv4({.payload = payload}));
  const Bytes snapped(full.begin(), full.begin() + kFrameHeadersBytes + 100);
  PcapFile(kLinktypeEthernet)
      .add(padded)
      .add(ethernet(ipv4({.payload = payload, .udp_length_delta = -62})))
      .add(snapped, 1'700'000'000, 0, full.size())
      .save(path);
  const ReadResult result = read_capture(path);
  REQUIRE(result.records.size() == 3);

  CHECK(result.records[0].payload == pattern(2, 1));
  CHECK_FALSE(result.records[0].snapped);
  // A UDP length shorter than the IP payload is honoured, as the Linux stack does.
  CHECK(result.records[1].payload == Bytes(payload.begin(), payload.begin() + 1200));
  CHECK(result.records[1].udp_payload_length == 1200);
  CHECK_FALSE(result.records[1].snapped);

  CHECK(result.records[2].snapped);
  CHECK(result.records[2].payload == Bytes(payload.begin(), payload.begin() + 100));
  CHECK(result.records[2].udp_payload_length == 1262);
  CHECK(result.stats.snapped == 1);
}

TEST_CASE("every cut of a frame stays inside the captured bytes", "[capture]") {
  ScratchDir dir("capture");
  const fs::path path = dir / "cuts.pcap";
  const Bytes payload = pattern(64, 11);
  const Bytes frame = ethernet(ipv4({.payload = payload}), kEthertypeIpv4, {0x8100});
  const std::size_t headers = kFrameHeadersBytes + 4;
  PcapFile file(kLinktypeEthernet);
  for (std::size_t size = 0; size <= frame.size(); ++size) {
    file.add(Bytes(frame.begin(), frame.begin() + static_cast<std::ptrdiff_t>(size)), 1'700'000'000,
             0, frame.size());
  }
  file.save(path);
  const ReadResult result = read_capture(path);
  CHECK(result.stats.malformed == headers);  // cut inside the headers
  REQUIRE(result.records.size() == payload.size() + 1);
  for (std::size_t i = 0; i < result.records.size(); ++i) {
    INFO("captured payload bytes " << i);
    CHECK(result.records[i].payload == Bytes(payload.begin(), payload.begin() + i));
    CHECK(result.records[i].snapped == (i < payload.size()));
  }
}

TEST_CASE("random header corruption never yields bytes outside the record", "[capture]") {
  ScratchDir dir("capture");
  const fs::path path = dir / "fuzz.pcap";
  std::mt19937 random(20240611);
  const Bytes frame = ethernet(ipv4({.payload = pattern(200, 0)}), kEthertypeIpv4, {0x8100});
  std::vector<std::size_t> captured;  // captured length of record i (its timestamp is i s)
  PcapFile file(kLinktypeEthernet);
  for (std::uint32_t i = 0; i < 2000; ++i) {
    Bytes mutated = frame;
    const int flips = 1 + static_cast<int>(random() % 4);
    for (int f = 0; f < flips; ++f) {
      mutated[random() % (kFrameHeadersBytes + 4)] = static_cast<std::uint8_t>(random());
    }
    mutated.resize(random() % (frame.size() + 1));
    captured.push_back(mutated.size());
    file.add(mutated, i);
  }
  file.save(path);

  CaptureReader reader(path.string());
  pandarcap::CaptureRecord record;
  std::size_t yielded = 0;
  while (reader.next(record) == CaptureStatus::kRecord) {
    ++yielded;
    const auto index = static_cast<std::size_t>(record.timestamp_ns / 1'000'000'000);
    REQUIRE(index < captured.size());
    // Ethernet + IPv4 + UDP headers take at least 42 of the record's bytes.
    CHECK(record.payload.size() + kFrameHeadersBytes <= captured[index]);
    CHECK(record.payload.size() <= record.udp_payload_length);
  }
  CHECK(reader.stats().records == 2000);
  CHECK(yielded > 0);
  CHECK(reader.stats().malformed > 0);
}

TEST_CASE("classic pcap with nanosecond timestamps keeps the nanoseconds", "[capture]") {
  ScratchDir dir("capture");
  const fs::path path = dir / "ns.pcap";
  PcapFile(kLinktypeEthernet, /*nanosecond=*/true)
      .add(ethernet(ipv4({.payload = pattern(8, 0)})), 1'700'000'000, 123'456'789)
      .save(path);
  const ReadResult result = read_capture(path);
  REQUIRE(result.records.size() == 1);
  CHECK(result.records[0].timestamp_ns == 1'700'000'000'123'456'789);
}

TEST_CASE("pcapng: Ethernet packets, nanosecond timestamps, truncation and corruption",
          "[capture]") {
  ScratchDir dir("capture");
  const Datagram first{.payload = pattern(1266, 1)};
  const Datagram second{.payload = pattern(500, 2), .destination = {kHost.ip, 2369}};
  const std::uint64_t t0 = 1'757'559'840'719'494'123;
  Bytes file = pcapng_header();
  const std::size_t first_block = file.size();
  append(file, pcapng_packet(ethernet(ipv4(first)), t0));
  const std::size_t second_block = file.size();
  append(file, pcapng_packet(ethernet(ipv4(second), kEthertypeIpv4, {0x8100}), t0 + 1));
  const fs::path path = dir / "hand.pcapng";

  SECTION("whole file") {
    write_bytes(path, file);
    const ReadResult result = read_capture(path);
    REQUIRE(result.status == CaptureStatus::kEnd);
    REQUIRE(result.records.size() == 2);
    CHECK(result.records[0].payload == first.payload);
    CHECK(result.records[0].timestamp_ns == static_cast<std::int64_t>(t0));
    CHECK(result.records[1].payload == second.payload);
    CHECK(result.records[1].destination.port == 2369);
    CHECK(result.records[1].timestamp_ns == static_cast<std::int64_t>(t0 + 1));
  }
  SECTION("a timestamp past what int64 nanoseconds hold saturates") {
    // 2^64 - 1 ns overflows seconds * 10^9; 9223372036.999999999 s overflows only on adding the
    // nanoseconds (INT64_MAX is 9223372036.854775807 s).
    for (std::uint64_t late_ns :
         {std::numeric_limits<std::uint64_t>::max(), std::uint64_t{9'223'372'036'999'999'999u}}) {
      Bytes late = pcapng_header();
      append(late, pcapng_packet(ethernet(ipv4(first)), late_ns));
      write_bytes(path, late);
      const ReadResult result = read_capture(path);
      REQUIRE(result.records.size() == 1);
      CHECK(result.records[0].timestamp_ns == std::numeric_limits<std::int64_t>::max());
    }
  }
  SECTION("cut in the middle of a block body") {
    write_bytes(path, file, second_block + 100);
    const ReadResult result = read_capture(path);
    CHECK(result.records.size() == 1);
    CHECK(result.status == CaptureStatus::kTruncated);
    // libpcap: "truncated pcapng dump file; tried to read 580 bytes, only got 92"
    CHECK_THAT(result.error, Catch::StartsWith(path.string() + ": truncated pcapng dump file"));
  }
  SECTION("cut in the middle of a block header") {
    write_bytes(path, file, second_block + 6);
    const ReadResult result = read_capture(path);
    CHECK(result.records.size() == 1);
    CHECK(result.status == CaptureStatus::kTruncated);
    // libpcap: "truncated pcapng dump file; tried to read 8 bytes, only got 6"
    CHECK_THAT(result.error, Catch::Contains("truncated pcapng dump file"));
    CHECK_THAT(result.error, Catch::Contains("only got 6"));
  }
  SECTION("a block length beyond libpcap's maximum is corruption") {
    file[first_block + 4] = 0x00;
    file[first_block + 5] = 0xFF;
    file[first_block + 6] = 0xFF;
    file[first_block + 7] = 0xFF;
    write_bytes(path, file);
    const ReadResult result = read_capture(path);
    CHECK(result.records.empty());
    // libpcap: "pcapng block size 4294967040 > maximum 16777216"
    CHECK(result.status == CaptureStatus::kError);
    CHECK_THAT(result.error, Catch::Contains("pcapng block size"));
  }
  SECTION("a block whose trailing length disagrees is corruption") {
    file[second_block - 4] ^= 0x40;
    write_bytes(path, file);
    const ReadResult result = read_capture(path);
    CHECK(result.records.empty());
    CHECK(result.status == CaptureStatus::kError);
    CHECK_THAT(result.error, Catch::Contains("don't match"));
  }
}

TEST_CASE("real pcapng capture: one 1266-byte Pandar40P packet", "[capture]") {
  const auto path =
      pandarcap::test::real_capture("velocityreport_pandar40p_single_packet_1266B.pcapng");
  if (!path) return;
  const ReadResult result = read_capture(*path);
  REQUIRE(result.status == CaptureStatus::kEnd);
  REQUIRE(result.records.size() == 1);
  const ReadResult::Record& r = result.records[0];
  CHECK(r.payload.size() == 1266);
  CHECK_FALSE(r.snapped);
  CHECK(pandarcap::to_string(r.source) == "192.168.100.202:10000");
  CHECK(pandarcap::to_string(r.destination) == "192.168.100.151:2369");
  CHECK(r.payload[0] == 0xFF);  // first block marker FF EE
  CHECK(r.payload[1] == 0xEE);
}

TEST_CASE("real classic capture: 1439 dual-return packets of 1262 bytes", "[capture]") {
  const auto path = pandarcap::test::real_capture("pandar40p_nebula_dual_600rpm_1262B.pcap");
  if (!path) return;
  const ReadResult result = read_capture(*path);
  REQUIRE(result.status == CaptureStatus::kEnd);
  REQUIRE(result.records.size() == 1439);
  std::int64_t previous_ns = 0;
  for (const ReadResult::Record& r : result.records) {
    REQUIRE(r.payload.size() == 1262);
    REQUIRE(r.source == Endpoint{0xC0A801C9, 2368});
    REQUIRE(r.timestamp_ns >= previous_ns);
    previous_ns = r.timestamp_ns;
  }
  CHECK(read_capture(*path, {.destination_port = 2368}).records.size() == 1439);
  const ReadResult none = read_capture(*path, {.destination_port = 2369});
  CHECK(none.records.empty());
  CHECK(none.stats.port_filtered == 1439);
}
