// `pandarcap-bench write`: how fast the writer's two formats go on this machine. PCD frames
// (encoding alone, encoding and LZF compression as DATA binary_compressed, and encoding plus
// writing a file) and pcap recording (packets written to a file), in points/s, packets/s and
// MB/s, and the CPU per PCD frame with and without LZF. The files go to a temporary directory (the
// page cache, unless the disk is slower than memory), so these are the writer's CPU limits rather
// than a disk benchmark.
#pragma once

#include <nlohmann/json.hpp>
#include <string>

namespace pandarcap::bench {

struct WriteBenchOptions {
  std::string directory;  // where the files go; "" = a temporary directory, removed
  int frames = 50;        // PCD frames of one simulated revolution (about 73 000 points) each
  int packets = 200'000;  // pcap records of 1262-byte packets
};

nlohmann::ordered_json run_write_bench(const WriteBenchOptions& options);

// Prints the report as a short table.
void print_write_report(const nlohmann::ordered_json& report);

}  // namespace pandarcap::bench
