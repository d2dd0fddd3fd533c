#include "daemon/pcap/capture_reader.hpp"

#include <fcntl.h>
#include <pcap/pcap.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <limits>

#include "core/mcap/mcap_records.hpp"
#include "core/mcap/ros2_messages.hpp"
#include "core/units.hpp"
#include "daemon/pcap/mcap_packet_reader.hpp"
#include "daemon/pcap/zstd_magic.hpp"
#include "daemon/pcap/zstd_read_stream.hpp"

namespace pandarcap {
namespace {

constexpr std::uint16_t kEthertypeIpv4 = 0x0800;
constexpr std::uint16_t kEthertypeIpv6 = 0x86DD;
constexpr std::uint16_t kEthertypeVlan = 0x8100;        // 802.1Q C-tag
constexpr std::uint16_t kEthertypeQinQ = 0x88A8;        // 802.1ad S-tag
constexpr std::uint16_t kEthertypeQinQLegacy = 0x9100;  // pre-802.1ad S-tag, still seen
constexpr std::size_t kVlanTagBytes = 4;                // TCI (2) + inner ethertype (2)

constexpr std::size_t kIpv4MinHeaderBytes = 20;
constexpr std::uint8_t kIpProtocolUdp = 17;
constexpr std::uint16_t kIpMoreFragments = 0x2000;
constexpr std::uint16_t kIpFragmentOffsetMask = 0x1FFF;
constexpr std::size_t kUdpHeaderBytes = 8;

constexpr std::size_t kIpv6HeaderBytes = 40;
// IPv6 next-header values (IANA "Assigned Internet Protocol Numbers").
constexpr std::uint8_t kIpv6HopByHop = 0;
constexpr std::uint8_t kIpv6Routing = 43;
constexpr std::uint8_t kIpv6Fragment = 44;
constexpr std::uint8_t kIpv6Authentication = 51;
constexpr std::uint8_t kIpv6DestinationOptions = 60;
// More extension headers than any real packet has (RFC 8200 recommends at most one of each):
// a crafted chain is refused after this many rather than walked to its end.
constexpr int kIpv6MaxExtensionHeaders = 8;

std::uint16_t load_u16_be(const std::uint8_t* p) noexcept {
  return static_cast<std::uint16_t>((p[0] << 8) | p[1]);
}

std::uint32_t load_u32_be(const std::uint8_t* p) noexcept {
  return (static_cast<std::uint32_t>(p[0]) << 24) | (static_cast<std::uint32_t>(p[1]) << 16) |
         (static_cast<std::uint32_t>(p[2]) << 8) | static_cast<std::uint32_t>(p[3]);
}

// Where a link layer puts the network-layer protocol and the network-layer packet.
struct LinkLayer {
  std::size_t header_bytes = 0;
  std::size_t protocol_offset = 0;  // big-endian ethertype at this offset
  bool raw_ip = false;              // no link header: the record starts with the IP header
};

// DLT_RAW is 12 on Linux and 14 on BSD/OS. libpcap maps a file's LINKTYPE_RAW (101) and 12 to the
// platform's DLT_RAW, but passes 14 (written by old BSD/OS tools) through unnamed.
constexpr int kDltRawBsdOs = 14;

// DLT values as pcap_datalink() reports them (libpcap maps a file's LINKTYPE_ to its DLT_).
std::optional<LinkLayer> link_layer(int dlt) noexcept {
  if (dlt == DLT_RAW || dlt == kDltRawBsdOs || dlt == DLT_IPV4 || dlt == DLT_IPV6) {
    return LinkLayer{0, 0, true};
  }
  switch (dlt) {
    case DLT_EN10MB:
      return LinkLayer{14, 12, false};  // dst MAC, src MAC, ethertype
    case DLT_LINUX_SLL:
      return LinkLayer{16, 14, false};  // packet type, ARPHRD, address length, address, protocol
    case DLT_LINUX_SLL2:
      return LinkLayer{20, 0, false};  // protocol first, then interface index, ARPHRD, ...
    default:
      return std::nullopt;
  }
}

enum class FrameKind { kUdp, kNonIp, kNonUdp, kFragment, kMalformed };

// The UDP header and payload of a datagram: `datagram` is what the IP header says its payload is
// (`datagram_bytes` long), of which `captured` bytes are in the record.
FrameKind parse_udp(const std::uint8_t* udp, std::size_t datagram_bytes, std::size_t captured,
                    CaptureRecord& out) noexcept {
  if (datagram_bytes < kUdpHeaderBytes || captured < kUdpHeaderBytes) return FrameKind::kMalformed;
  const std::size_t udp_length = load_u16_be(udp + 4);
  // As the Linux stack does: a UDP length shorter than the IP payload is honoured (trailing bytes
  // ignored), a longer one is malformed.
  if (udp_length < kUdpHeaderBytes || udp_length > datagram_bytes) return FrameKind::kMalformed;
  const std::size_t declared = udp_length - kUdpHeaderBytes;
  // More bytes than declared: link-layer padding (Ethernet's 60-byte minimum) or a trailer.
  // Fewer: the record was cut by the capture's snap length.
  const std::size_t payload_captured = captured - kUdpHeaderBytes;
  out.payload =
      std::span<const std::uint8_t>(udp + kUdpHeaderBytes, std::min(declared, payload_captured));
  out.udp_payload_length = static_cast<std::uint32_t>(declared);
  out.snapped = payload_captured < declared;
  out.source.port = load_u16_be(udp);
  out.destination.port = load_u16_be(udp + 2);
  return FrameKind::kUdp;
}

// IPv6 (RFC 8200): the fixed header, then a chain of extension headers to the UDP header. The
// payload length counts everything after the fixed header; 0 (a jumbogram's) is refused.
FrameKind parse_ipv6(std::span<const std::uint8_t> ip, CaptureRecord& out) noexcept {
  if (ip.size() < kIpv6HeaderBytes || (ip[0] >> 4) != 6) return FrameKind::kMalformed;
  const std::size_t payload_length = load_u16_be(ip.data() + 4);
  if (payload_length == 0) return FrameKind::kMalformed;
  std::uint8_t next = ip[6];
  std::size_t offset = kIpv6HeaderBytes;
  const std::size_t end = kIpv6HeaderBytes + payload_length;  // of the datagram, not the record
  for (int headers = 0; next != kIpProtocolUdp; ++headers) {
    if (next == kIpv6Fragment) return FrameKind::kFragment;
    if (next != kIpv6HopByHop && next != kIpv6Routing && next != kIpv6DestinationOptions &&
        next != kIpv6Authentication) {
      return FrameKind::kNonUdp;  // TCP, ICMPv6, no next header, ESP, ...
    }
    if (headers == kIpv6MaxExtensionHeaders) return FrameKind::kMalformed;
    if (ip.size() < offset + 2 || end < offset + 2) return FrameKind::kMalformed;
    // Lengths: in 8-byte units not counting the first 8; AH's in 4-byte units not counting 8.
    const std::size_t length = next == kIpv6Authentication ? (std::size_t{ip[offset + 1]} + 2) * 4
                                                           : (std::size_t{ip[offset + 1]} + 1) * 8;
    next = ip[offset];
    offset += length;
    if (offset > end || offset > ip.size()) return FrameKind::kMalformed;
  }
  const FrameKind kind = parse_udp(ip.data() + offset, end - offset, ip.size() - offset, out);
  if (kind != FrameKind::kUdp) return kind;
  out.source.ipv6 = out.destination.ipv6 = true;
  std::copy_n(ip.data() + 8, 16, out.source.ip6.begin());
  std::copy_n(ip.data() + 24, 16, out.destination.ip6.begin());
  return FrameKind::kUdp;
}

// Parses one record's captured bytes down to the UDP payload. Reads only inside `frame`; every
// length in the headers is untrusted and checked against what was captured before it is used.
FrameKind parse_frame(const LinkLayer& link, std::span<const std::uint8_t> frame,
                      CaptureRecord& out) noexcept {
  std::size_t ip_offset = link.header_bytes;
  if (frame.size() < ip_offset) return FrameKind::kMalformed;
  bool ipv6 = false;
  if (link.raw_ip) {
    // DLT_RAW carries IPv6 as well; the version nibble tells them apart.
    if (frame.empty()) return FrameKind::kMalformed;
    ipv6 = (frame[0] >> 4) == 6;
  } else {
    std::uint16_t protocol = load_u16_be(frame.data() + link.protocol_offset);
    // Any number of VLAN tags, each 4 bytes: TCI, then the ethertype of what follows.
    while (protocol == kEthertypeVlan || protocol == kEthertypeQinQ ||
           protocol == kEthertypeQinQLegacy) {
      if (frame.size() - ip_offset < kVlanTagBytes) return FrameKind::kMalformed;
      protocol = load_u16_be(frame.data() + ip_offset + 2);
      ip_offset += kVlanTagBytes;
    }
    if (protocol != kEthertypeIpv4 && protocol != kEthertypeIpv6) return FrameKind::kNonIp;
    ipv6 = protocol == kEthertypeIpv6;
  }

  const std::span<const std::uint8_t> ip = frame.subspan(ip_offset);
  if (ipv6) return parse_ipv6(ip, out);
  if (ip.size() < kIpv4MinHeaderBytes) return FrameKind::kMalformed;
  if ((ip[0] >> 4) != 4) return FrameKind::kMalformed;
  const std::size_t ip_header_bytes = std::size_t{ip[0] & 0x0Fu} * 4;
  const std::size_t total_length = load_u16_be(ip.data() + 2);
  if (ip_header_bytes < kIpv4MinHeaderBytes || ip_header_bytes > ip.size() ||
      total_length < ip_header_bytes) {
    return FrameKind::kMalformed;
  }
  const std::uint16_t fragment = load_u16_be(ip.data() + 6);
  if ((fragment & kIpMoreFragments) != 0 || (fragment & kIpFragmentOffsetMask) != 0) {
    return FrameKind::kFragment;
  }
  if (ip[9] != kIpProtocolUdp) return FrameKind::kNonUdp;
  // The UDP header must lie inside the datagram and inside the captured bytes.
  const FrameKind kind = parse_udp(ip.data() + ip_header_bytes, total_length - ip_header_bytes,
                                   ip.size() - ip_header_bytes, out);
  if (kind != FrameKind::kUdp) return kind;
  out.source.ip = load_u32_be(ip.data() + 12);
  out.destination.ip = load_u32_be(ip.data() + 16);
  return FrameKind::kUdp;
}

// Record time in ns. pcapng timestamps are 64-bit, so a corrupt one can exceed what int64 ns can
// hold (year 2262): saturate rather than overflow.
std::int64_t timestamp_ns(const timeval& ts, bool nanosecond) noexcept {
  std::int64_t seconds = ts.tv_sec;
  // Classic pcap stores seconds as an unsigned 32-bit number (to 2106), which libpcap 1.10 hands
  // over sign-extended: 2038-2106 arrive as -2^31..-1. (A pcapng time there would be a 64-bit
  // count past 2^63 s: corrupt either way.)
  if (seconds < 0 && seconds >= -(std::int64_t{1} << 31)) seconds += std::int64_t{1} << 32;
  const std::int64_t fraction = nanosecond ? ts.tv_usec : std::int64_t{ts.tv_usec} * 1000;
  std::int64_t ns = 0;
  if (__builtin_mul_overflow(seconds, kNsPerSecond, &ns) ||
      __builtin_add_overflow(ns, fraction, &ns)) {
    return seconds < 0 ? std::numeric_limits<std::int64_t>::min()
                       : std::numeric_limits<std::int64_t>::max();
  }
  return ns;
}

}  // namespace

CaptureReader::CaptureReader(const std::string& path, Options options)
    : path_(path), options_(options) {
  // Opened here rather than by libpcap: O_NONBLOCK so that a FIFO with no writer cannot hold
  // the start (the daemon's signals are blocked by then), and anything but a regular file is
  // refused before it is read.
  const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
  if (fd < 0) {
    throw CaptureError("cannot open capture '" + path + "': " + std::strerror(errno));
  }
  struct stat info {};
  if (::fstat(fd, &info) != 0 || !S_ISREG(info.st_mode)) {
    ::close(fd);
    throw CaptureError("cannot open capture '" + path +
                       "': not a regular file (a FIFO, socket, device or directory)");
  }
  ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL) & ~O_NONBLOCK);
  size_bytes_ = static_cast<std::uint64_t>(info.st_size);
  fd_ = fd;
  // The kind of file, by its first bytes (pread: the file position stays at 0 for libpcap).
  std::uint8_t magic[mcap::kMagic.size()] = {};
  const ssize_t got = ::pread(fd, magic, sizeof magic, 0);
  const auto have = static_cast<std::size_t>(std::max<ssize_t>(got, 0));
  if (have == sizeof magic && std::equal(mcap::kMagic.begin(), mcap::kMagic.end(), magic)) {
    open_mcap(fd);
    return;
  }
  FILE* file = nullptr;
  if (have >= kZstdMagic.size() && std::equal(kZstdMagic.begin(), kZstdMagic.end(), magic)) {
    format_ = CaptureFormat::kPcapZstd;
    try {
      file = ZstdReadStream::open(fd, zstd_);  // owns fd from here
    } catch (const std::exception& e) {
      throw CaptureError("cannot open capture '" + path + "': " + e.what());
    }
  } else {
    file = ::fdopen(fd, "rb");
    if (file == nullptr) {
      ::close(fd);
      throw CaptureError("cannot open capture '" + path + "': " + std::strerror(errno));
    }
  }
  char errbuf[PCAP_ERRBUF_SIZE] = {};
  // Nanosecond precision: libpcap scales microsecond files up, and keeps pcapng's finer units.
  // Once open, libpcap owns the FILE (pcap_close closes it); a failed open leaves it ours.
  handle_ = pcap_fopen_offline_with_tstamp_precision(file, PCAP_TSTAMP_PRECISION_NANO, errbuf);
  if (handle_ == nullptr) {
    // A zstd stream that does not decompress says why (libpcap only saw a failed read), and so
    // does one cut before its first whole capture header.
    std::string why = errbuf;
    if (zstd_ != nullptr && !zstd_->error().empty()) {
      why = zstd_->error();
    } else if (zstd_ != nullptr && zstd_->unfinished_frame()) {
      why =
          "the zstd stream ends inside a frame before a whole capture header (cut off while "
          "recording)";
    } else if (zstd_ != nullptr) {
      why = "(decompressed) " + why;
    }
    std::fclose(file);
    throw CaptureError("cannot open capture '" + path + "': " + why);
  }
  // Always nano with libpcap >= 1.5 (the open fails otherwise); checked so that a microsecond
  // handle could never be read as nanoseconds.
  nanosecond_ = pcap_get_tstamp_precision(handle_) == PCAP_TSTAMP_PRECISION_NANO;
  link_type_ = pcap_datalink(handle_);
  if (!link_layer(link_type_)) {
    pcap_close(handle_);
    const char* name = pcap_datalink_val_to_name(link_type_);
    throw CaptureError("capture '" + path + "' has unsupported link type " +
                       (name != nullptr ? name : "unknown") + " (" + std::to_string(link_type_) +
                       "); supported: EN10MB, LINUX_SLL, LINUX_SLL2, RAW, IPV4, IPV6");
  }
}

