#include "daemon/pcap/pcap_writer.hpp"

#include <algorithm>
#include <array>
#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <system_error>
#include <utility>

#include "core/units.hpp"
#include "daemon/io/errors.hpp"

namespace pandarcap {
namespace {

constexpr std::uint32_t kPcapMagicMicroseconds = 0xA1B2C3D4;  // native order: readers detect it
constexpr std::uint16_t kPcapVersionMajor = 2;
constexpr std::uint16_t kPcapVersionMinor = 4;
constexpr std::uint32_t kLinktypeEthernet = 1;

constexpr std::size_t kEthernetBytes = 14;
constexpr std::size_t kIpv4Bytes = 20;
constexpr std::size_t kIpv6Bytes = 40;
constexpr std::size_t kUdpBytes = 8;
constexpr std::size_t kHeadersBytes = kEthernetBytes + kIpv4Bytes + kUdpBytes;      // 42
constexpr std::size_t kHeadersBytesIpv6 = kEthernetBytes + kIpv6Bytes + kUdpBytes;  // 62
constexpr std::size_t kMaxUdpPayloadBytes = 65535 - kIpv4Bytes - kUdpBytes;         // 65507

// Appends integers to a fixed buffer, in native order (pcap headers) or big-endian (wire headers).
template <std::size_t N>
class ByteWriter {
 public:
  void native_u16(std::uint16_t v) { bytes(&v, sizeof v); }
  void native_u32(std::uint32_t v) { bytes(&v, sizeof v); }
  void be_u16(std::uint16_t v) {
    buffer_[size_++] = static_cast<std::uint8_t>(v >> 8);
    buffer_[size_++] = static_cast<std::uint8_t>(v);
  }
  void be_u32(std::uint32_t v) {
    be_u16(static_cast<std::uint16_t>(v >> 16));
    be_u16(static_cast<std::uint16_t>(v));
  }
  void bytes(const void* data, std::size_t n) {
    std::memcpy(buffer_.data() + size_, data, n);
    size_ += n;
  }
  std::uint8_t* at(std::size_t offset) { return buffer_.data() + offset; }
  std::span<const std::uint8_t> written() const { return {buffer_.data(), size_}; }

