#include "daemon/live/live_publish.hpp"

#include "core/mcap/mcap_records.hpp"
#include "core/mcap/ros2_messages.hpp"

namespace pandarcap::live {
namespace {

void put_u64(std::vector<std::uint8_t>& out, std::uint64_t v) {
  for (int i = 0; i < 8; ++i)
    out.push_back(static_cast<std::uint8_t>(v >> (8 * i)));
}

void dropped(LiveHandover& live) noexcept {
  live.counters.messages_dropped.fetch_add(1, std::memory_order_relaxed);
}

}  // namespace

std::size_t points_message_bytes(PcdLayout layout, std::size_t frame_id_bytes,
                                 std::size_t max_points) noexcept {
  return kMessageDataHeaderBytes + mcap::pointcloud2_prefix_bytes(frame_id_bytes, layout) +
         max_points * pcd_point_bytes(layout) + mcap::kPointCloud2SuffixBytes;
}

void offer_frame(LiveHandover& live, const Frame& frame, std::string_view frame_id,
                 std::int64_t log_time_ns) noexcept {
  if (live.counters.points_subscribers.load(std::memory_order_relaxed) == 0) return;
  const PcdLayout layout = frame.format.layout;
  std::vector<std::uint8_t>& out = live.points.back();
  if (!frame.is_encoded() ||
      points_message_bytes(layout, frame_id.size(), frame.size) > live.points.capacity()) {
    dropped(live);
    return;
  }
  // Within the capacity reserved at start-up: push_back never allocates here.
  out.clear();
  out.push_back(kMessageDataOpcode);
  for (int i = 0; i < 4; ++i)
    out.push_back(0);  // the subscription id, the server's to write per client
  put_u64(out, static_cast<std::uint64_t>(log_time_ns));
  mcap::ByteWriter w(out);
  mcap::write_pointcloud2_prefix(w, mcap::ros_time(frame.info.start_ns), frame_id,
                                 static_cast<std::uint32_t>(frame.size), layout);
  w.bytes(frame.used_bytes());
  mcap::write_pointcloud2_suffix(w);
  if (live.points.publish()) dropped(live);
}

void offer_health(LiveHandover& live, std::string_view json_line,
                  std::int64_t realtime_ns) noexcept {
  if (live.counters.clients.load(std::memory_order_relaxed) == 0) return;
  while (!json_line.empty() && json_line.back() == '\n')
    json_line.remove_suffix(1);
  std::vector<std::uint8_t>& out = live.health.back();
  if (8 + json_line.size() > live.health.capacity()) {
    dropped(live);
    return;
  }
  out.clear();
  put_u64(out, static_cast<std::uint64_t>(realtime_ns));
  out.insert(out.end(), json_line.begin(), json_line.end());
  live.health.publish();  // a record replaced before it was sent is not worth counting: 1 s old
}

}  // namespace pandarcap::live
