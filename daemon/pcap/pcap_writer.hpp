// Writes UDP payloads as a classic pcap file (LINKTYPE_ETHERNET, microsecond timestamps) with
// synthesised Ethernet / IPv4 / UDP headers, so that Wireshark, tcpdump, tcpreplay and LidarView
// read the recording like one taken on the wire.
//
// Synthesised headers: Ethernet 02:00:00:00:00:02 <- 02:00:00:00:00:01; for an IPv4 datagram
// IPv4 with a correct header checksum, TTL 64, DF set, incrementing identification and UDP
// checksum 0 ("not computed", legal for IPv4); for an IPv6 one (a replayed IPv6 capture) IPv6
// with hop limit 64 and the UDP checksum IPv6 requires, computed (0 when only part of the
// datagram is held: its sum cannot be known).
//
// Compressed (given a ZstdStreamCompressor): the same pcap stream as one zstd frame
// (daemon/pcap/zstd_write_stream.hpp), each flush() ending a block, close() ending the frame; the
// file then opens as it is in tshark, Wireshark and pandarcapd --replay. bytes() and
// flushed_bytes() are the file's (compressed) bytes.
//
// Errors: every failing write throws std::system_error carrying errno and the file name (the
// bytes go through daemon/io's OutputFile, so the tests' system-call seam reaches them); the
// try_ forms return the same as an io::IoError instead (the writer's loop: nothing thrown,
// nothing allocated). One writer object serves file after file (open()), its buffers kept. Nothing
// is buffered past flush(); close() (or the destructor, which cannot report a failure) flushes.
// After a failure (a full disk), abandon() cuts the file back to what the last successful flush()
// wrote, which always ends on a record boundary, so the file stays readable to its end. Not
// thread-safe.
#pragma once

#include <array>
#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <span>
#include <string>
#include <string_view>

#include "daemon/io/errors.hpp"
#include "daemon/io/file_output.hpp"
#include "daemon/pcap/capture_reader.hpp"
#include "daemon/pcap/zstd_write_stream.hpp"

namespace pandarcap {

// The classic-pcap layout PcapWriter writes; core/pcap_recovery.cpp reads it back.
inline constexpr std::size_t kPcapGlobalHeaderBytes = 24;
inline constexpr std::size_t kPcapRecordHeaderBytes = 16;
// A record's bytes besides the UDP payload: its header and the Ethernet, IPv4 and UDP headers
// written in front of the payload (14 + 20 + 8); an IPv6 datagram's IPv6 header is 20 longer.
inline constexpr std::size_t kPcapRecordOverheadBytes = kPcapRecordHeaderBytes + 42;
inline constexpr std::size_t kPcapRecordOverheadBytesIpv6 = kPcapRecordHeaderBytes + 62;
// Not 65535: the largest record (a 65507-byte payload) is a 65549-byte frame, and readers cut
// records to the file's snaplen. 262144 is libpcap's maximum and tcpdump's default.
inline constexpr std::uint32_t kPcapSnaplen = 262144;

// The 24-byte global header every PcapWriter file begins with (native byte order, microsecond
// times, LINKTYPE_ETHERNET, snaplen kPcapSnaplen).
std::array<std::uint8_t, kPcapGlobalHeaderBytes> pcap_global_header() noexcept;

// The buffer the daemon gives its recordings: the decoder hands over raw packets at
// least every 100 ms, and 1 MiB holds that much of one sensor (~0.5 MB) twice over.
inline constexpr std::size_t kPcapBufferBytes = 1 << 20;

class PcapWriter {
 public:
  // Creates (truncates) `path` and writes the pcap global header, flushed at once: from then on
  // the file is a valid (empty) capture, and a full disk shows here. Throws std::system_error.
  // `buffer`, if given, holds records until flush() (it must outlive the writer): unbuffered, a
  // recording at one sensor's rate costs two write(2) a packet; a buffer that holds what arrives
  // between two flush() calls makes it one per flush.
  // `compressor`, if given, makes the file a zstd frame (it must outlive the writer, and serve
  // one writer at a time: the writer begins its frame).
  explicit PcapWriter(const std::string& path, std::span<char> buffer = {},
                      ZstdStreamCompressor* compressor = nullptr);
  PcapWriter() = default;  // no file: open() one
  ~PcapWriter();
  // Begins the file `path` as the constructor does (the writer must hold no open file: close()
  // or abandon() it first), returning the failure; after one no file is open. Once the writer
  // has held a path as long, allocates nothing.
  io::IoError open(std::string_view path, std::span<char> buffer, ZstdStreamCompressor* compressor);
  bool is_open() const noexcept { return file_.is_open(); }
  // Room for a path of `bytes` made now (at start-up): the first open() allocates nothing.
  void reserve_path(std::size_t bytes) {
    path_.reserve(bytes);
    file_.reserve_path(bytes);
  }
  // Whether write() takes a datagram of `payload_bytes` received at `timestamp_ns`: false for
  // one longer than UDP carries, or a time outside 1970..2106 (std::invalid_argument there).
  static bool recordable(std::size_t payload_bytes, std::int64_t timestamp_ns) noexcept;
  PcapWriter(const PcapWriter&) = delete;
  PcapWriter& operator=(const PcapWriter&) = delete;

