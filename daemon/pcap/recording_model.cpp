#include "daemon/pcap/recording_model.hpp"

#include "daemon/pcap/capture_reader.hpp"

namespace pandarcap {

std::optional<RecordingModel> recording_model(const std::string& path,
                                              std::optional<std::uint16_t> port,
                                              std::uint64_t max_datagrams) {
  CaptureReader::Options options;
  options.destination_port = port;
  CaptureReader reader(path, options);
  CaptureRecord record;
  RecordingModel found;
  while (found.records < max_datagrams && reader.next(record) == CaptureStatus::kRecord) {
    ++found.records;
    if (record.snapped) continue;
    // A known model only where its own check passes (detect_model); an unsupported one by its
    // header alone (identify_model): it is named, never decoded.
    const DetectedModel d = detect_model(record.payload);
    if (d.kind == DetectionKind::kKnown) {
      found.detected = d;
      found.named = reader.named_model();
      return found;
    }
    const DetectedModel named = identify_model(record.payload);
    if (named.kind == DetectionKind::kUnsupported) {
      found.detected = named;
      found.named = reader.named_model();
      return found;
    }
  }
  found.named = reader.named_model();
  if (!found.named) return std::nullopt;
  found.detected.kind = DetectionKind::kKnown;
  found.detected.model = *found.named;
  found.from_file = true;
  return found;
}

}  // namespace pandarcap