// An MCAP file: its first packet is read now, so that a file without any fails at once (the
// daemon's "capture unreadable" exit, inspect's), not after a start that replays nothing.
void CaptureReader::open_mcap(int fd) {
  format_ = CaptureFormat::kMcap;
  mcap_ = std::make_unique<McapPacketReader>(fd, path_);  // owns fd from here
  CaptureRecord record;
  const CaptureStatus status = mcap_->next(record, stats_);
  if (status == CaptureStatus::kRecord) {
    first_ = record;
    return;
  }
  if (stats_.records == 0) {
    std::string message = path_ + " holds no " + std::string(mcap::kPandarPacketName) +
                          " messages: record with output.mcap_packets = true";
    if (status != CaptureStatus::kEnd)
      message += " (and reading it failed: " + mcap_->error() + ")";
    throw CaptureError(message);
  }
  final_status_ = status;  // packets, none of them readable: the summary says so
  error_ = mcap_->error();
}

std::uint64_t CaptureReader::bytes_read() const noexcept {
  if (mcap_) return mcap_->offset();
  const off_t at = ::lseek(fd_, 0, SEEK_CUR);
  return at < 0 ? 0 : static_cast<std::uint64_t>(at);
}

std::optional<SensorModelId> CaptureReader::named_model() const noexcept {
  if (!mcap_) return std::nullopt;
  return mcap_->named_model();
}