  // Appends one record of a whole datagram. `timestamp_ns` is truncated to microseconds.
  // Payloads longer than a UDP datagram can carry (65507 bytes), and times outside 1970..2106
  // (classic pcap stores seconds as an unsigned 32-bit number), throw std::invalid_argument.
  void write(std::span<const std::uint8_t> udp_payload, std::int64_t timestamp_ns, Endpoint source,
             Endpoint destination) {
    write(udp_payload, udp_payload.size(), timestamp_ns, source, destination);
  }
  // Appends one record of a datagram of which only `kept` (its first bytes) is held: a datagram
  // the socket cut, or a record a capture's snap length cut. The record claims no byte it does
  // not hold: its captured length covers the headers and `kept`, its original length and the
  // IPv4 / UDP length fields the whole `original_payload_bytes` (at least kept.size(), at most
  // 65507), as a capture tool with a short snap length writes it.
  void write(std::span<const std::uint8_t> kept, std::size_t original_payload_bytes,
             std::int64_t timestamp_ns, Endpoint source, Endpoint destination);
  // Appends one record of a frame as the wire gave it: `wire_header` (Ethernet, any VLAN tags,
  // IP, UDP, exactly as received; the packet_ring receiver keeps them), then `rest`, the bytes
  // after them that were kept (the datagram, and any padding). `wire_length` is the frame's
  // length on the wire, the record's original length: the record `tcpdump -w` writes. Takes
  // only a recordable() time (rest.size() is at most a slot's).
  io::IoError try_write_frame(std::span<const std::uint8_t> wire_header,
                              std::span<const std::uint8_t> rest, std::size_t wire_length,
                              std::int64_t timestamp_ns);
  void flush() {
    if (const io::IoError error = try_flush()) io::throw_io_error(error);
  }
  void close() {
    if (const io::IoError error = try_close()) io::throw_io_error(error);
  }
  // The same, returning the failure. try_write takes only a recordable() datagram.
  io::IoError try_write(std::span<const std::uint8_t> kept, std::size_t original_payload_bytes,
                        std::int64_t timestamp_ns, Endpoint source, Endpoint destination);
  io::IoError try_flush();
  io::IoError try_close();

  // What abandon() dropped: the records (and their pcap bytes) written since the last good flush.
  struct Dropped {
    std::uint64_t records = 0;
    std::uint64_t bytes = 0;
  };
  // Discards whatever is buffered, truncates the file to the last successful flush and closes
  // it, without throwing; a compressed file is then ended with an empty last block and the
  // content checksum of what it holds (if that write fails too, the frame stays unfinished: readers
  // see every flushed record, then a cut). The file then holds flushed_records() whole records (0:
  // possibly not even the global header; the caller removes it).
  Dropped abandon() noexcept;

  std::uint64_t records() const noexcept { return records_; }
  // The file's size so far (uncompressed: with what is buffered; compressed: as written).
  std::uint64_t bytes() const noexcept { return compressor_ ? file_.size() : bytes_; }
  bool compressed() const noexcept { return compressor_ != nullptr; }
  std::uint64_t flushed_records() const noexcept { return flushed_records_; }
  std::uint64_t flushed_bytes() const noexcept { return flushed_bytes_; }
  const std::string& path() const noexcept { return path_; }
  // The file is still where its path says (see OutputFile::at_its_path).
  bool at_its_path() const noexcept { return file_.at_its_path(); }

 private:
  // Appends to the buffer, or straight to the file when there is none (or `bytes` is larger).
  io::IoError append(std::span<const std::uint8_t> bytes);
  // The buffered bytes to the file; compressed, with the block or frame ended as `step` says.
  io::IoError flush_buffer(ZstdStreamCompressor::Step step = ZstdStreamCompressor::Step::kContinue);
  io::IoError emit(std::span<const std::uint8_t> bytes, ZstdStreamCompressor::Step step);
  io::IoError not_open() const noexcept { return {EBADF, "cannot write", path_}; }

  std::string path_;
  OutputFile file_;
  ZstdStreamCompressor* compressor_ = nullptr;  // the caller's; null: uncompressed
  std::span<char> buffer_;  // the caller's; bytes [0, buffered_) await the next flush()
  std::size_t buffered_ = 0;
  std::uint16_t ip_id_ = 0;
  std::uint64_t records_ = 0;
  std::uint64_t bytes_ = 0;                 // of the pcap stream (uncompressed)
  std::uint64_t flushed_records_ = 0;       // as of the last flush() that succeeded
  std::uint64_t flushed_bytes_ = 0;         // the file's size then
  std::uint64_t flushed_stream_bytes_ = 0;  // the pcap stream's (uncompressed) bytes then
  Xxh64 flushed_hash_;                      // compressed: the stream's hash then (its checksum)
};

}  // namespace pandarcap
