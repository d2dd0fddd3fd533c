// The health record's storage part (core/health/health_format_parts.hpp): free space, write rates,
// the time left, and the upload backlog.
#include <fmt/format.h>

#include <cmath>
#include <iterator>

#include "core/health/health_format_parts.hpp"
#include "core/text_encoding.hpp"

namespace pandarcap::health_format {

// The storage gauges (docs/storage.md). The time left is +Inf while nothing is written; free space
// and time left are left out when no output file system could be asked.
void storage_prometheus(std::string& out, std::string_view sensor, const StorageGauges& st) {
  const auto append = [&out]<typename... Args>(fmt::format_string<Args...> format, Args&&... args) {
    fmt::format_to(std::back_inserter(out), format, std::forward<Args>(args)...);
  };
  if (st.free_known) {
    family(out, "storage_free_bytes", "gauge",
           "Free bytes on the output file system that fills first at the last minute's write "
           "rate");
    append("pandarcap_storage_free_bytes{{{}}} {}\n", sensor, st.free_bytes);
  }
  family(out, "storage_written_bytes_per_second", "gauge",
         "Bytes written per second over the last minute, by output (frames, pcap, mcap, health)");
  for (std::size_t i = 0; i < kStorageOutputCount; ++i) {
    append("pandarcap_storage_written_bytes_per_second{{{},output=\"{}\"}} {}\n", sensor,
           kStorageOutputNames[i], st.written_bytes_per_second[i]);
  }
  if (st.free_known) {
    // In seconds, Prometheus's base unit (the JSON line keeps hours_left).
    family(out, "storage_time_left_seconds", "gauge",
           "Seconds until the output file system is full at the last minute's write rate; +Inf "
           "while nothing is written");
    if (std::isfinite(st.hours_left)) {
      append("pandarcap_storage_time_left_seconds{{{}}} {}\n", sensor, st.hours_left * 3600);
    } else {
      append("pandarcap_storage_time_left_seconds{{{}}} +Inf\n", sensor);
    }
  }
  // Only where recordings leave by upload: elsewhere an ever older backlog means nothing.
  const UploadGauges& up = st.upload;
  if (!up.enabled || !up.known) return;
  family(out, "storage_upload_backlog_bytes", "gauge",
         "Bytes of finished files waiting in the upload directories (output.upload)");
  append("pandarcap_storage_upload_backlog_bytes{{{}}} {}\n", sensor, up.backlog_bytes);
  family(out, "storage_upload_backlog_files", "gauge",
         "Finished files waiting in the upload directories (output.upload)");
  append("pandarcap_storage_upload_backlog_files{{{}}} {}\n", sensor, up.backlog_files);
  family(out, "storage_upload_oldest_seconds", "gauge",
         "Seconds since the oldest file waiting for upload was finished; 0 when none waits");
  append("pandarcap_storage_upload_oldest_seconds{{{}}} {}\n", sensor, up.oldest_seconds);
}

void storage_json(std::string& out, const StorageGauges& st) {
  out += ",\"storage\":{\"free_bytes\":";
  if (st.free_known) {
    fmt::format_to(std::back_inserter(out), "{}", st.free_bytes);
  } else {
    out += "null";
  }
  out += ",\"written_bytes_per_second\":{";
  for (std::size_t i = 0; i < kStorageOutputCount; ++i) {
    fmt::format_to(std::back_inserter(out), "\"{}\":", kStorageOutputNames[i]);
    append_json_number(out, st.written_bytes_per_second[i]);
    out += ',';
  }
  out += "\"total\":";
  append_json_number(out, st.written_bytes_per_second_total);
  out += "},\"hours_left\":";
  append_json_number(out, st.free_known ? st.hours_left : NAN);  // null: nothing written
  const UploadGauges& up = st.upload;
  fmt::format_to(std::back_inserter(out), ",\"upload\":{{\"enabled\":{}", up.enabled);
  if (up.known) {
    fmt::format_to(std::back_inserter(out), ",\"backlog_bytes\":{},\"backlog_files\":{}",
                   up.backlog_bytes, up.backlog_files);
    out += ",\"oldest_seconds\":";
    append_json_number(out, up.oldest_seconds);
  } else {
    out += R"(,"backlog_bytes":null,"backlog_files":null,"oldest_seconds":null)";
  }
  out += "}}";
}

}  // namespace pandarcap::health_format
