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
  // An unsupported model's header (identify_model: by its first bytes alone) is remembered, not
  // taken at once: one look-alike datagram must not stand for a recording of a model pandarcap
  // decodes. It names the recording only when no packet of a known model follows in the window.
  std::optional<DetectedModel> unsupported;
  while (found.records < max_datagrams && reader.next(record) == CaptureStatus::kRecord) {
    ++found.records;
    if (record.snapped) continue;
    // A known model only where its own check passes (detect_model).
    const DetectedModel d = detect_model(record.payload);
    if (d.kind == DetectionKind::kKnown) {
      found.detected = d;
      found.named = reader.named_model();
      return found;
    }
    const DetectedModel named = identify_model(record.payload);
    if (named.kind == DetectionKind::kUnsupported && !unsupported) unsupported = named;
  }
  found.named = reader.named_model();
  if (unsupported && !found.named) {
    found.detected = *unsupported;
    return found;
  }
  if (!found.named) return std::nullopt;
  found.detected.kind = DetectionKind::kKnown;
  found.detected.model = *found.named;
  found.from_file = true;
  return found;
}

}  // namespace pandarcap
