// Problems that hold until they end, rather than grow from one second to the next: a replay that
// met damage in its file (from then on, to the last health record: a damaged recording never
// ends a replay "ok"), and a live view that cannot listen on its port (until it can). The health
// policy names them among the others (HealthGauges::standing, core/health/health_policy.hpp).
//
// "recording damaged: raw/x.mcap: the chunk at offset 1234 fails its CRC (1 damaged chunk
// skipped, 1800 packets in it)", "recording cut short: raw/x.pcap.zst: the zstd stream ends
// inside a frame ...", "live view: port 8765 in use (retrying every 10 s)".
//
// Written in place into `out` (cleared, its capacity kept: nothing allocated once it has grown).
// Called by the writer thread; reads what the replay thread and the live view's thread publish.
#pragma once

#include <string>

#include "daemon/live/live_handover.hpp"
#include "daemon/pipeline_types.hpp"

namespace pandarcap {

void describe_standing_problems(const ReceiveCounters& receive, const live::LiveCounters* live,
                                std::string& out);

}  // namespace pandarcap
