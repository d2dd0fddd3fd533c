// The writer thread's side of the live view: a finished frame or a health record put in the
// handover (live_handover.hpp) as the server will send it. Nothing here allocates, locks or makes
// a system call: the writer's loop calls these.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string_view>

#include "core/frames/frame.hpp"
#include "core/frames/pcd.hpp"
#include "daemon/live/live_handover.hpp"

namespace pandarcap::live {

// The bytes of the largest frame's message: Foxglove's header, then a PointCloud2 of
// `max_points` points in `layout` with a frame id of `frame_id_bytes` characters.
std::size_t points_message_bytes(PcdLayout layout, std::size_t frame_id_bytes,
                                 std::size_t max_points) noexcept;

// The frame as a PointCloud2 (the MCAP's message: the arena's bytes as they are) stamped with its
// first firing time and logged at `log_time_ns`, when a client subscribes to the points. A frame
// that does not fit, or is not encoded, is dropped and counted.
void offer_frame(LiveHandover& live, const Frame& frame, std::string_view frame_id,
                 std::int64_t log_time_ns) noexcept;

// The health record's JSON line, logged at `realtime_ns`, when a client is connected.
void offer_health(LiveHandover& live, std::string_view json_line,
                  std::int64_t realtime_ns) noexcept;

}  // namespace pandarcap::live