 private:
  std::array<std::uint8_t, N> buffer_{};
  std::size_t size_ = 0;
};

// The one's-complement sum of big-endian 16-bit words (RFC 1071), an odd last byte padded with
// zero, added to `sum`; folded by internet_checksum().
std::uint64_t add_words(std::uint64_t sum, std::span<const std::uint8_t> bytes) noexcept {
  std::size_t i = 0;
  for (; i + 1 < bytes.size(); i += 2) {
    sum += static_cast<std::uint32_t>((bytes[i] << 8) | bytes[i + 1]);
  }
  if (i < bytes.size()) sum += static_cast<std::uint32_t>(bytes[i] << 8);
  return sum;
}

std::uint16_t internet_checksum(std::uint64_t sum) noexcept {
  while ((sum >> 16) != 0) {
    sum = (sum & 0xFFFF) + (sum >> 16);  // end-around carry
  }
  return static_cast<std::uint16_t>(~sum);
}

// RFC 791 header checksum: one's complement of the one's-complement sum of the 16-bit words.
std::uint16_t ipv4_checksum(std::span<const std::uint8_t> header) {
  return internet_checksum(add_words(0, header));
}

}  // namespace

std::array<std::uint8_t, kPcapGlobalHeaderBytes> pcap_global_header() noexcept {
  ByteWriter<kPcapGlobalHeaderBytes> header;
  header.native_u32(kPcapMagicMicroseconds);
  header.native_u16(kPcapVersionMajor);
  header.native_u16(kPcapVersionMinor);
  header.native_u32(0);  // thiszone: timestamps are UTC
  header.native_u32(0);  // sigfigs
  header.native_u32(kPcapSnaplen);
  header.native_u32(kLinktypeEthernet);
  std::array<std::uint8_t, kPcapGlobalHeaderBytes> bytes{};
  std::copy(header.written().begin(), header.written().end(), bytes.begin());
  return bytes;
}

PcapWriter::PcapWriter(const std::string& path, std::span<char> buffer,
                       ZstdStreamCompressor* compressor) {
  if (const io::IoError error = open(path, buffer, compressor)) io::throw_io_error(error);
}

io::IoError PcapWriter::open(std::string_view path, std::span<char> buffer,
                             ZstdStreamCompressor* compressor) {
  path_.assign(path);
  compressor_ = compressor;
  buffer_ = buffer;
  buffered_ = 0;
  ip_id_ = 0;
  records_ = bytes_ = 0;
  flushed_records_ = flushed_bytes_ = flushed_stream_bytes_ = 0;
  flushed_hash_.reset();
  if (compressor_ != nullptr) compressor_->begin();
  io::IoError error = file_.try_open(path_, OutputFile::Mode::kCreate);
  if (!error) error = append(pcap_global_header());
  bytes_ = kPcapGlobalHeaderBytes;
  // At once, so that the file is a valid (empty) capture from here on even if the process dies
  // before its first flush. One write per file.
  if (!error) error = try_flush();
  if (error) {
    buffered_ = 0;
    records_ = bytes_ = 0;
    (void)file_.try_close();  // the failure is the one to report
  }
  return error;
}

PcapWriter::~PcapWriter() {
  // A destructor cannot report a failure; callers that need to know call close() first.
  if (!file_.is_open()) return;
  try {
    (void)flush_buffer();
  } catch (const std::exception&) {
    // Reported by nobody: see above.
  }
}

io::IoError PcapWriter::append(std::span<const std::uint8_t> bytes) {
  if (!file_.is_open()) return not_open();
  // An empty payload (a zero-length datagram) may come with a null data(), which memcpy must not
  // get even for 0 bytes; there is nothing to append anyway.
  if (bytes.empty()) return {};
  if (buffered_ + bytes.size() > buffer_.size()) {
    if (const io::IoError error = flush_buffer()) return error;
    if (bytes.size() > buffer_.size()) return emit(bytes, ZstdStreamCompressor::Step::kContinue);
  }
  std::memcpy(buffer_.data() + buffered_, bytes.data(), bytes.size());
  buffered_ += bytes.size();
  return {};
}

io::IoError PcapWriter::flush_buffer(ZstdStreamCompressor::Step step) {
  const std::size_t n = std::exchange(buffered_, 0);
  return emit(std::span(reinterpret_cast<const std::uint8_t*>(buffer_.data()), n), step);
}

io::IoError PcapWriter::emit(std::span<const std::uint8_t> bytes, ZstdStreamCompressor::Step step) {
  if (compressor_ == nullptr) return file_.try_write(bytes);
  const std::span<const std::uint8_t> out = compressor_->compress(bytes, step);
  return out.empty() ? io::IoError{} : file_.try_write(out);
}

bool PcapWriter::recordable(std::size_t payload_bytes, std::int64_t timestamp_ns) noexcept {
  return payload_bytes <= kMaxUdpPayloadBytes && timestamp_ns >= 0 &&
         timestamp_ns / kNsPerSecond <= std::int64_t{UINT32_MAX};
}

void PcapWriter::write(std::span<const std::uint8_t> udp_payload,
                       std::size_t original_payload_bytes, std::int64_t timestamp_ns,
                       Endpoint source, Endpoint destination) {
  if (udp_payload.size() > kMaxUdpPayloadBytes) {
    throw std::invalid_argument("UDP payload of " + std::to_string(udp_payload.size()) +
                                " bytes exceeds the maximum of " +
                                std::to_string(kMaxUdpPayloadBytes));
  }
  const std::int64_t seconds = timestamp_ns / kNsPerSecond;
  if (timestamp_ns < 0 || seconds > std::int64_t{UINT32_MAX}) {
    throw std::invalid_argument("timestamp " + std::to_string(timestamp_ns) +
                                " ns is outside the pcap range (1970 to 2106)");
  }
  if (const io::IoError error =
          try_write(udp_payload, original_payload_bytes, timestamp_ns, source, destination)) {
    io::throw_io_error(error);
  }
}

io::IoError PcapWriter::try_write(std::span<const std::uint8_t> udp_payload,
                                  std::size_t original_payload_bytes, std::int64_t timestamp_ns,
                                  Endpoint source, Endpoint destination) {
  // A datagram longer than IPv4 can carry was not received as one: the headers say the most
  // they can, and the record still holds only what was kept.
  const std::size_t original =
      std::clamp(original_payload_bytes, udp_payload.size(), kMaxUdpPayloadBytes);
  const std::int64_t seconds = timestamp_ns / kNsPerSecond;
  const std::int64_t microseconds = timestamp_ns % kNsPerSecond / kNsPerMicrosecond;
  const bool ipv6 = source.ipv6 || destination.ipv6;
  const std::size_t headers = ipv6 ? kHeadersBytesIpv6 : kHeadersBytes;
  const auto udp_length = static_cast<std::uint16_t>(kUdpBytes + original);
  const auto captured_bytes = static_cast<std::uint32_t>(headers + udp_payload.size());
  const auto original_bytes = static_cast<std::uint32_t>(headers + original);

  ByteWriter<kPcapRecordHeaderBytes + kHeadersBytesIpv6> out;
  out.native_u32(static_cast<std::uint32_t>(seconds));
  out.native_u32(static_cast<std::uint32_t>(microseconds));
  out.native_u32(captured_bytes);  // bytes in this record
  out.native_u32(original_bytes);  // bytes the datagram had on the wire

  constexpr std::array<std::uint8_t, 6> kDestinationMac{0x02, 0, 0, 0, 0, 0x02};
  constexpr std::array<std::uint8_t, 6> kSourceMac{0x02, 0, 0, 0, 0, 0x01};
  out.bytes(kDestinationMac.data(), kDestinationMac.size());
  out.bytes(kSourceMac.data(), kSourceMac.size());
  const std::size_t ip_offset = kPcapRecordHeaderBytes + kEthernetBytes;
  std::uint16_t udp_checksum = 0;  // IPv4: "not computed"
  if (ipv6) {
    out.be_u16(0x86DD);      // ethertype IPv6
    out.be_u32(0x60000000);  // version 6, traffic class 0, flow label 0
    out.be_u16(udp_length);  // payload length: the UDP datagram, no extension headers
    out.be_u16(0x1140);      // next header UDP (17), hop limit 64
    out.bytes(source.ip6.data(), source.ip6.size());
    out.bytes(destination.ip6.data(), destination.ip6.size());
    if (original == udp_payload.size()) {
      // RFC 8200 8.1: over the pseudo-header (addresses, UDP length, next header), the UDP
      // header with a zero checksum, and the payload; a sum of 0 is sent as 0xFFFF.
      std::uint64_t sum = add_words(0, {out.at(ip_offset + 8), 32});
      sum += udp_length + 17u;
      sum += source.port + destination.port + udp_length;
      sum = add_words(sum, udp_payload);
      udp_checksum = internet_checksum(sum);
      if (udp_checksum == 0) udp_checksum = 0xFFFF;
    }
  } else {
    out.be_u16(0x0800);  // ethertype IPv4
    out.be_u16(0x4500);  // version 4, IHL 5 (no options), DSCP/ECN 0
    out.be_u16(static_cast<std::uint16_t>(kIpv4Bytes + udp_length));
    out.be_u16(ip_id_++);
    out.be_u16(0x4000);  // flags: DF; fragment offset 0
    out.be_u16(0x4011);  // TTL 64, protocol UDP (17)
    out.be_u16(0);       // header checksum, filled in below
    out.be_u32(source.ip);
    out.be_u32(destination.ip);
    const std::uint16_t checksum = ipv4_checksum({out.at(ip_offset), kIpv4Bytes});
    out.at(ip_offset + 10)[0] = static_cast<std::uint8_t>(checksum >> 8);
    out.at(ip_offset + 10)[1] = static_cast<std::uint8_t>(checksum);
  }

  out.be_u16(source.port);
  out.be_u16(destination.port);
  out.be_u16(udp_length);
  out.be_u16(udp_checksum);

  io::IoError error = append(out.written());
  if (!error) error = append(udp_payload);
  if (error) return error;
  bytes_ += out.written().size() + udp_payload.size();
  ++records_;
  return {};
}

io::IoError PcapWriter::try_write_frame(std::span<const std::uint8_t> wire_header,
                                        std::span<const std::uint8_t> rest, std::size_t wire_length,
                                        std::int64_t timestamp_ns) {
  const std::size_t captured = wire_header.size() + rest.size();
  ByteWriter<kPcapRecordHeaderBytes> out;
  out.native_u32(static_cast<std::uint32_t>(timestamp_ns / kNsPerSecond));
  out.native_u32(static_cast<std::uint32_t>(timestamp_ns % kNsPerSecond / kNsPerMicrosecond));
  out.native_u32(static_cast<std::uint32_t>(captured));
  out.native_u32(static_cast<std::uint32_t>(std::max(wire_length, captured)));
  io::IoError error = append(out.written());
  if (!error) error = append(wire_header);
  if (!error) error = append(rest);
  if (error) return error;
  bytes_ += out.written().size() + captured;
  ++records_;
  return {};
}

io::IoError PcapWriter::try_flush() {
  if (!file_.is_open()) return not_open();
  if (const io::IoError error = flush_buffer(ZstdStreamCompressor::Step::kFlush)) return error;
  flushed_records_ = records_;
  flushed_bytes_ = bytes();
  flushed_stream_bytes_ = bytes_;
  if (compressor_ != nullptr) flushed_hash_ = compressor_->content_hash();
  return {};
}

io::IoError PcapWriter::try_close() {
  if (!file_.is_open()) return {};
  // A failing flush leaves the file open, for abandon() to cut back to whole records.
  if (compressor_ != nullptr) {
    if (const io::IoError error = flush_buffer(ZstdStreamCompressor::Step::kEnd)) return error;
    flushed_records_ = records_;
    flushed_bytes_ = bytes();
    flushed_stream_bytes_ = bytes_;
  } else if (const io::IoError error = try_flush()) {
    return error;
  }
  return file_.try_close();
}

PcapWriter::Dropped PcapWriter::abandon() noexcept {
  const Dropped dropped{records_ - flushed_records_, bytes_ - flushed_stream_bytes_};
  buffered_ = 0;  // never written
  if (file_.is_open()) {
    // What reached the file past the last good flush is a prefix of a record at best. If the
    // cut fails too, the reader stops at the cut record (kTruncated).
    file_.truncate(flushed_bytes_);
    // A flush ended a block: an empty last block ends the frame there, and the checksum of the
    // stream up to it closes the frame as zstd would have. (If that fails, the frame stays
    // unfinished: readers get every flushed record, then report the cut.)
    if (compressor_ != nullptr && flushed_bytes_ > 0 && !file_.try_write(kZstdEmptyLastBlock))
      (void)file_.try_write(zstd_content_checksum(flushed_hash_));
    // Nothing more can be done about a failed close: the count above says what was lost.
    (void)file_.try_close();
  }
  records_ = flushed_records_;
  bytes_ = flushed_stream_bytes_;
  return dropped;
}

}  // namespace pandarcap
