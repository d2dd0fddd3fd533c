// A classic pcap file's records as the tests compare them: each header's time, lengths and the
// bytes kept. What the daemon writes, tcpdump -w writes, and the tests' witnesses write.
#pragma once

#include <catch2/catch.hpp>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <tuple>
#include <vector>

#include "bench/child_process.hpp"

namespace pandarcap::test {

struct PcapRecord {
  std::uint32_t seconds = 0, fraction = 0, captured = 0, original = 0;
  std::string bytes;
  bool operator==(const PcapRecord&) const = default;
  bool operator<(const PcapRecord& o) const {
    return std::tie(seconds, fraction, captured, original, bytes) <
           std::tie(o.seconds, o.fraction, o.captured, o.original, o.bytes);
  }
};

// Every record of `file`, which must be whole records after the file header (either time
// resolution, native order). `magic`, when given, gets the header's magic number.
inline std::vector<PcapRecord> read_pcap_records(const std::filesystem::path& file,
                                                 std::uint32_t* magic = nullptr) {
  const std::string data = harness::read_file(file);  // one read, not a character at a time
  INFO(file.string());
  REQUIRE(data.size() >= 24);
  std::uint32_t m = 0;
  std::memcpy(&m, data.data(), 4);
  REQUIRE((m == 0xA1B2C3D4u || m == 0xA1B23C4Du));
  if (magic != nullptr) *magic = m;
  std::vector<PcapRecord> out;
  std::size_t at = 24;
  while (at + 16 <= data.size()) {
    std::uint32_t h[4];
    std::memcpy(h, data.data() + at, 16);
    if (at + 16 + h[2] > data.size()) break;
    out.push_back({h[0], h[1], h[2], h[3], data.substr(at + 16, h[2])});
    at += 16 + h[2];
  }
  CHECK(at == data.size());  // whole records, nothing after them
  return out;
}

// How many whole records `file` holds now (a file still being written: what is there so far).
inline std::size_t count_pcap_records(const std::filesystem::path& file) {
  std::ifstream in(file, std::ios::binary);
  std::size_t count = 0;
  char header[24];
  if (!in.read(header, 24)) return 0;
  while (in.read(header, 16)) {
    std::uint32_t captured = 0;
    std::memcpy(&captured, header + 8, 4);
    if (!in.seekg(captured, std::ios::cur)) break;
    ++count;
  }
  return count;
}

}  // namespace pandarcap::test
