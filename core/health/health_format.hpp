// Renders a HealthSnapshot for the outside world: a Prometheus text file for node_exporter's
// textfile collector, and one JSON object per line for logs and scripts. Pure functions.
//
// Prometheus conventions kept: names `pandarcap_*` in snake_case, counters end in `_total`, base
// units (bytes, seconds), no timestamps on samples, every sample carries the `sensor` label, a
// `pandarcap_build_info{version=...} 1` gauge, reasons as a `reason` label on one counter family,
// and the state as one 0/1 series per possible state (`pandarcap_state{state="ok"} 1`), so an
// alert can say `pandarcap_state{state!="ok"} == 1`.
//
// The JSON line has the keys `time` (RFC 3339 UTC), `unix_time_ns`, `sensor`, `version`,
// `decoder`, `state`, `reason`, `counters` {name: value, with `rejects` and `filtered_points` as
// {reason: value}}, `gauges` {name: value}, `storage` {free_bytes, written_bytes_per_second
// {frames, pcap, mcap, health, total}, hours_left (null while nothing is written)} and `latency`
// {count, p50_us, p99_us, p999_us, max_us}. Names match the HealthCounters/HealthGauges fields
// one-to-one, so the accounting identity can be checked from either output.
#pragma once

#include <string>

#include "core/health/health.hpp"

namespace pandarcap {

// The whole .prom file, '\n'-terminated.
std::string to_prometheus(const HealthSnapshot& snapshot);

// One JSON object and a '\n'.
std::string to_json_line(const HealthSnapshot& snapshot);

// The same, written into `out` (cleared first). Once `out` has grown to the size of a record,
// rendering again allocates nothing: the writer thread renders every second with these.
void render_prometheus(const HealthSnapshot& snapshot, std::string& out);
void render_json_line(const HealthSnapshot& snapshot, std::string& out);

}  // namespace pandarcap