const std::string& CaptureReader::first_damage() const noexcept {
  return mcap_ ? mcap_->first_damage() : first_damage_;
}

void CaptureReader::malformed(const char* what) {
  ++stats_.malformed;
  if (first_damage_.empty())
    first_damage_ = path_ + ": record " + std::to_string(stats_.records) + " " + what;
}

CaptureReader::~CaptureReader() {
  if (handle_ != nullptr) pcap_close(handle_);
}

CaptureStatus CaptureReader::next(CaptureRecord& out) {
  if (final_status_) return *final_status_;
  if (mcap_) {
    if (first_) {
      out = *first_;
      first_.reset();
      return CaptureStatus::kRecord;
    }
    const CaptureStatus status = mcap_->next(out, stats_);
    if (status != CaptureStatus::kRecord) {
      final_status_ = status;
      error_ = mcap_->error();
    }
    return status;
  }
  const LinkLayer link = *link_layer(link_type_);
  for (;;) {
    pcap_pkthdr* header = nullptr;
    const u_char* data = nullptr;
    const int rc = pcap_next_ex(handle_, &header, &data);
    if (rc != 1) return finish(rc);
    ++stats_.records;
    // A record header no capture tool writes: more bytes captured than the packet had, or a
    // fraction of a second that is a whole second or more (libpcap scales microseconds to ns).
    // Damage in the header, which libpcap does not check; its bytes are not trusted.
    if (header->caplen > header->len || header->ts.tv_usec < 0 ||
        header->ts.tv_usec >= (nanosecond_ ? 1'000'000'000 : 1'000'000)) {
      malformed(
          "has a record header no capture tool writes (caplen above len, or a sub-second "
          "field of a second or more)");
      continue;
    }
    CaptureRecord record;
    FrameKind kind = parse_frame(link, {data, header->caplen}, record);
    // A datagram held whole in a record whose len says the packet was longer (by more than an
    // Ethernet FCS the capture left out): the record header is damaged.
    if (kind == FrameKind::kUdp && !record.snapped && header->len > header->caplen + 4) {
      malformed("has a record header whose len is longer than the whole datagram it holds");
      continue;
    }
    switch (kind) {
      case FrameKind::kNonIp:
        ++stats_.non_ip;
        continue;
      case FrameKind::kNonUdp:
        ++stats_.non_udp;
        continue;
      case FrameKind::kFragment:
        ++stats_.ip_fragments;
        continue;
      case FrameKind::kMalformed:
        malformed("has headers that do not hold together (damaged, or malformed when captured)");
        continue;
      case FrameKind::kUdp:
        break;
    }
    if (options_.destination_port && record.destination.port != *options_.destination_port) {
      ++stats_.port_filtered;
      continue;
    }
    record.timestamp_ns = timestamp_ns(header->ts, nanosecond_);
    ++stats_.udp_datagrams;
    if (record.source.ipv6) ++stats_.ipv6_datagrams;
    if (record.snapped) ++stats_.snapped;
    out = record;
    return CaptureStatus::kRecord;
  }
}

// libpcap reports every read failure as PCAP_ERROR, so the kind is told by its message. Rule:
// "truncated" in the message -> kTruncated, anything else -> kError. What libpcap 1.10.3 says:
//   pcap cut in a record header   "truncated dump file; tried to read 16 header bytes, only got 5"
//   pcap cut in a record's data   "truncated dump file; tried to read 1304 captured bytes, only
//                                  got 1204"
//   pcapng cut in a block header  "truncated pcapng dump file; tried to read 8 bytes, only got 6"
//   pcapng cut in a block body    "truncated pcapng dump file; tried to read 72 bytes, only got 62"
//   corrupt record / block        "invalid packet capture length 4294967040, bigger than snaplen
//                                  of 262144", "pcapng block size 4294967040 > maximum 16777216",
//                                  "block total length in header and trailer don't match"
// A corrupt caplen that is plausible (below the file's snaplen) but runs past the end of the file
// is indistinguishable from a cut-off recording and reads as kTruncated.
// A zstd capture: a stream that failed to decompress is kError with zstd's reason; one that ends
// inside its frame (a killed run's .part, cut at a record boundary) kTruncated even when libpcap
// saw a clean end.
CaptureStatus CaptureReader::finish(int pcap_status) {
  if (zstd_ != nullptr && !zstd_->error().empty()) {
    error_ = path_ + ": " + zstd_->error();
    final_status_ = CaptureStatus::kError;
  } else if (zstd_ != nullptr && zstd_->unfinished_frame() &&
             (pcap_status == PCAP_ERROR_BREAK ||
              std::string_view(pcap_geterr(handle_)).find("truncated") != std::string_view::npos)) {
    // libpcap may see the cut first, inside a record: the stream's end inside its frame says
    // which it is.
    error_ = path_ +
             ": the zstd stream ends inside a frame: the file is cut short (cut off while "
             "recording, or an unfinished copy)";
    final_status_ = CaptureStatus::kTruncated;
  } else if (pcap_status == PCAP_ERROR_BREAK) {
    final_status_ = CaptureStatus::kEnd;
  } else {
    const std::string message = pcap_status == PCAP_ERROR
                                    ? pcap_geterr(handle_)
                                    : "pcap_next_ex returned " + std::to_string(pcap_status);
    error_ = path_ + ": " + message;
    final_status_ = message.find("truncated") != std::string::npos ? CaptureStatus::kTruncated
                                                                   : CaptureStatus::kError;
  }
  return *final_status_;
}

}  // namespace pandarcap
