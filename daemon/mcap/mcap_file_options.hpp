// What shapes an MCAP file: chunking, compression, topics, frame id and what goes in its header
// records. Plain data, from the [output] section (daemon_options.cpp) and the recorder.
#pragma once

#include <cstddef>
#include <string>
#include <utility>
#include <vector>

#include "core/frames/pcd.hpp"
#include "core/mcap/chunk_codec.hpp"

namespace pandarcap {

struct McapFileOptions {
  mcap::ChunkCompression compression = mcap::ChunkCompression::kZstd;
  int compression_level = 1;  // zstd's: -7 (fastest) .. 19 (lz4: chunk_codec.hpp)
  // output.mcap_chunk_crc: each chunk's CRC-32 of its records. Off, every compressed chunk says 0
  // ("not computed", as the MCAP spec allows); zstd's frame checksum still finds damage in a zstd
  // chunk (chunk_pipeline.hpp).
  bool chunk_crc = false;
  std::size_t chunk_bytes = 4u << 20;  // uncompressed messages per chunk, about
  std::size_t chunk_buffers = 3;       // the chunk pool (chunk_pipeline.hpp): >= 2
  // No free chunk buffer: false (live) leaves the message out, counted; true (a replay, a
  // conversion that must be whole, with no sensor to keep up with) waits for the oldest chunk in
  // flight and writes it.
  bool wait_for_free_chunk = false;
  std::size_t max_frame_points = 180'000;  // the largest frame (the arenas' capacity)
  std::size_t max_chunks = 16'384;         // per file
  bool packets = false;                    // a /pandar/packets channel
  std::string points_topic = "/pandar/points";
  std::string health_topic = "/pandar/health";
  std::string packets_topic = "/pandar/packets";
  std::string frame_id = "pandar";
  // The points' layout and axes (output.pcd_fields, sensor.frame): the PCD files', so a frame
  // arena's bytes go into the PointCloud2 message as they are.
  PcdFormat format{PcdLayout::kPandarcap, Axes::kHesai};
  std::string library;                                        // the Header's, "pandarcap <version>"
  std::vector<std::pair<std::string, std::string>> metadata;  // the "pandarcap" record
  // The "foxglove" metadata record's deviceName (what Foxglove's importers file the recording
  // under); "" = no such record.
  std::string device_name;
  std::string calibration_csv;  // attached to every file as calibration.csv
  // The sensor model's display name ("PandarXT32") when known at start (a fixed sensor.model, a
  // replay's packets, --simulate): the packets channel's metadata sensor_model. "" (a live
  // "auto", whose packets choose it later): no such entry; the packets say (docs/mcap.md).
  std::string sensor_model;
};

}  // namespace pandarcap
