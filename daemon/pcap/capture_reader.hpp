// Reads UDP payloads out of pcap and pcapng capture files (libpcap does the file formats), the
// same compressed with zstd (pandarcapd's raw/NAME.pcap.zst, `zstd FILE.pcap`), and the Pandar
// packets of an MCAP file (its pandar_msgs/msg/PandarPacket channel: mcap_packet_reader.hpp).
// The kind is told by the file's first bytes, never by its name: the zstd magic 28 B5 2F FD
// (decompressed as a stream while libpcap reads it: zstd_read_stream.hpp), the MCAP magic
// 89 'MCAP0' 0D 0A, else libpcap's own formats.
//
// Link types: Ethernet (with any number of 802.1Q / 802.1ad VLAN tags), Linux cooked capture v1
// (SLL) and v2 (SLL2), and raw IP. Network layer: IPv4 / UDP and IPv6 / UDP (behind any
// hop-by-hop, routing, destination-options or authentication headers). Everything else (ARP,
// TCP, IP fragments, malformed headers) is skipped and counted in CaptureStats, never an error:
// the replay's summary and pandarcap-inspect print those counts. Fragments are not reassembled
// (a Pandar packet fits one Ethernet frame; a fragmented one was sent through a smaller MTU).
//
// End of input has three distinct outcomes:
//   kEnd        the file ended cleanly after its last record;
//   kTruncated  the file ends in the middle of a record (a recording cut off by a crash or a full
//               disk), or a zstd capture inside its frame (a killed run's NAME.pcap.zst.part), or
//               an MCAP file before its data end: every complete record before it was yielded;
//   kError      the file is corrupt (bad record header, compressed data that does not decompress,
//               a damaged MCAP chunk, ...): error() says what and where.
// A file that cannot be opened or is not a capture at all makes the constructor throw, and so does
// an MCAP file without a single PandarPacket message.
//
// MCAP packets carry no addresses: their records' source and destination are empty (0.0.0.0:0,
// has_endpoints() false) and Options::destination_port does not apply to them.
//
// Not thread-safe; one reader per thread. A record's payload span is valid until the next call.
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>

#include "core/sensors/sensor_model_id.hpp"
#include "daemon/pcap/endpoint.hpp"

struct pcap;  // libpcap's handle, kept out of this header

namespace pandarcap {

class McapPacketReader;
class ZstdReadStream;

class CaptureError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct CaptureRecord {
  std::span<const std::uint8_t> payload;  // UDP payload bytes present in the file
  std::int64_t timestamp_ns = 0;          // record time, ns since the Unix epoch
  Endpoint source;
  Endpoint destination;
  std::uint32_t udp_payload_length = 0;  // length the UDP header declares
  bool snapped = false;  // the record holds fewer bytes than the datagram had (snaplen)
};

enum class CaptureStatus { kRecord, kEnd, kTruncated, kError };

enum class CaptureFormat { kPcap, kPcapZstd, kMcap };  // kPcap: pcap or pcapng

struct CaptureStats {
  std::uint64_t records = 0;         // every record read from the file
  std::uint64_t udp_datagrams = 0;   // records yielded (after the port filter)
  std::uint64_t ipv6_datagrams = 0;  // of which IPv6 / UDP
  std::uint64_t port_filtered = 0;   // UDP datagrams to another destination port (MCAP: packets
                                     // on a second PandarPacket channel)
  std::uint64_t non_ip = 0;          // ARP, unknown ethertypes / link protocols
  std::uint64_t non_udp = 0;         // IPv4 or IPv6 but not UDP
  std::uint64_t ip_fragments = 0;    // IPv4 fragments and IPv6 fragment headers (not reassembled)
  std::uint64_t malformed = 0;       // headers cut short or inconsistent
  std::uint64_t snapped = 0;         // yielded datagrams with snapped == true
  // MCAP: damaged chunks skipped by the chunk index, the packets their message indexes list, and
  // damaged records read over (a damaged length, resumed at the next chunk).
  std::uint64_t chunks_skipped = 0;
  std::uint64_t packets_skipped = 0;
  std::uint64_t records_damaged = 0;

  // Records read but not yielded for what they are (the port filter's are asked for).
  std::uint64_t skipped() const noexcept { return non_ip + non_udp + ip_fragments + malformed; }
};

class CaptureReader {
 public:
  struct Options {
    std::optional<std::uint16_t> destination_port;  // yield only datagrams to this port
  };

  // Opens `path` (pcap or pcapng, either compressed with zstd, or MCAP). Throws CaptureError
  // naming the file when it cannot be opened, is not a capture, has an unsupported link type, or
  // (MCAP) holds no PandarPacket message.
  explicit CaptureReader(const std::string& path, Options options = {});
  ~CaptureReader();
  CaptureReader(const CaptureReader&) = delete;
  CaptureReader& operator=(const CaptureReader&) = delete;

  // Advances to the next UDP datagram. kRecord fills `out`; anything else is final.
  CaptureStatus next(CaptureRecord& out);

  const std::string& path() const noexcept { return path_; }
  // Human-readable reason for kTruncated / kError (includes the file name).
  const std::string& error() const noexcept { return error_; }
  // The first damage read over without stopping (MCAP chunks skipped, a pcap record whose
  // headers do not hold together: counted malformed), "" while none.
  const std::string& first_damage() const noexcept;
  const CaptureStats& stats() const noexcept { return stats_; }
  // How far through the file reading is, in the file's own bytes (compressed ones for a
  // pcap.zst, read ahead by a buffer), and the file's size: a replay's progress.
  std::uint64_t bytes_read() const noexcept;
  std::uint64_t size_bytes() const noexcept { return size_bytes_; }
  int link_type() const noexcept { return link_type_; }  // 0 for MCAP
  CaptureFormat format() const noexcept { return format_; }
  // Whether records carry their source and destination (not MCAP's).
  bool has_endpoints() const noexcept { return format_ != CaptureFormat::kMcap; }
  // The model the file itself names (an MCAP packets channel's sensor_model metadata, once read:
  // McapPacketReader::named_model); none for pcap, which names none.
  std::optional<SensorModelId> named_model() const noexcept;

 private:
  CaptureStatus finish(int pcap_status);  // records the final status of a failed pcap_next_ex
  void malformed(const char* what);       // counts the record just read, naming the first
  void open_mcap(int fd);

  std::string path_;
  Options options_;
  pcap* handle_ = nullptr;
  int link_type_ = 0;
  bool nanosecond_ = false;
  std::string error_;
  std::string first_damage_;
  CaptureStats stats_;
  std::optional<CaptureStatus> final_status_;  // set once next() has returned a final status
  CaptureFormat format_ = CaptureFormat::kPcap;
  const ZstdReadStream* zstd_ = nullptr;  // kPcapZstd: the stream behind libpcap's FILE
  std::unique_ptr<McapPacketReader> mcap_;
  std::optional<CaptureRecord> first_;  // MCAP: the packet read at open, not yet yielded
  int fd_ = -1;                         // pcap, pcap.zst: the file libpcap reads (owned there)
  std::uint64_t size_bytes_ = 0;
};

}  // namespace pandarcap
